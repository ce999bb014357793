"""The one entry-point loader: plugins of another package join a registry table by name."""

from __future__ import annotations

from collections.abc import Callable, MutableMapping
from importlib.metadata import entry_points


def load_plugins(
    group: str,
    table: MutableMapping,
    add: Callable[[str, object, str], None],
    kind: str,
    error: type[Exception] = ValueError,
) -> None:
    """Load every entry point of ``group`` whose name is not in ``table`` yet and hand it to
    ``add(name, loaded_object, "module:attr")``; names already there keep their entry.

    Raises ``error`` in one line naming the entry point ("<kind> plugin NAME = VALUE failed to
    load (...)") when one cannot be imported: a broken plugin is named, it never crashes the
    built-ins.
    """
    for ep in entry_points(group=group):
        if ep.name in table:
            continue
        try:
            obj = ep.load()
        except Exception as e:  # noqa: BLE001 - a broken plugin must be named, not crash
            raise error(
                f"{kind} plugin {ep.name} = {ep.value} failed to load ({type(e).__name__}: {e})"
            ) from None
        add(ep.name, obj, ep.value)

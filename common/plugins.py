"""The one entry-point loader: plugins of another package join a registry table by name.

A plugin is isolated from everything that does not use it: one that fails to import (any
exception, ``SystemExit`` included; only ``KeyboardInterrupt`` passes) or that its table
refuses is named in one warning line on stderr, once per process, and left out; the table
remembers why, so naming it later is refused with that reason.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Callable
from importlib.metadata import entry_points

_warned: set[str] = set()


def program_name() -> str:
    """The running program, for the prefix of a message: the top package of ``python -m
    PACKAGE.module``, else the script's file name (``osnerf``)."""
    spec = getattr(sys.modules.get("__main__"), "__spec__", None)
    if spec is not None and spec.name:
        return spec.name.partition(".")[0]
    script = os.path.basename(sys.argv[0]) if sys.argv else ""
    return script if script and not script.startswith("-") else "python"


def warn_once(message: str) -> None:
    """Print ``<program>: warning: <message>`` on stderr, the first time only."""
    if message in _warned:
        return
    _warned.add(message)
    if sys.stderr is not None:
        print(f"{program_name()}: warning: {message}", file=sys.stderr, flush=True)


def _one_line(e: BaseException, named: bool = True) -> str:
    """The first line of ``e``'s message (at most 200 characters), after its type if ``named``."""
    lines = [ln.strip() for ln in str(e).splitlines() if ln.strip()]
    text = lines[0][:200] if lines else ""
    return f"{type(e).__name__}: {text}" if named and text else text or type(e).__name__


def load_plugins(
    group: str,
    kind: str,
    add: Callable[[str, object, str], None],
    skip: Callable[[str, str], str | None] = lambda name, value: None,
) -> dict[str, str]:
    """Load the entry points of ``group`` and hand each to ``add(name, object, "module:attr")``.

    Args:
        group: the entry-point group (``semcodec.codecs``).
        kind: what an entry is, for messages ("codec").
        add: joins a loaded entry to its table; a ``TypeError`` or ``ValueError`` refuses it.
        skip: ``skip(name, value)`` says why an entry point is not loaded (a name already
            taken, a name that cannot be named): None loads it, ``""`` skips it without a
            word, any other text skips it with that text in a warning line.
    Returns:
        The entry points that failed to load or that ``add`` refused: name -> the reason in
        one line (``"codec plugin NAME = VALUE failed to load (ImportError: ...)"``), each
        also named in one warning line.
    """
    failed: dict[str, str] = {}
    for ep in entry_points(group=group):
        why = skip(ep.name, ep.value)
        if why is not None:
            if why:
                warn_once(why)
            continue
        where = f"{kind} plugin {ep.name} = {ep.value}"
        try:
            obj = ep.load()
        except KeyboardInterrupt:
            raise
        except BaseException as e:  # noqa: BLE001 - SystemExit at import too: named, skipped
            failed[ep.name] = f"{where} failed to load ({_one_line(e)})"
        else:
            try:
                add(ep.name, obj, ep.value)
                continue
            except (TypeError, ValueError) as e:
                failed[ep.name] = f"{where} is refused ({_one_line(e, named=False)})"
        warn_once(f"{failed[ep.name]}; it is skipped")
    return failed

"""The one way to declare a table of named things (channels, MCSs, codecs, schemes, devices...).

    CHANNELS = Registry[ChannelFactory]("channel", {"awgn": AWGN, ...})
    CODECS = Registry[CodecFactory]("codec", entry_points="semcodec.codecs")

    @CODECS.register("jscc")
    def _jscc(checkpoint): ...

    CODECS["nope"]     # KeyError: "unknown codec 'nope'; known: deepjscc, jscc"

A registry is a read-only :class:`~collections.abc.Mapping` (``in``, ``items()``, iteration in
registration order), so code that reads a table reads it as it would a dict. Entries come from
:meth:`Registry.register` (a call or a decorator) and, for a registry with an entry-point group,
from other packages' entry points, loaded on first read through :func:`common.plugins.load_plugins`.
A plugin that fails to load, that ``check`` refuses, that would take a name already in the
table, or whose name holds ``:`` or ``,`` is named in one warning line and left out; every
other entry works. Naming a plugin that failed (``table["broken"]``) raises the registry's
``error`` with its reason in one line.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping
from typing import Any, Generic, TypeVar, overload

from common.plugins import load_plugins

T = TypeVar("T")


class Registry(Mapping[str, T], Generic[T]):
    """A named table: ``register``, ``[name]`` (KeyError naming the known ones), ``names()``.

    Args:
        kind: what an entry is, for messages ("channel", "MCS", "codec").
        entries: the built-in entries, in order.
        entry_points: an entry-point group whose entries join the table on first read.
        check: called as ``check(name, entry)`` before an entry joins; raises to refuse it.
        error: the exception raised on reading a plugin that failed to load (default
            ``ValueError``).
    """

    def __init__(
        self,
        kind: str,
        entries: Mapping[str, T] | None = None,
        *,
        entry_points: str | None = None,
        check: Callable[[str, Any], None] | None = None,
        error: type[Exception] = ValueError,
    ) -> None:
        self.kind = kind
        self.entry_point_group = entry_points
        self._check = check
        self._error = error
        self._entries: dict[str, T] = {}
        self.plugins: dict[str, str] = {}
        """Entries that came from entry points: name -> ``module:attr``."""
        self.broken: dict[str, str] = {}
        """Entry points that failed to load or were refused: name -> the reason, one line."""
        self._plugins_loaded = entry_points is None
        for name, entry in (entries or {}).items():
            self.register(name, entry)

    @overload
    def register(self, name: str) -> Callable[[T], T]: ...

    @overload
    def register(self, name: str, entry: T) -> T: ...

    def register(self, name: str, entry: Any = None) -> Any:
        """Add ``entry`` under ``name``; without ``entry``, a decorator that adds what it wraps.

        Raises:
            ValueError: the name is empty, holds ``:`` or ``,`` (they separate names and
                arguments on command lines), or is taken.
        """
        if not isinstance(name, str) or not name or ":" in name or "," in name:
            raise ValueError(f"{self.kind} name must be non-empty without ':' or ',', got {name!r}")

        def add(obj: T) -> T:
            if name in self._entries:
                raise ValueError(f"{self.kind} {name!r} is already registered")
            if self._check is not None:
                self._check(name, obj)
            self._entries[name] = obj
            return obj

        return add if entry is None else add(entry)

    def load_entry_points(self, force: bool = False) -> None:
        """Add the entries of the entry-point group (once; ``force`` reads the group again, for
        a plugin installed while running). Names already taken keep their entry; a plugin
        that would take one is named in a warning line, as is one that fails to load."""
        if self.entry_point_group is None or (self._plugins_loaded and not force):
            return
        self._plugins_loaded = True

        def add(name: str, obj: Any, value: str) -> None:
            self.register(name, obj)
            self.plugins[name] = value
            self.broken.pop(name, None)

        self.broken.update(load_plugins(self.entry_point_group, self.kind, add, self._skip_plugin))

    def _skip_plugin(self, name: str, value: str) -> str | None:
        """Why the entry point ``name = value`` is not loaded (see ``load_plugins``' skip)."""
        where = f"{self.kind} plugin {name} = {value}"
        if self.plugins.get(name) == value:
            return ""  # loaded already
        if name in self._entries:
            held = self.plugins.get(name)
            held = f"the {self.kind} plugin {held}" if held else f"a built-in {self.kind}"
            return f"{where} is skipped: {name} is taken by {held}, which is kept"
        if not name or ":" in name or "," in name:
            return f"{where} is refused: a {self.kind} name cannot hold ':' or ','"
        return None

    def unregister(self, name: str) -> T:
        """Remove ``name`` and return its entry (a plugin uninstalled while running)."""
        entry = self[name]
        del self._entries[name]
        self.plugins.pop(name, None)
        return entry

    def names(self) -> list[str]:
        """Every name, built-ins first, in registration order."""
        return list(self)

    def __getitem__(self, name: str) -> T:
        self.load_entry_points()
        try:
            return self._entries[name]
        except (KeyError, TypeError):
            if isinstance(name, str) and name in self.broken:
                raise self._error(self.broken[name]) from None
            raise KeyError(
                f"unknown {self.kind} {name!r}; known: {', '.join(self._entries)}"
            ) from None

    def __contains__(self, name: object) -> bool:
        self.load_entry_points()
        return name in self._entries

    def __iter__(self) -> Iterator[str]:
        self.load_entry_points()
        return iter(list(self._entries))

    def __len__(self) -> int:
        self.load_entry_points()
        return len(self._entries)

    def __repr__(self) -> str:
        return f"Registry({self.kind!r}: {', '.join(self._entries)})"

"""The one registry of semantic codecs: ``CODECS`` (name -> factory) and ``make_codec``.

A factory takes an optional checkpoint path (``str`` or None) and returns a
:class:`semcodec.SemanticCodec`; None means the codec's default weights (for ``jscc`` the
shipped checkpoint). Other packages add codecs through the entry-point group
``semcodec.codecs``::

    [semcodec.codecs]
    mycodec = mypackage.codec:make

``make_codec("NAME[:CHECKPOINT]")`` builds one. Built-in codecs register with
:func:`register_codec` exactly as a plugin's factory would be called.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from common import load_plugins
from semcodec.contract import CODEC_MEMBERS, missing_members

ENTRY_POINT_GROUP = "semcodec.codecs"

CodecFactory = Callable[[str | None], object]
CODECS: dict[str, CodecFactory] = {}
"""Registered codecs: name -> factory(checkpoint: str | None) -> codec."""
PLUGINS: dict[str, str] = {}
"""Codecs that came from entry points: name -> ``module:attr``."""
_entry_points_loaded = False


class CodecPluginError(ValueError):
    """A codec plugin failed to load, raised in its factory or returned no codec."""


def register_codec(name: str) -> Callable[[CodecFactory], CodecFactory]:
    """Decorator: ``@register_codec("name")`` on a factory adds it to :data:`CODECS`."""

    def add(factory: CodecFactory) -> CodecFactory:
        if not name or ":" in name or "," in name:
            raise ValueError(f"codec name must be non-empty without ':' or ',', got {name!r}")
        CODECS[name] = factory
        return factory

    return add


def load_codec_entry_points(force: bool = False) -> dict[str, CodecFactory]:
    """Add the codecs of the ``semcodec.codecs`` entry points (once; ``force`` rereads them).

    Names already registered keep their factory. Raises :class:`CodecPluginError` (one line
    naming the entry point) when one cannot be imported.
    """
    global _entry_points_loaded
    if _entry_points_loaded and not force:
        return CODECS
    _entry_points_loaded = True

    def add(name: str, factory, value: str) -> None:
        if not callable(factory):
            raise CodecPluginError(f"codec plugin {name} = {value} is not callable")
        CODECS[name] = factory
        PLUGINS[name] = value

    load_plugins(ENTRY_POINT_GROUP, CODECS, add, "codec", CodecPluginError)
    return CODECS


def codec_names() -> list[str]:
    """Every registered codec name (built-ins and entry points), sorted: for ``--help``."""
    return sorted(load_codec_entry_points())


def parse_codec_spec(spec: str) -> tuple[str, str | None]:
    """``"NAME[:CHECKPOINT]"`` -> (name, checkpoint path or None); ValueError when empty."""
    if not isinstance(spec, str) or not spec.strip():
        raise ValueError(f"codec must be NAME or NAME:CHECKPOINT, got {spec!r}")
    name, sep, checkpoint = spec.strip().partition(":")
    if not name or (sep and not checkpoint):
        raise ValueError(f"codec must be NAME or NAME:CHECKPOINT, got {spec!r}")
    return name, checkpoint or None


def make_codec(spec: str):
    """Build the codec ``"NAME[:CHECKPOINT]"`` through its registered factory.

    Raises:
        KeyError: unknown name (the message lists the known ones).
        CodecPluginError: a plugin's factory raised or returned no codec (one line naming
            the plugin).
        FileNotFoundError, ValueError: from a built-in factory (missing or corrupt
            checkpoint, a checkpoint of another codec).
    """
    name, checkpoint = parse_codec_spec(spec)
    load_codec_entry_points()
    if name not in CODECS:
        raise KeyError(f"unknown codec {name!r}; known: {', '.join(sorted(CODECS))}")
    factory = CODECS[name]
    where = f"codec plugin {name} = {PLUGINS[name]}" if name in PLUGINS else f"codec {name}"
    if name in PLUGINS:
        try:
            codec = factory(checkpoint)
        except Exception as e:  # noqa: BLE001 - one line naming the plugin
            first = (str(e).strip().splitlines() or [""])[0][:160]
            raise CodecPluginError(f"{where} raised {type(e).__name__}: {first}") from None
    else:
        codec = factory(checkpoint)
    missing = missing_members(codec, CODEC_MEMBERS)
    if missing:
        raise CodecPluginError(
            f"{where} returned {type(codec).__name__}, not a semantic codec "
            f"(missing {', '.join(missing)})"
        )
    return codec


def open_codec(spec: str | None = None):
    """The codec a command names: None -> the shipped default (``jscc``); ``NAME[:CHECKPOINT]``
    -> :func:`make_codec`; a bare path to a checkpoint file -> ``jscc:PATH`` (a checkpoint of
    another codec is refused, naming the spec that loads it)."""
    if spec is None:
        return make_codec("jscc")
    name, _ = parse_codec_spec(spec)
    if name not in load_codec_entry_points() and Path(spec).is_file():
        return make_codec(f"jscc:{spec}")
    return make_codec(spec)


@register_codec("jscc")
def _jscc(checkpoint: str | None = None):
    """semcodec's ADJSCC (``semcodec.load_codec``; None = the shipped checkpoint)."""
    from semcodec.codec import load_codec

    return load_codec(checkpoint)


@register_codec("deepjscc")
def _deep_jscc(checkpoint: str | None = None):
    """Deep JSCC (Bourtsoulatze et al. 2019), :mod:`semcodec.deep_jscc`; None = untrained."""
    from semcodec.deep_jscc import make_deep_jscc

    return make_deep_jscc(checkpoint)

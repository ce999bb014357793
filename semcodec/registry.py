"""The one registry of semantic codecs: ``CODECS`` (name -> factory) and ``make_codec``.

A factory takes an optional checkpoint path (``str`` or None) and returns a
:class:`semcodec.SemanticCodec`; None means the codec's default weights (for ``jscc`` the
shipped checkpoint). Other packages add codecs through the entry-point group
``semcodec.codecs``::

    [semcodec.codecs]
    mycodec = mypackage.codec:make

``make_codec("NAME[:CHECKPOINT]")`` builds one. Built-in codecs register with
``CODECS.register`` and are called exactly as a plugin's factory would be.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from common import Registry
from semcodec.contract import CODEC_MEMBERS, missing_members

ENTRY_POINT_GROUP = "semcodec.codecs"

CodecFactory = Callable[[str | None], object]


class CodecPluginError(ValueError):
    """A codec plugin failed to load, raised in its factory or returned no codec."""


def _callable(name: str, factory: object) -> None:
    if not callable(factory):
        raise TypeError("is not callable")


CODECS = Registry[CodecFactory](
    "codec", entry_points=ENTRY_POINT_GROUP, check=_callable, error=CodecPluginError
)
"""Registered codecs: name -> factory(checkpoint: str | None) -> codec; ``CODECS.plugins``
names those that came from entry points (name -> ``module:attr``)."""


def codec_names() -> list[str]:
    """Every registered codec name (built-ins and entry points), sorted: for ``--help``."""
    return sorted(CODECS)


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
    factory = CODECS[name]
    plugin = CODECS.plugins.get(name)
    where = f"codec plugin {name} = {plugin}" if plugin else f"codec {name}"
    if plugin:
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
    if name not in CODECS and Path(spec).is_file():
        return make_codec(f"jscc:{spec}")
    return make_codec(spec)


@CODECS.register("jscc")
def _jscc(checkpoint: str | None = None):
    """semcodec's ADJSCC (``semcodec.load_codec``; None = the shipped checkpoint)."""
    from semcodec.codec import load_codec

    return load_codec(checkpoint)


@CODECS.register("deepjscc")
def _deep_jscc(checkpoint: str | None = None):
    """Deep JSCC (Bourtsoulatze et al. 2019), :mod:`semcodec.deep_jscc`; None = untrained."""
    from semcodec.deep_jscc import make_deep_jscc

    return make_deep_jscc(checkpoint)

"""The one registry of semantic codecs: ``CODECS`` (name -> factory) and ``make_codec``.

A factory takes an optional checkpoint path (``str`` or None) and returns a
:class:`semcodec.SemanticCodec`; None means the codec's default weights (for ``jscc`` the
shipped checkpoint). Other packages add codecs through the entry-point group
``semcodec.codecs``::

    [semcodec.codecs]
    mycodec = mypackage.codec:make

``make_codec("NAME[:CHECKPOINT]")`` builds one (a named checkpoint must be a file: a
missing one or a folder is refused before any factory sees it). Built-in codecs register
with ``CODECS.register`` and are called exactly as a plugin's factory would be.

``open_codec`` is what a command's ``--codec`` goes through: it also takes a bare path to a
checkpoint file, loaded by the codec that its model card names (the card's ``codec``: the
safetensors metadata ``model_card`` that :func:`semcodec.save_checkpoint` writes, and that
the trainer fills in for any codec), and it refuses a codec without trained weights
(:func:`semcodec.contract.protocol.is_trained`) unless asked with ``allow_untrained``.
:func:`plugin_origin` says which installed distribution a plugin codec comes from.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path

from common import InputError, Registry
from semcodec.contract.checkpoint import JSCC_CODEC, check_checkpoint_file, read_card
from semcodec.contract.protocol import CODEC_MEMBERS, is_trained, missing_members

ENTRY_POINT_GROUP = "semcodec.codecs"
DEFAULT_CODEC = JSCC_CODEC
"""The codec a command uses when it names none (with its shipped checkpoint)."""

CodecFactory = Callable[[str | None], object]


class CodecPluginError(ValueError):
    """A codec plugin failed to load, raised in its factory or returned no codec."""


class UntrainedCodecError(InputError):
    """The codec has no trained weights and running it untrained was not asked for."""


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
        FileNotFoundError, ValueError: a checkpoint that is missing or a folder; from a
            built-in factory, a corrupt checkpoint or one of another codec.
    """
    name, checkpoint = parse_codec_spec(spec)
    factory = CODECS[name]
    if checkpoint is not None:
        check_checkpoint_file(checkpoint)  # a plugin never sees a missing file or a folder
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


def resolve_codec_spec(spec: str | None) -> tuple[str, str | None]:
    """The (registry name, checkpoint path or None) that a command's ``--codec`` names.

    None -> :data:`DEFAULT_CODEC` with its default weights; ``NAME[:CHECKPOINT]`` of a
    registered NAME -> as written; anything else is a path to a checkpoint file, loaded by
    the codec its model card names.

    Raises:
        KeyError: an unknown name that is no file either, or a card naming a codec that is
            not installed (each listing the known codecs).
        FileNotFoundError: a path (with a folder or a suffix) to no file.
        ValueError: a folder, or a file without a readable model card.
    """
    if spec is None:
        return DEFAULT_CODEC, None
    name, checkpoint = parse_codec_spec(spec)
    if name in CODECS:
        return name, checkpoint
    path = Path(spec.strip())
    if not path.exists():
        if "/" not in spec and os.sep not in spec and not path.suffix:
            CODECS[name]  # KeyError: unknown codec, listing the known ones
        raise FileNotFoundError(
            f"codec checkpoint not found: {spec} (no such file, and no codec of that name; "
            f"known: {', '.join(CODECS)})"
        )
    held = str(read_card(path).get("codec", JSCC_CODEC))
    if held not in CODECS:
        raise KeyError(
            f"checkpoint {path} holds codec {held!r}, which is not installed; known: "
            f"{', '.join(CODECS)}"
        )
    return held, str(path)


def open_codec(spec: str | None = None, allow_untrained: bool = False):
    """The codec a command names (see :func:`resolve_codec_spec`): None -> the shipped
    default; ``NAME[:CHECKPOINT]`` -> :func:`make_codec`; a bare path to a checkpoint file ->
    the codec its card names, with that checkpoint.

    Raises what :func:`resolve_codec_spec` and :func:`make_codec` raise, and
    :class:`UntrainedCodecError` for a codec without trained weights unless
    ``allow_untrained``.
    """
    name, checkpoint = resolve_codec_spec(spec)
    codec = make_codec(name if checkpoint is None else f"{name}:{checkpoint}")
    if not allow_untrained and not is_trained(codec):
        raise UntrainedCodecError(
            f"codec {name} has no trained weights (a freshly initialised network): name a "
            f"checkpoint ({name}:CHECKPOINT), or pass --allow-untrained to run it untrained"
        )
    return codec


def plugin_origin(name: str) -> dict[str, str | None] | None:
    """Where the plugin codec ``name`` comes from: ``{"distribution", "version",
    "entry_point"}`` (``group: name = module:attr``) of the installed package whose entry
    point registered it; None for a built-in codec."""
    value = CODECS.plugins.get(name) if name in CODECS else None
    if value is None:
        return None
    from importlib.metadata import entry_points

    dist = next(
        (ep.dist for ep in entry_points(group=ENTRY_POINT_GROUP, name=name) if ep.value == value),
        None,
    )
    return {
        "distribution": dist.metadata["Name"] if dist is not None else None,
        "version": dist.version if dist is not None else None,
        "entry_point": f"{ENTRY_POINT_GROUP}: {name} = {value}",
    }

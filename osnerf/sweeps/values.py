"""A sweep's values that name an entry of a table, checked against that table before any
point runs (:func:`check_values`).

The command's own parser checks what it can (types, ranges, ``choices``); an option whose
value names a table entry that the command looks up only when it runs (a codec, a channel of
the command's own set, a scheme list, an MCS, a renderer, a scene) is checked here, so a
misspelt axis value stops the sweep before its first point instead of when its point comes.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from common import Registry
from osnerf.scenes import SCENES
from osnerf.schemes import parse_schemes
from phy import THEORY_CHANNELS
from phy.digital import MCS_TABLE
from renderer import RENDERERS
from semcodec import LINK_SCHEMES, TrainConfig, codec_names, parse_codec_spec
from semcodec.links import eval_channels


def _codec(command: str, value: str) -> None:
    """``NAME``, ``NAME:CHECKPOINT`` of ``semcodec.CODECS`` (the checkpoint a file), or a
    checkpoint path."""
    names = codec_names()
    if ":" not in value and value not in names:
        if Path(value).is_file():
            return  # a checkpoint path: its codec is read from its card when the point runs
        raise ValueError(
            f"unknown codec {value!r}, and no checkpoint file of that name; known: "
            f"{', '.join(names)}"
        )
    name, checkpoint = parse_codec_spec(value)
    if name not in names:
        raise ValueError(f"unknown codec {name!r}; known: {', '.join(names)}")
    if checkpoint is not None and not Path(checkpoint).is_file():
        what = "a folder" if Path(checkpoint).is_dir() else "not found"
        raise ValueError(f"codec {name}: checkpoint {checkpoint!r} is {what}, not a file")


def _channel(command: str, value: str) -> None:
    """The channels of the command: run's (``phy.CHANNELS`` and ``ota``), eval-codec's
    (``semcodec.links.eval_channels``: ``phy.CHANNELS``, the TS 38.101-4 conditions and
    ``raytraced`` included), ber's (``phy.THEORY_CHANNELS``), train-codec's
    (``semcodec.jscc.TRAIN_CHANNELS``, a comma-separated mixture)."""
    known: tuple[str, ...] | list[str] = ()
    if command == "run":
        from osnerf.run.config import RUN_CHANNELS as known
    elif command == "eval-codec":
        known = eval_channels()
    elif command == "ber":
        known = THEORY_CHANNELS
    elif command == "train-codec":
        TrainConfig(channel=value)
    if known and value not in known:
        raise ValueError(f"unknown channel {value!r}; known: {', '.join(known)}")


def _schemes(command: str, value: str) -> None:
    """eval-codec's schemes (``semcodec.LINK_SCHEMES``); others parse theirs themselves."""
    if command == "eval-codec":
        parse_schemes(value, LINK_SCHEMES)


def _mcs(command: str, value: str) -> None:
    """An MCS of ``phy.digital.MCS_TABLE``."""
    if value not in MCS_TABLE:
        raise ValueError(f"unknown MCS {value!r}; known: {', '.join(MCS_TABLE)}")


def _renderer(command: str, value: str) -> None:
    """A renderer of ``renderer.RENDERERS``."""
    RENDERERS[value]


def _scene(command: str, value: str) -> None:
    """A scene of ``osnerf.scenes.SCENES``."""
    SCENES[value]


VALUE_CHECKS = Registry[Callable[[str, str], None]](
    "sweep value check",
    {
        "codec": _codec,
        "receiver_codec": _codec,
        "channel": _channel,
        "schemes": _schemes,
        "mcs": _mcs,
        "renderer": _renderer,
        "scene": _scene,
    },
)
"""Option (dest name) -> ``check(command, value)``: raises ValueError or KeyError (one line)
when ``value`` names no entry of the option's table for ``command``."""


def check_values(command: str, options: dict[str, tuple[str, list[Any]]]) -> None:
    """Check every value of every option that names a table entry (:data:`VALUE_CHECKS`).

    Args:
        options: dest name -> (where it is in the spec, e.g. ``"axis 'codec'"``, its values).
    Raises:
        ValueError: naming the axis (or fixed option), the value and the known entries.
    """
    for dest, (where, values) in options.items():
        if dest not in VALUE_CHECKS:
            continue
        for value in dict.fromkeys(str(v) for v in values):
            try:
                VALUE_CHECKS[dest](command, value)
            except (ValueError, KeyError) as e:
                msg = e.args[0] if isinstance(e, KeyError) and e.args else e
                raise ValueError(f"{where} value {value!r}: {msg}") from None

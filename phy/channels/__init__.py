"""Channels on one interface: ``channel(x, snr_db, generator=None) -> ChannelOutput``.

One registry, :data:`CHANNELS` (name -> factory); :func:`make_channel` builds by name.
"""

from __future__ import annotations

import functools
import importlib.util
from collections.abc import Callable

from common import Registry
from phy.channels.awgn import AWGN
from phy.channels.base import Channel, ChannelOutput
from phy.channels.rayleigh import RayleighFading
from phy.channels.rician import RicianFading


def _lazy(module: str, name: str, **defaults) -> Callable[..., Channel]:
    """A factory that imports ``module`` (sionna-backed, slow to import) only when called."""

    def factory(**kwargs) -> Channel:
        cls = getattr(importlib.import_module(module), name)
        return cls(**{**defaults, **kwargs})

    factory.__name__ = f"{name}_factory"
    factory.__doc__ = f"{module}.{name}"
    return factory


CHANNELS = Registry[Callable[..., Channel]](
    "channel",
    {
        "awgn": AWGN,
        "rayleigh": functools.partial(RayleighFading, mode="block"),
        "rayleigh_fast": functools.partial(RayleighFading, mode="fast"),
        "rician": functools.partial(RicianFading, mode="block"),
        "rician_fast": functools.partial(RicianFading, mode="fast"),
    },
)
if importlib.util.find_spec("phy.channels.tr38901") is not None:
    CHANNELS.register("tdl", _lazy("phy.channels.tr38901", "TDLChannel"))
    CHANNELS.register("cdl", _lazy("phy.channels.tr38901", "CDLChannel"))
if importlib.util.find_spec("phy.raytrace") is not None:
    CHANNELS.register("raytraced", _lazy("phy.raytrace", "RayTracedChannel"))


def make_channel(name: str, **kwargs) -> Channel:
    """Build a registered channel by name; unknown names raise KeyError listing the known ones.

    Example: ``make_channel("rician", k_factor_db=3.0)``.
    """
    return CHANNELS[name](**kwargs)


__all__ = [
    "AWGN",
    "CHANNELS",
    "Channel",
    "ChannelOutput",
    "RayleighFading",
    "RicianFading",
    "make_channel",
]

"""Channels on one interface: ``channel(x, snr_db, generator=None) -> ChannelOutput``.

One registry, :data:`CHANNELS` (name -> factory); :func:`make_channel` builds by name. A
factory of a frequency-selective channel (run over OFDM) carries ``ofdm = True``; a TS
38.101-4 propagation condition (``tdla30-10``: the fixed TDL-A30 profile at a maximum
Doppler of 10 Hz) carries ``profile`` and ``max_doppler_hz``.
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


def _lazy(module: str, name: str, ofdm: bool = False, **defaults) -> Callable[..., Channel]:
    """A factory that imports ``module`` (sionna-backed, slow to import) only when called."""

    def factory(**kwargs) -> Channel:
        cls = getattr(importlib.import_module(module), name)
        return cls(**{**defaults, **kwargs})

    factory.__name__ = f"{name}_factory"
    factory.__doc__ = f"{module}.{name}"
    factory.ofdm = ofdm  # type: ignore[attr-defined]
    return factory


_CONDITION_FIXES = ("model", "delay_spread_s", "max_doppler_hz", "min_speed_m_s", "max_speed_m_s")


def _condition(name: str, profile: str, max_doppler_hz: float) -> Callable[..., Channel]:
    """A TS 38.101-4 propagation condition: the fixed TDL ``profile`` at ``max_doppler_hz``
    (one speed, ``f_D c / f_c``, whatever the carrier). Its name fixes profile and Doppler;
    the numerology, carrier and ``spec_version`` may be given."""
    build = _lazy(
        "phy.channels.tr38901",
        "TDLChannel",
        model=profile,
        max_doppler_hz=max_doppler_hz,
        kind=name,
    )

    def factory(**kwargs) -> Channel:
        fixed = sorted(set(kwargs) & set(_CONDITION_FIXES))
        if fixed:
            raise ValueError(
                f"channel {name} fixes {', '.join(fixed)} (TDL-{profile} at "
                f"{max_doppler_hz:g} Hz); use 'tdl' to choose them"
            )
        return build(**kwargs)

    factory.__name__ = f"{name}_factory"
    factory.__doc__ = f"TS 38.101-4 {name.upper()}: TDL-{profile}, {max_doppler_hz:g} Hz Doppler"
    factory.ofdm = True  # type: ignore[attr-defined]
    factory.profile = profile  # type: ignore[attr-defined]
    factory.max_doppler_hz = max_doppler_hz  # type: ignore[attr-defined]
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
    CHANNELS.register("tdl", _lazy("phy.channels.tr38901", "TDLChannel", ofdm=True))
    CHANNELS.register("cdl", _lazy("phy.channels.tr38901", "CDLChannel", ofdm=True))
    # TS 38.101-4 V19.2.2 Annex B.2.2 propagation conditions (name = delay profile + maximum
    # Doppler in Hz): Table B.2.2-1 (FR1), then Table B.2.2-2 (FR2)
    for _profile, _dopplers in (
        ("A30", (5, 10, 20, 180, 195, 1400, 2700)),
        ("B100", (400,)),
        ("C300", (100, 600, 1200)),
        ("D30", (5,)),
        ("A30", (35, 75, 300)),
        ("C60", (300,)),
        ("D30", (75,)),
    ):
        for _fd in _dopplers:
            _name = f"tdl{_profile.lower()}-{_fd}"
            CHANNELS.register(_name, _condition(_name, _profile, float(_fd)))
    del _profile, _dopplers, _fd, _name
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

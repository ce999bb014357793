"""Which link each channel runs on, and what a transmitter assumes about it.

Decided once here for every user (``eval-codec``, ``osnerf run``, training, the digital
baseline's MCS choice and the refining transmitter):

* :data:`OFDM_CHANNELS` run over OFDM (``phy.ResourceGrid()``) with pilot LS estimates; every
  other simulated channel is one tap per symbol with perfect CSI. Both receivers are
  zero-forcing: unbiased estimates with the per-symbol effective noise variance.
* :func:`channel_kind`: a link's channel as its ``phy.CHANNELS`` name (each channel carries
  it as ``Channel.kind``); :func:`channel_record`: what a result records of it.
* :func:`assumed_channel`: the statistical model a transmitter that never sees the draw
  plans with: the channel itself where ``phy`` simulates it by its distribution; TDL-A over
  OFDM for the ray-traced responses (fixed per position, unknown to the transmitter) and
  for any radio link (``"ota"``); :func:`symbol_model`: its flat per-symbol equivalent.
"""

from __future__ import annotations

from phy.channels import CHANNELS, make_channel
from phy.link import FlatLink, Link, OFDMLink
from phy.ofdm import ResourceGrid

OFDM_CHANNELS = frozenset(n for n, f in CHANNELS.items() if getattr(f, "ofdm", False))
"""Frequency-selective channel models that run over OFDM with pilot LS estimates: the
``phy.CHANNELS`` entries marked ``ofdm`` (tdl, cdl and the TS 38.101-4 conditions)."""
UNKNOWN_CHANNEL_MODEL = "tdl"
"""What a transmitter assumes where it cannot know the channel's distribution."""


def channel_link(
    channel: str, *, ofdm: bool | None = None, csi: str | None = None, **channel_kwargs
) -> Link:
    """The link of a ``phy.CHANNELS`` name, with an unbiased (ZF) receiver.

    Args:
        channel: a ``phy.CHANNELS`` name.
        ofdm: over OFDM with pilots (default: ``channel in OFDM_CHANNELS``).
        csi: ``"perfect"``/``"none"`` for one tap, ``"perfect"``/``"ls"`` over OFDM (default:
            ``"ls"`` over OFDM, else ``"perfect"``).
        channel_kwargs: passed to the channel (e.g. ``model="A"``, ``delay_spread_s``).
    """
    ch = make_channel(channel, **channel_kwargs)
    if channel in OFDM_CHANNELS if ofdm is None else ofdm:
        return OFDMLink(ResourceGrid(), ch, csi=csi or "ls", equalizer="zf")
    return FlatLink(ch, csi=csi or "perfect", equalizer="zf")


def receiver_description(channel: str) -> str:
    """The receiver of :func:`channel_link` in words (for result files)."""
    if channel in OFDM_CHANNELS:
        return "OFDM, pilot LS estimates, ZF + per-symbol noise variance"
    return "one tap, perfect CSI, ZF + per-symbol noise variance"


def channel_kind(link) -> str:
    """The ``phy.CHANNELS`` name of a link's (or a channel's) channel.

    Raises:
        KeyError: the link's channel does not say (not a ``phy`` channel).
    """
    kind = getattr(getattr(link, "channel", link), "kind", "")
    if kind not in CHANNELS:
        raise KeyError(
            f"cannot tell the channel kind of {type(link).__name__}; pass channel= one of "
            f"{sorted(CHANNELS)}"
        )
    return kind


def channel_record(link) -> dict:
    """What a result records of a link's (or a channel's) channel: its ``Channel.record()``
    (``{"channel": name, ...}``; TDL/CDL add the profile and the pinned TR 38.901
    ``spec_version``), or ``{"channel": None}`` for a channel that is not ``phy``'s."""
    ch = getattr(link, "channel", link)
    record = getattr(ch, "record", None)
    return record() if callable(record) else {"channel": None}


def symbol_model(channel: str) -> str:
    """The flat ``phy.CHANNELS`` model that gives each symbol of ``channel``'s link the fade
    statistics it sees, for a transmitter that simulates its link symbol by symbol (the
    refining JSCC transmitter): fast Rayleigh for the frequency-selective OFDM channels,
    whose interleaved symbols ride independently faded subcarriers (as the digital
    calibration's curves assume); the channel itself otherwise. One tap per symbol costs a
    fraction of an OFDM grid with pilots and estimation."""
    kind = assumed_channel(channel)
    return "rayleigh_fast" if kind in OFDM_CHANNELS else kind


def assumed_channel(channel: str) -> str:
    """The ``phy.CHANNELS`` model a transmitter plans with for ``channel`` (a
    ``phy.CHANNELS`` name, or any other link name such as ``"ota"``)."""
    return channel if channel in CHANNELS and channel != "raytraced" else UNKNOWN_CHANNEL_MODEL

"""Links: channel + receiver front end, ``link(x, snr_db, generator=None) -> LinkOutput``.

A link hides how symbols cross the air (flat channel, OFDM with pilots, a real radio) and
hands back equalised symbols plus the effective noise variance per symbol, which is what a
soft demapper or a JSCC decoder needs. Links are differentiable in ``x``.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor

from phy.channels._common import check_symbols
from phy.channels.base import Channel
from phy.ofdm.equalization import EQUALIZERS, equalize

CSI_FLAT = ("perfect", "none")


@dataclass
class LinkOutput:
    """What a link delivers.

    Attributes:
        x_hat: [batch, num_symbols] complex64 after equalisation.
        noise_var: [batch, num_symbols] float32 effective post-equalisation noise variance.
        outage: [batch] bool where the channel had no path, or ``None``.
    """

    x_hat: Tensor
    noise_var: Tensor
    outage: Tensor | None = None


def check_link_input(x: Tensor) -> Tensor:
    """Raise ValueError unless ``x`` is [batch, num_symbols] complex."""
    check_symbols(x)
    if x.dim() != 2:
        raise ValueError(f"x must be [batch, num_symbols] complex64, got shape {tuple(x.shape)}")
    return x


class FlatLink(torch.nn.Module):
    """A flat (one tap per symbol) channel and a one-tap equaliser.

    Args:
        channel: any :class:`phy.Channel` (AWGN, Rayleigh block/fast, Rician, ...).
        csi: ``"perfect"`` (the receiver knows h) or ``"none"`` (it equalises nothing:
            ``x_hat = y`` and ``noise_var`` is the channel's noise variance).
        equalizer: ``"mmse"`` or ``"zf"``; see :func:`phy.equalize` for what each returns.
    """

    def __init__(self, channel: Channel, csi: str = "perfect", equalizer: str = "mmse"):
        super().__init__()
        if not isinstance(channel, torch.nn.Module) or not callable(channel):
            raise ValueError(f"channel must be a phy Channel, got {type(channel).__name__}")
        if csi not in CSI_FLAT:
            raise ValueError(f"csi must be one of {list(CSI_FLAT)}, got {csi!r}")
        if equalizer not in EQUALIZERS:
            raise ValueError(f"equalizer must be one of {list(EQUALIZERS)}, got {equalizer!r}")
        self.channel = channel
        self.csi = csi
        self.equalizer = equalizer

    def forward(self, x: Tensor, snr_db, generator: torch.Generator | None = None) -> LinkOutput:
        """Args: x [batch, num_symbols] complex64; snr_db float or [batch] (Es/N0, dB).

        Returns: LinkOutput with x_hat [batch, num_symbols] complex64 and noise_var
        [batch, num_symbols] float32.
        """
        check_link_input(x)
        out = self.channel(x, snr_db, generator=generator)
        nv = out.noise_var.reshape(-1, 1).to(torch.float32)
        if out.h is None or self.csi == "none":
            return LinkOutput(out.y, nv.expand(out.y.shape).contiguous(), out.outage)
        x_hat, nv_eff = equalize(out.y, out.h, nv, self.equalizer)
        return LinkOutput(x_hat, nv_eff, out.outage)

    def extra_repr(self) -> str:
        return f"csi={self.csi!r}, equalizer={self.equalizer!r}"

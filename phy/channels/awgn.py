"""Additive white Gaussian noise: y = x + n, n ~ CN(0, noise_var)."""

from __future__ import annotations

import torch
from torch import Tensor

from phy.channels._common import add_noise, check_symbols, noise_var_per_batch
from phy.channels.base import Channel, ChannelOutput


class AWGN(Channel):
    """Complex AWGN with sionna.phy's convention (``noise_var`` = its ``no``, per complex sample).

    The noise is drawn with torch from the explicit ``generator`` (sionna's ``AWGN`` block
    only draws from its global RNG), so runs are reproducible per call.
    """

    kind = "awgn"

    def forward(self, x: Tensor, snr_db, generator: torch.Generator | None = None) -> ChannelOutput:
        """Args: x [batch, ...] complex64; snr_db float or [batch]. Returns y like x, h None."""
        check_symbols(x)
        nv = noise_var_per_batch(snr_db, x.shape[0], x.device)
        return ChannelOutput(y=add_noise(x, nv, generator), h=None, noise_var=nv, outage=None)

    def extra_repr(self) -> str:
        return ""

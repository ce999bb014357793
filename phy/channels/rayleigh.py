"""Rayleigh fading: y = h x + n, h ~ CN(0, 1), one h per block or one per symbol."""

from __future__ import annotations

import torch
from torch import Tensor

from phy.channels._common import (
    add_noise,
    check_mode,
    check_symbols,
    complex_normal,
    fading_shape,
    noise_var_per_batch,
)
from phy.channels.base import Channel, ChannelOutput


class RayleighFading(Channel):
    """Flat Rayleigh fading, E|h|^2 = 1.

    Args:
        mode: ``"block"`` (one h per batch row: one image, one packet) or ``"fast"``
            (an independent h per symbol).

    ``h`` is returned as [batch, 1, ...] (block) or x's shape (fast). Fading and noise are
    drawn with torch from ``generator`` (sionna's ``RayleighBlockFading`` uses a global RNG).
    """

    def __init__(self, mode: str = "block"):
        super().__init__()
        self.mode = check_mode(mode)

    @property
    def kind(self) -> str:
        """``"rayleigh"`` (block) or ``"rayleigh_fast"``."""
        return "rayleigh" if self.mode == "block" else "rayleigh_fast"

    def forward(self, x: Tensor, snr_db, generator: torch.Generator | None = None) -> ChannelOutput:
        """Args: x [batch, ...] complex64; snr_db float or [batch]. Returns y like x."""
        check_symbols(x)
        nv = noise_var_per_batch(snr_db, x.shape[0], x.device)
        h = complex_normal(fading_shape(x, self.mode), generator, x.dtype, x.device)
        return ChannelOutput(y=add_noise(h * x, nv, generator), h=h, noise_var=nv, outage=None)

    def extra_repr(self) -> str:
        return f"mode={self.mode!r}"

"""Rician fading: a line-of-sight term plus Rayleigh scatter, E|h|^2 = 1."""

from __future__ import annotations

import math

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


class RicianFading(Channel):
    """h = sqrt(K/(K+1)) exp(j phi) + sqrt(1/(K+1)) CN(0, 1), K = 10**(k_factor_db/10).

    Args:
        k_factor_db: ratio of line-of-sight to scattered power in dB, in [-30, 40]
            (-30 dB is practically Rayleigh).
        mode: ``"block"`` (one h per batch row) or ``"fast"`` (one per symbol; the
            line-of-sight phase stays fixed within a row).
        los_phase_rad: the line-of-sight phase phi; ``None`` draws it uniformly per batch row.
    """

    def __init__(
        self, k_factor_db: float = 6.0, mode: str = "block", los_phase_rad: float | None = None
    ):
        super().__init__()
        if not isinstance(k_factor_db, int | float) or not -30.0 <= float(k_factor_db) <= 40.0:
            raise ValueError(f"k_factor_db must be a number in [-30, 40] dB, got {k_factor_db!r}")
        if los_phase_rad is not None and not math.isfinite(float(los_phase_rad)):
            raise ValueError(
                f"los_phase_rad must be a finite number or None, got {los_phase_rad!r}"
            )
        self.k_factor_db = float(k_factor_db)
        self.mode = check_mode(mode)
        self.los_phase_rad = los_phase_rad

    @property
    def k_factor(self) -> float:
        """Linear K factor."""
        return 10.0 ** (self.k_factor_db / 10.0)

    @property
    def kind(self) -> str:
        """``"rician"`` (block) or ``"rician_fast"``."""
        return "rician" if self.mode == "block" else "rician_fast"

    def forward(self, x: Tensor, snr_db, generator: torch.Generator | None = None) -> ChannelOutput:
        """Args: x [batch, ...] complex64; snr_db float or [batch]. Returns y like x."""
        check_symbols(x)
        nv = noise_var_per_batch(snr_db, x.shape[0], x.device)
        k = self.k_factor
        block = (x.shape[0], *([1] * (x.dim() - 1)))
        if self.los_phase_rad is None:
            phi = 2 * math.pi * torch.rand(block, generator=generator, device=x.device)
        else:
            phi = torch.full(block, float(self.los_phase_rad), device=x.device)
        los = math.sqrt(k / (k + 1.0)) * torch.polar(torch.ones_like(phi), phi).to(x.dtype)
        scatter = complex_normal(fading_shape(x, self.mode), generator, x.dtype, x.device)
        h = los + math.sqrt(1.0 / (k + 1.0)) * scatter
        return ChannelOutput(y=add_noise(h * x, nv, generator), h=h, noise_var=nv, outage=None)

    def extra_repr(self) -> str:
        return f"k_factor_db={self.k_factor_db}, mode={self.mode!r}"

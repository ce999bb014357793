"""Generalised divisive normalisation (Balle et al. 2016) and its inverse.

``GDN(x)_i = x_i / sqrt(beta_i + sum_j gamma_ij x_j^2)``; IGDN multiplies instead.
beta and gamma are kept non-negative by a squared reparametrisation with a floor.
"""

from __future__ import annotations

import torch
from torch import Tensor, nn
from torch.nn import functional as F

_PEDESTAL = 2.0**-18


class GDN(nn.Module):
    """GDN over channels of a [batch, channels, height, width] float32 tensor.

    Args:
        channels: number of feature channels.
        inverse: IGDN (decoder side) when True.
        beta_min: floor on beta, keeps the denominator away from zero.
        gamma_init: initial diagonal of gamma.
    """

    def __init__(
        self, channels: int, inverse: bool = False, beta_min: float = 1e-6, gamma_init: float = 0.1
    ):
        super().__init__()
        self.inverse = inverse
        self._beta_bound = (beta_min + _PEDESTAL) ** 0.5
        self.beta = nn.Parameter(torch.sqrt(torch.ones(channels) + _PEDESTAL))
        self.gamma = nn.Parameter(torch.sqrt(gamma_init * torch.eye(channels) + _PEDESTAL))

    def forward(self, x: Tensor) -> Tensor:
        """x: [batch, channels, height, width] -> same shape."""
        beta = self.beta.clamp_min(self._beta_bound) ** 2 - _PEDESTAL
        gamma = self.gamma.clamp_min(_PEDESTAL**0.5) ** 2 - _PEDESTAL
        c = gamma.shape[0]
        norm = F.conv2d(x * x, gamma.reshape(c, c, 1, 1), beta)
        return x * torch.sqrt(norm) if self.inverse else x * torch.rsqrt(norm)

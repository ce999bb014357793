"""Gray-coded constellations (sionna.phy's), bit mapping and hard decisions.

The points and their bit labels are those of ``sionna.phy.mapping.Constellation`` (BPSK =
2-PAM, QPSK/16-QAM/64-QAM as in 3GPP 38.211, unit average energy; a test checks equality),
so uncoded and coded chains use the same mapping. They are computed here so that mapping
does not import sionna (about 3 s). Point ``i`` carries the bits of ``i`` MSB first.
"""

from __future__ import annotations

import functools

import numpy as np
import torch
from torch import Tensor

from common import Registry

MODULATIONS = Registry[int]("modulation", {"bpsk": 1, "qpsk": 2, "16qam": 4, "64qam": 6})
"""name -> bits per symbol (Gray-mapped QAM; BPSK)."""


def bits_per_symbol(modulation: str) -> int:
    """Bits per symbol of a registered modulation; unknown names raise KeyError listing them."""
    return MODULATIONS[modulation]


def _pam_gray(bits: np.ndarray) -> np.ndarray:
    """3GPP 38.211 amplitude of Gray-labelled PAM: (1 - 2 b0) (2**(n-1) - pam(b1..)), [..., n] ->
    [...]."""
    n = bits.shape[-1]
    if n == 1:
        return 1.0 - 2.0 * bits[..., 0]
    return (1.0 - 2.0 * bits[..., 0]) * (2 ** (n - 1) - _pam_gray(bits[..., 1:]))


@functools.cache
def _points(modulation: str) -> Tensor:
    """sionna.phy.mapping.Constellation's points (equality checked in the tests), without
    importing sionna: I from the even bits, Q from the odd bits, unit mean energy."""
    k = bits_per_symbol(modulation)
    labels = (np.arange(2**k)[:, None] >> np.arange(k - 1, -1, -1)[None, :]) & 1  # [M, k] MSB first
    if modulation == "bpsk":
        pts = _pam_gray(labels).astype(np.complex128)
    else:
        pts = _pam_gray(labels[:, 0::2]) + 1j * _pam_gray(labels[:, 1::2])
    pts = pts / np.sqrt(np.mean(np.abs(pts) ** 2))
    return torch.tensor(pts, dtype=torch.complex64)


def constellation(modulation: str) -> Tensor:
    """[2**bits_per_symbol] complex64 points, unit mean energy; index i carries bits(i) MSB
    first."""
    return _points(modulation).clone()


def _bit_weights(k: int, device) -> Tensor:
    return 2 ** torch.arange(k - 1, -1, -1, device=device)


def map_bits(bits: Tensor, modulation: str) -> Tensor:
    """Map bits to symbols.

    Args:
        bits: [batch, num_symbols * bits_per_symbol] integer or float tensor of 0/1.
    Returns:
        [batch, num_symbols] complex64.
    """
    k = bits_per_symbol(modulation)
    if not isinstance(bits, Tensor) or bits.dim() < 1:
        raise ValueError("bits must be a torch.Tensor [batch, num_bits] of 0/1")
    if bits.shape[-1] % k:
        raise ValueError(
            f"bits: last dimension ({bits.shape[-1]}) must be a multiple of {k} for {modulation}"
        )
    b = bits.reshape(*bits.shape[:-1], -1, k).to(torch.int64)  # [..., num_symbols, k]
    idx = (b * _bit_weights(k, b.device)).sum(-1)
    return _points(modulation).to(bits.device)[idx]


def hard_decision(y: Tensor, modulation: str, chunk: int = 1 << 16) -> Tensor:
    """Index of the nearest constellation point (ML detection for equalised symbols).

    Args:
        y: [..., num_symbols] complex.
    Returns:
        [..., num_symbols] int64 point indices.
    """
    pts = _points(modulation).to(y.device)
    flat = y.reshape(-1)
    out = torch.empty(flat.shape, dtype=torch.int64, device=y.device)
    for s in range(0, flat.numel(), chunk):
        d = (flat[s : s + chunk, None] - pts[None, :]).abs()  # [chunk, num_points]
        out[s : s + chunk] = d.argmin(dim=1)
    return out.reshape(y.shape)


def indices_to_bits(idx: Tensor, modulation: str) -> Tensor:
    """[..., num_symbols] int64 -> [..., num_symbols * bits_per_symbol] uint8, MSB first."""
    k = bits_per_symbol(modulation)
    bits = (idx[..., None] // _bit_weights(k, idx.device)) % 2  # [..., num_symbols, k]
    return bits.reshape(*idx.shape[:-1], -1).to(torch.uint8)


def demap_hard(y: Tensor, modulation: str) -> Tensor:
    """Hard-decision bits: [..., num_symbols] complex -> [..., num_symbols * k] uint8."""
    return indices_to_bits(hard_decision(y, modulation), modulation)

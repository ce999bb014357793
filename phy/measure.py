"""What a receiver measures on a link with known pilots: its SNR, and whether two copies of
a block fade independently.

Both send QPSK pilot blocks through a ``phy.Link`` (``link(x, snr_db, generator) ->
LinkOutput`` with unbiased estimates and their per-symbol noise variance).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch


@dataclass(frozen=True)
class CopyFading:
    """Whether two copies of a block see independent fades (:func:`measure_copy_fading`).

    Attributes:
        spread_db: std of the per-symbol post-equalisation SNR (dB) about each view's mean.
        correlation: correlation of those deviations between the two copies of each symbol.
    """

    spread_db: float
    correlation: float

    def independent(self, min_spread_db: float, max_correlation: float) -> bool:
        """The copies fade (spread at least ``min_spread_db``) and not together (correlation
        below ``max_correlation``): combining them buys diversity."""
        return self.spread_db >= min_spread_db and self.correlation < max_correlation


def qpsk_pilots(num_blocks: int, num_pilots: int, generator: torch.Generator) -> torch.Tensor:
    """[num_blocks, num_pilots] unit-power QPSK symbols, complex64."""
    bits = torch.randint(0, 2, (num_blocks, num_pilots, 2), generator=generator)
    return ((1 - 2 * bits[..., 0]) + 1j * (1 - 2 * bits[..., 1])).to(torch.complex64) / math.sqrt(2)


def measure_snr_db(
    links, snr_db, generator: torch.Generator, num_pilots: int = 256, num_blocks: int = 8
) -> np.ndarray:
    """Post-equalisation SNR per link from known QPSK pilot blocks.

    Per block, the LMMSE pilots ``x_hat / (1 + noise_var) = g x + e`` give the gain
    ``g = <x, x_hat> / <x, x>`` and the unbiased SNR ``|g|^2 / var(e)`` (``|h|^2 snr`` on
    block fading, ``1 / noise_var`` on AWGN; robust to the deep fades of fast fading, where
    ZF's error alone would diverge). The linear SNR is averaged over ``num_blocks`` blocks
    (independent fades on a block-fading link: the long-term SNR a rate is chosen on).

    Args:
        links: one link per view.
        snr_db: one SNR per link (what it runs at).
    Returns:
        [num_links] float measured SNR in dB.
    """
    out = []
    for link, s in zip(links, snr_db):
        x = qpsk_pilots(num_blocks, num_pilots, generator)
        y = link(x, float(s), generator=generator)
        z = y.x_hat / (1.0 + y.noise_var.clamp(0.0, 1e6))  # LMMSE
        g = (x.conj() * z).sum(-1, keepdim=True) / (x.abs() ** 2).sum(
            -1, keepdim=True
        )  # [blocks, 1]
        e = (z - g * x).abs().pow(2).mean(-1)  # [blocks]
        snr = (g.abs().squeeze(-1) ** 2 / e.clamp_min(1e-12)).mean()
        out.append(10 * math.log10(max(float(snr), 1e-3)))
    return np.asarray(out)


def measure_copy_fading(
    links, snr_db, generator: torch.Generator, num_pilots: int = 256, num_pairs: int = 4
) -> CopyFading:
    """Whether copies fade independently: ``num_pairs`` QPSK pilot blocks per link, each
    sent twice back to back, and the per-symbol SNR the receiver reports (``1 / noise_var``,
    dB) compared between the two copies, pooled over the links after removing each link's
    mean.

    Args:
        links: one link per view.
        snr_db: one SNR per link (what it runs at).
    """
    first, second = [], []
    for link, s in zip(links, snr_db):
        x = qpsk_pilots(num_pairs, num_pilots, generator)
        y = link(x.repeat_interleave(2, dim=0), float(s), generator=generator)
        db = -10.0 * torch.log10(y.noise_var.double().clamp(1e-12, 1e12))
        db = db - db.mean()
        first.append(db[0::2].flatten())
        second.append(db[1::2].flatten())
    a, b = torch.cat(first), torch.cat(second)
    va, vb = float((a * a).mean()), float((b * b).mean())
    spread = math.sqrt((va + vb) / 2.0)
    corr = float((a * b).mean()) / math.sqrt(va * vb) if va * vb > 1e-18 else 0.0
    return CopyFading(spread_db=spread, correlation=corr)

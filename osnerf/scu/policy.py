"""The SCU's rate policy: CBR per measured SNR, when to send copies, how far to oversample
the demanded objects, the SNR the codec is told after the copies are combined, and the SNR
each transmitter believes (:func:`transmitter_estimate`)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch

from osnerf.scheme_types import scheme_seed


@dataclass(frozen=True)
class RatePolicy:
    """CBR per measured SNR: lower SNR -> more channel symbols per source value.

    The SNR (dB) falls in band ``k`` when it is below ``thresholds_db[k]`` (and above the
    previous one); the last band is everything above the last threshold.

    Attributes:
        thresholds_db: ascending band edges, dB.
        cbrs: one CBR per band (len(thresholds_db) + 1), each in (0, 1].
        repeat_below_db: below it a block is sent twice and the copies MRC-combined.
    """

    thresholds_db: tuple[float, ...] = (0.0, 5.0, 10.0)
    cbrs: tuple[float, ...] = (1 / 8, 1 / 12, 1 / 16, 1 / 24)
    repeat_below_db: float = 3.0
    """Below this measured SNR every view costs twice its CBR, sent as two MRC-combined copies.
    On-demand views send copies only where they fade independently (``phy.CopyFading``);
    otherwise the second copy's symbols are spent as rate: on a static channel a copy buys
    only the 3 dB combining gain, which the codec's rate beats (docs/design-notes.md, "End to
    end")."""
    copy_spread_db: float = 1.0
    """Copies can fade independently only where the per-symbol SNR spreads (std about each
    view's mean, dB) by at least this: a flat static channel (AWGN) has no fades to escape."""
    max_copy_correlation: float = 0.5
    """... and where the two copies' per-symbol SNR deviations correlate less than this (a
    static multipath channel repeats its frequency fades in every copy; block, fast and TDL
    fading do not)."""
    static_repeat_below_db: float = -5.0
    """Where copies do not fade independently, views measured below this still send copies:
    near the bottom of the codec's SNR range 3 dB of SNR is worth more than the rate."""
    max_object_oversampling: int = 3
    """Largest factor s by which the demanded objects are upsampled before encoding (s^2 times
    the feature positions), >= 1."""
    object_budget_fraction: float = 2 / 3
    """On-demand views cost this fraction of what sending every view whole would cost at the
    same SNR (the full-scene budget): the symbols saved by not sending the background are
    spent on the objects through oversampling. In (0, 1]."""
    min_position_cbr: float = 0.09
    """The SCU takes the largest oversampling at which the on-demand budget gives every
    feature position touching the objects at least this CBR (the codec's largest CBR is
    every channel on them), and scales the rate to spend the budget, in (0, 1]: a larger
    oversampling at too few channels per position loses to a smaller one at more. A CBR per
    position, not a fraction of the codec's largest CBR, so it holds across codecs
    (docs/design-notes.md, "Defaults")."""

    def __post_init__(self):
        if len(self.cbrs) != len(self.thresholds_db) + 1:
            raise ValueError(
                f"cbrs must have len(thresholds_db) + 1 = {len(self.thresholds_db) + 1} entries"
            )
        if list(self.thresholds_db) != sorted(self.thresholds_db):
            raise ValueError(f"thresholds_db must be ascending, got {self.thresholds_db}")
        if any(not 0 < c <= 1 for c in self.cbrs):
            raise ValueError(f"cbrs must be in (0, 1], got {self.cbrs}")
        if self.max_object_oversampling < 1:
            raise ValueError(
                f"max_object_oversampling must be >= 1, got {self.max_object_oversampling}"
            )
        if self.copy_spread_db < 0:
            raise ValueError(f"copy_spread_db must be >= 0, got {self.copy_spread_db}")
        if not -1 <= self.max_copy_correlation <= 1:
            raise ValueError(
                f"max_copy_correlation must be in [-1, 1], got {self.max_copy_correlation}"
            )
        for name in ("object_budget_fraction", "min_position_cbr"):
            if not 0 < getattr(self, name) <= 1:
                raise ValueError(f"{name} must be in (0, 1], got {getattr(self, name)}")

    def copies_independent(self, copy_fading) -> bool:
        """Whether copies fade independently on links with these pilot measurements
        (``phy.CopyFading.independent`` at :attr:`copy_spread_db` and
        :attr:`max_copy_correlation`): where they do not, the link is static."""
        return copy_fading.independent(self.copy_spread_db, self.max_copy_correlation)

    def cbr_for(self, snr_db: float) -> float:
        """The CBR of the band ``snr_db`` falls in."""
        k = int(np.searchsorted(np.asarray(self.thresholds_db), float(snr_db), side="right"))
        return float(self.cbrs[k])


def combined_snr_db(measured_snr_db: float, repetitions: int, snr_range_db) -> float:
    """The average SNR after MRC of ``repetitions`` copies (their SNRs add), clamped to the
    codec's range: what the encoder is told and the decoder's AF modules see."""
    snr = float(measured_snr_db) + 10.0 * math.log10(max(int(repetitions), 1))
    return float(np.clip(snr, *snr_range_db))


def transmitter_estimate(
    measured_snr_db: np.ndarray, plan_snr_db: float | None, snr_error_db: float, seed: int
) -> np.ndarray:
    """Each view's SNR as its transmitter believes it: the pilot measurement (or
    ``plan_snr_db`` for every view) plus a zero-mean Gaussian error of ``snr_error_db`` drawn
    from the run seed (its own stream), the same for every scheme. Unchanged with neither.

    Args:
        measured_snr_db: [num_views] the SCU's measurements.
    Returns:
        [num_views] float64.
    """
    est = np.asarray(measured_snr_db, dtype=np.float64)
    if plan_snr_db is not None:
        est = np.full_like(est, float(plan_snr_db))
    if snr_error_db:
        gen = torch.Generator().manual_seed(scheme_seed(seed, "scu", "estimate error"))
        z = torch.randn(est.shape, generator=gen, dtype=torch.float64).numpy()
        est = est + float(snr_error_db) * z
    return est

"""The numbers of one ``osnerf eval-codec`` point: each draw's seed, what the transmitter
believes the SNR is, what a point tallies over its images x draws, and the statistics of the
result (mean with its bootstrap interval, outage percentiles)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from common import ms_ssim, psnr
from renderer import lpips
from semcodec.links import ssim

ESTIMATE_STREAM = 0x5E57
"""Tag of the SNR-estimate error's random stream (apart from every channel draw)."""


def draw_seed(seed: int, snr_index: int, image_index: int, draw: int) -> int:
    """Seed of one draw, the same in every scheme (common random numbers)."""
    return ((seed * 1_000_003 + snr_index) * 100_003 + image_index) * 1_009 + draw


CI_MIN_VALUES = 5
"""Fewer images x draws than this give no interval: with so few a bootstrap only repeats
the values (its interval would claim what they cannot show)."""
CI_RESAMPLES = 10_000
INTERVAL_TEXT = (
    f"95% percentile bootstrap interval of the mean over images x draws ({CI_RESAMPLES} "
    f"resamples, seed 0); none (null) with fewer than {CI_MIN_VALUES} values"
)


def snr_belief(
    snr_db: float,
    plan_snr_db: float | None,
    snr_error_db: float,
    seed: int,
    snr_index: int,
    image_index: int,
    draw: int,
) -> float | None:
    """What the transmitter believes the average SNR of one draw is: ``plan_snr_db`` (else
    the truth) plus ``snr_error_db`` times a standard normal from the run's seed, the same
    for every scheme (its own stream: the channel's draws are untouched). None when it
    knows the truth exactly (no plan, no error)."""
    if plan_snr_db is None and not snr_error_db:
        return None
    believed = float(snr_db if plan_snr_db is None else plan_snr_db)
    if snr_error_db:
        rng = np.random.default_rng([ESTIMATE_STREAM, seed, snr_index, image_index, draw])
        believed += float(snr_error_db) * float(rng.standard_normal())
    return believed


def outage_stats(psnrs, lost: int, total: int) -> dict:
    """Per-image outage statistics over images x draws: the 5th and 10th percentile of PSNR
    and the fraction of images lost (received as nothing)."""
    v = np.asarray(psnrs, dtype=np.float64)
    return {
        "psnr_p5": float(np.percentile(v, 5)),
        "psnr_p10": float(np.percentile(v, 10)),
        "lost_fraction": lost / total if total else 0.0,
    }


def mean_ci95(values) -> tuple[float, float | None, float | None]:
    """(mean, low, high): the 95 % percentile bootstrap interval of the mean, resampling
    the values with replacement (a fixed seed: the same values give the same interval). It
    lies within the values' range, so within what a PSNR can be; (mean, None, None) with
    fewer than :data:`CI_MIN_VALUES` values."""
    v = np.asarray(values, dtype=np.float64).reshape(-1)
    m = float(v.mean())
    if v.size < CI_MIN_VALUES:
        return m, None, None
    rng = np.random.default_rng(0)
    means = v[rng.integers(0, v.size, size=(CI_RESAMPLES, v.size))].mean(axis=1)
    lo, hi = np.quantile(means, [0.025, 0.975])
    return m, float(lo), float(hi)


@dataclass
class DrawTally:
    """What one (scheme, SNR) point gathers over its images x draws, draw by draw.

    Attributes:
        score_lpips: whether LPIPS is scored.
        psnr: [image][draw] PSNR.
        ssim, ms_ssim, lpips: per draw, in order (MS-SSIM None under its smallest size).
        beliefs: [image][draw] the SNR the transmitter planned for.
        forecast: the digital planner's expected number of lost images (None: no forecast).
        extra: failed codewords, lost images and symbols sent, summed.
        lost: views lost by cause (a separate source-channel code's).
        mcs_used, scales_used: draws per MCS, images sent downscaled by each factor (1: whole).
        stats_keys: the scheme's last ``mcs_choice``, ``calibration``, ``resample_filter``.
        separate: the scheme reported views lost (a separate source-channel code).
        budget: the codec's symbol budget over images x draws (semantic schemes).
    """

    score_lpips: bool
    psnr: list[list[float]] = field(default_factory=list)
    ssim: list[float] = field(default_factory=list)
    ms_ssim: list[float | None] = field(default_factory=list)
    lpips: list[float] = field(default_factory=list)
    beliefs: list[list[float]] = field(default_factory=list)
    forecast: float | None = None
    extra: dict[str, int] = field(
        default_factory=lambda: {"failed_codewords": 0, "lost_images": 0, "num_symbols": 0}
    )
    lost: dict[str, int] = field(default_factory=lambda: {"budget": 0, "channel": 0})
    mcs_used: dict[str, int] = field(default_factory=dict)
    scales_used: dict[str, int] = field(default_factory=dict)
    stats_keys: dict = field(default_factory=dict)
    separate: bool = False
    budget: int | None = None

    def add(self, res, img) -> float:
        """Tally one draw's received images ``res`` against ``img``; returns its PSNR."""
        value = psnr(res.images, img)
        self.ssim.append(ssim(res.images, img))
        self.ms_ssim.append(ms_ssim(res.images, img))
        if res.stats.get("forecast_loss") is not None:
            self.forecast = (self.forecast or 0.0) + sum(res.stats["forecast_loss"])
        if self.score_lpips:
            self.lpips.append(float(lpips(res.images.clamp(0, 1), img)[0]))
        for k in self.extra:
            self.extra[k] += int(res.stats.get(k, 0) or 0)
        if "symbol_budget" in res.stats:  # the semantic codec's: sent against asked
            self.budget = (self.budget or 0) + int(res.stats["symbol_budget"])
        self.separate = self.separate or "views_lost" in res.stats
        for k, v in (res.stats.get("views_lost") or {}).items():
            self.lost[k] += int(v)
        for m in res.stats.get("mcs") or []:
            self.mcs_used[str(m)] = self.mcs_used.get(str(m), 0) + 1
        for sc in res.stats.get("scale") or []:
            self.scales_used[str(sc)] = self.scales_used.get(str(sc), 0) + 1
        for k in ("mcs_choice", "calibration", "resample_filter"):
            if k in res.stats:
                self.stats_keys[k] = res.stats[k]
        return value

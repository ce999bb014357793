"""Per-position statistics of a ray-traced channel impulse response (pure numpy).

For one position with valid paths ``i`` of power ``p_i = |a_i|^2`` and delay ``tau_i``:

* path gain ``G = sum_i p_i`` (wideband, linear; ``path_gain_db = 10 log10 G``);
* RMS delay spread ``sqrt(sum p_i tau_i^2 / G - (sum p_i tau_i / G)^2)``;
* Rician K factor estimate ``max_i p_i / (G - max_i p_i)``: the dominant path against the
  rest (the LoS path when there is one); ``inf`` for a single path;
* for a moving transmitter whose paths have Doppler shifts ``f_i``: the mean Doppler
  ``sum p_i f_i / G`` and the RMS Doppler spread ``sqrt(sum p_i f_i^2 / G - mean^2)``, the
  power-weighted spread of the Doppler spectrum (0 at rest).

In outage (no path) nothing is NaN: ``path_gain_db = -inf``, delay spread 0, K factor 0.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class RayStats:
    """Statistics for ``num_positions`` transmitter positions.

    Attributes:
        path_gain_db: [num_positions] float64, ``-inf`` in outage.
        rms_delay_spread_s: [num_positions] float64, 0 in outage.
        k_factor: [num_positions] float64 linear Rician K estimate (0 in outage, inf with
            a single path).
        num_paths: [num_positions] int64 valid paths.
        los: [num_positions] bool, a line-of-sight path exists.
        outage: [num_positions] bool, no path at all.
        mean_doppler_hz: [num_positions] float64 power-weighted mean Doppler shift.
        rms_doppler_spread_hz: [num_positions] float64 RMS Doppler spread (0 at rest).
    """

    path_gain_db: np.ndarray
    rms_delay_spread_s: np.ndarray
    k_factor: np.ndarray
    num_paths: np.ndarray
    los: np.ndarray
    outage: np.ndarray
    mean_doppler_hz: np.ndarray
    rms_doppler_spread_hz: np.ndarray

    @property
    def k_factor_db(self) -> np.ndarray:
        """[num_positions] float64: ``10 log10 k_factor`` (``-inf`` in outage)."""
        with np.errstate(divide="ignore"):
            return 10.0 * np.log10(self.k_factor)

    def records(self) -> list[dict]:
        """One JSON-safe dict per position; non-finite numbers become ``None``."""

        def num(v: float):
            return float(v) if math.isfinite(v) else None

        k_db = self.k_factor_db
        return [
            {
                "path_gain_db": num(self.path_gain_db[i]),
                "rms_delay_spread_s": num(self.rms_delay_spread_s[i]),
                "k_factor_db": num(k_db[i]),
                "num_paths": int(self.num_paths[i]),
                "los": bool(self.los[i]),
                "outage": bool(self.outage[i]),
                "mean_doppler_hz": float(self.mean_doppler_hz[i]),
                "rms_doppler_spread_hz": float(self.rms_doppler_spread_hz[i]),
            }
            for i in range(len(self.outage))
        ]


def _weighted_spread(p: np.ndarray, x: np.ndarray, safe: np.ndarray):
    """Power-weighted mean and RMS spread of ``x`` over the paths (axis 1)."""
    mean = (p * x).sum(axis=1) / safe
    return mean, np.sqrt(np.maximum((p * x**2).sum(axis=1) / safe - mean**2, 0.0))


def cir_stats(
    a: np.ndarray,
    tau_s: np.ndarray,
    valid: np.ndarray,
    los: np.ndarray,
    doppler_hz: np.ndarray | None = None,
) -> RayStats:
    """Statistics from padded CIRs.

    Args:
        a: [num_positions, max_paths] complex path coefficients (0 where not valid).
        tau_s: [num_positions, max_paths] float delays in seconds.
        valid: [num_positions, max_paths] bool.
        los: [num_positions] bool.
        doppler_hz: [num_positions, max_paths] float Doppler shifts (None: at rest).
    Returns:
        :class:`RayStats`.
    """
    p = np.where(valid, np.abs(a).astype(np.float64) ** 2, 0.0)  # [num_positions, max_paths]
    tau = np.where(valid, tau_s.astype(np.float64), 0.0)
    gain = p.sum(axis=1)
    outage = gain <= 0.0
    safe = np.where(outage, 1.0, gain)
    _, spread_tau = _weighted_spread(p, tau, safe)
    fd = np.zeros_like(p) if doppler_hz is None else np.where(valid, doppler_hz, 0.0)
    mean_fd, spread_fd = _weighted_spread(p, fd.astype(np.float64), safe)
    p_max = p.max(axis=1, initial=0.0)
    rest = gain - p_max
    with np.errstate(divide="ignore", invalid="ignore"):
        k = np.where(rest > 0, p_max / np.where(rest > 0, rest, 1.0), np.inf)
        path_gain_db = np.where(outage, -np.inf, 10.0 * np.log10(safe))
    k = np.where(outage, 0.0, k)
    return RayStats(
        path_gain_db=path_gain_db,
        rms_delay_spread_s=np.where(outage, 0.0, spread_tau),
        k_factor=k,
        num_paths=valid.sum(axis=1).astype(np.int64),
        los=np.asarray(los, dtype=bool) & ~outage,
        outage=outage,
        mean_doppler_hz=np.where(outage, 0.0, mean_fd),
        rms_doppler_spread_hz=np.where(outage, 0.0, spread_fd),
    )

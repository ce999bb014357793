"""Estimation for the over-the-air receiver: channel, common phase, timing drift.

Pure numpy on the FFT outputs of one frame, ``[num_rows, fft_size]`` in centred order,
where row ``l`` holds OFDM symbol ``l`` (training symbols first) and known reference values
``x`` (training carriers, pilots) sit on some carriers. The model of a frame whose CFO has
been removed is::

    y[l, k] = h[k] exp(j phi[l]) exp(-2j pi k tau[l] / fft_size) x[l, k] + n[l, k]

with a channel ``h`` static over the frame whose taps lie within the cyclic prefix, a
common phase ``phi`` (residual CFO: linear in l; phase noise: slow), and a timing drift
``tau`` (sampling-clock offset: linear in time). Every estimate pools the whole frame, so
it holds at -10 dB per sample where one OFDM symbol's pilots alone do not.
"""

from __future__ import annotations

import cmath
import math

import numpy as np
import scipy.fft

PHASE_WINDOW_SNR = 30.0  # per-symbol phases are smoothed over rows until this pooled SNR
DRIFT_SIGNIFICANCE = 4.0  # a timing drift is kept when it is this many standard errors


def delay_basis(carriers: np.ndarray, fft_size: int, delays: np.ndarray) -> np.ndarray:
    """``F[k, t] = exp(-2j pi (carrier_k - fft_size / 2) delay_t / fft_size)``.

    Args:
        carriers: [num_carriers] centred-order indices.
        delays: [num_taps] tap delays in samples.
    Returns:
        [num_carriers, num_taps] complex128.
    """
    f = np.asarray(carriers, np.float64) - fft_size // 2
    return np.exp(-2j * np.pi * np.outer(f, np.asarray(delays, np.float64)) / fft_size)


def channel_smoother(counts: np.ndarray, basis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Weighted least squares for a channel whose taps lie on ``basis``'s delays.

    Each carrier k has ``counts[k]`` unbiased observations ``h[k] + e`` (``E|e|^2 = sigma^2``)
    summing to ``obs_sum[k]``. The LS estimate ``obs_sum / counts`` has MSE
    ``sigma^2 / counts``; truncating to T taps fits ``taps = (F^H W F)^-1 F^H obs_sum`` with
    ``W = diag(counts)``, i.e. ``h = P obs_sum`` with ``P = F (F^H W F)^-1 F^H``, whose
    per-carrier MSE is ``sigma^2 P_kk`` (mean ``sigma^2 T / (num_carriers counts)`` for
    equal counts).

    Args:
        counts: [num_carriers] float > 0.
        basis: [num_carriers, num_taps] from :func:`delay_basis`.
    Returns:
        (P [num_carriers, num_carriers] complex128, mse_factor [num_carriers] float64:
        MSE / sigma^2).
    """
    fh = basis.conj().T  # [num_taps, num_carriers]
    gram = (fh * counts[None, :]) @ basis
    p = basis @ np.linalg.solve(gram, fh)
    return p, np.maximum(np.diag(p).real, 0.0)


def _moving_sum(a: np.ndarray, width: int) -> np.ndarray:
    """Centred moving sum over ``width`` (odd) entries, truncated at the ends."""
    half = width // 2
    c = np.concatenate([[0], np.cumsum(a)])
    i = np.arange(a.size)
    return c[np.minimum(i + half + 1, a.size)] - c[np.maximum(i - half, 0)]


def slope_search(a: np.ndarray) -> float:
    """The slope (radians per row) of the line ``exp(j w l)`` that best fits ``a`` [rows]:
    the strongest bin of a zero-padded FFT across rows (four bins per 1 / rows)."""
    m = 4 << max(0, math.ceil(math.log2(max(a.size, 1))))
    spec = scipy.fft.fft(a, m)
    power = spec.real * spec.real
    power += spec.imag * spec.imag
    return 2 * np.pi * (((int(np.argmax(power)) / m) + 0.5) % 1.0 - 0.5)


def track_phase(
    a: np.ndarray, snr_row: float, slope_hint: float | None = None
) -> tuple[np.ndarray, float]:
    """Common phase of every row from its pilot sums ``a[l] = g exp(j phi[l]) + noise``.

    A line (residual CFO) found by an FFT across rows and refined by the phase between the
    halves, then the residual smoothed over as many rows as it takes to reach
    ``PHASE_WINDOW_SNR`` (1 row at high SNR: tracks phase noise; the line alone when the
    rows are very noisy).

    Args:
        a: [num_rows] complex.
        snr_row: SNR of one row's sum, ``|g|^2 / noise`` (linear).
        slope_hint: a previous estimate of the slope (skips the FFT search).
    Returns:
        (phi [num_rows] float64 radians, slope radians per row).
    """
    rows = a.size
    idx = np.arange(rows)
    w = slope_search(a) if slope_hint is None else float(slope_hint)
    if rows >= 2:
        b = np.exp(-1j * w * idx)  # the line removed, summed over each half
        h = rows // 2
        w += (
            cmath.phase(complex(a[h : 2 * h] @ b[h : 2 * h]) * complex(a[:h] @ b[:h]).conjugate())
            / h
        )
    unrotated = np.exp(-1j * w * idx)
    phi0 = cmath.phase(complex(a @ unrotated))
    line = phi0 + w * idx
    width = int(math.ceil(PHASE_WINDOW_SNR / max(snr_row, 1e-6))) | 1
    if width >= rows:
        return line, w
    resid = a * unrotated
    resid *= cmath.exp(-1j * phi0)  # a exp(-j line)
    if width == 1:  # each row's own phase (a moving sum over one row is the row)
        return line + np.angle(resid), w
    return line + np.angle(_moving_sum(resid, width)), w


def track_delay(
    z: np.ndarray,
    pairs: np.ndarray,
    pair_step: int,
    times: np.ndarray,
    fft_size: int,
    snr_row: float,
) -> float:
    """Timing drift (samples per sample: the sampling-clock offset) from pilot observations.

    Rows are pooled in blocks until a block's pilots reach ``PHASE_WINDOW_SNR``; each
    block's delay comes from the phase step between pilots ``pair_step`` carriers apart;
    a weighted line through the blocks' delays against time gives the drift.

    Args:
        z: [num_rows, num_pilots] complex: pilot observations with the channel, common phase
            and the current drift model removed (about ``|h|^2`` times the residual ramp).
        pairs: [num_pairs] pilot indices j whose pilot j + 1 sits ``pair_step`` carriers above.
        times: [num_rows] sample time of each row.
    Returns:
        the residual drift (add it to the current model's); 0 when it is not
        ``DRIFT_SIGNIFICANCE`` standard errors away from 0.
    """
    rows = z.shape[0]
    block = min(rows, int(math.ceil(PHASE_WINDOW_SNR / max(snr_row, 1e-6))))
    nb = rows // block
    if nb < 2:
        return 0.0
    if block == 1:  # every row a block of its own
        zb, tb = z, times
    else:
        zb = z[: nb * block].reshape(nb, block, -1).sum(axis=1)  # [num_blocks, num_pilots]
        tb = times[: nb * block].reshape(nb, block).mean(axis=1)
    g = np.einsum("ij,ij->i", zb[:, pairs + 1], np.conj(zb[:, pairs]))  # [num_blocks]
    tau = np.angle(g) * (-fft_size / (2 * np.pi * pair_step))
    wgt = np.abs(g)
    sw = max(float(wgt.sum()), 1e-30)
    dt = tb - float(wgt @ tb) / sw
    wdt = wgt * dt
    sxx = float(wdt @ dt) / sw
    if sxx <= 0 or nb < 4:
        return 0.0
    slope = float(wdt @ tau) / sw / sxx
    resid = tau - (float(wgt @ tau) / sw + slope * dt)
    var_slope = float(wgt @ (resid * resid)) / sw / sxx / (nb - 2)
    # a drift that the blocks cannot tell from zero is zero (low SNR: no random walk)
    return slope if slope**2 > DRIFT_SIGNIFICANCE**2 * var_slope else 0.0

"""The over-the-air receiver: find frames in a capture and recover their symbols.

Acquisition (per candidate): Schmidl-Cox plateau -> fractional CFO -> even integer CFO from
the first long training symbol -> first-path timing by cross-correlation -> confirmation by
both long training symbols. Demodulation: DC removal, one CFO rotation (fine CFO from the
two long training symbols), channel estimate (their average), per-symbol pilot tracking of
timing drift (a line fit; the FFT window moves when it passes half a sample) and common
phase, noise from pilot residuals, one-tap ZF/MMSE. See :mod:`phy.frame` for the waveform.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch

from phy import sync
from phy.frame import FrameConfig, _as_complex_1d, _preamble, _time_body
from phy.ofdm.equalization import EQUALIZERS, equalize
from phy.ofdm.resource_grid import extract_data


@dataclass
class FrameResult:
    """What :func:`receive_frame` recovered.

    Attributes:
        symbols: [num_symbols] complex64 torch tensor, equalised (zeros when not detected).
        noise_var: [num_symbols] float32 torch tensor, effective noise variance per symbol
            (``inf`` when not detected).
        start_index: first sample of the frame in the given stream (-1 when not detected).
        cfo_hz: estimated carrier-frequency offset; ``cfo_subcarriers`` the same in carriers.
        sco_ppm: estimated sampling-clock offset (positive: the frame arrives stretched).
        snr_db_estimate: mean |H|^2 / N0 on the used carriers in dB, N0 from the difference
            of the two long training symbols: the SNR of random noise alone.
        effective_snr_db: the same with the noise the data saw (pilot residuals: noise plus
            quantisation, I/Q image, ISI/ICI); what ``noise_var`` is based on.
        detected: whether a complete frame was found.
    """

    symbols: torch.Tensor
    noise_var: torch.Tensor
    start_index: int
    cfo_hz: float
    cfo_subcarriers: float
    sco_ppm: float
    snr_db_estimate: float
    detected: bool
    effective_snr_db: float = float("nan")


def _without_dc(r: np.ndarray) -> np.ndarray:
    """Remove the capture's mean (an SDR's DC offset would make silence look periodic)."""
    return (r - r.mean()).astype(np.complex64) if r.size else r


def _acquire(r: np.ndarray, cfg: FrameConfig) -> list[tuple[int, float]]:
    """Every frame start in ``r`` with its CFO (subcarriers): [(start_index, cfo)]."""
    n, cp, s = cfg.fft_size, cfg.cp_length, cfg.symbol_length
    metric, p = sync.schmidl_cox_metric(r, n // 2)
    if metric.size == 0:
        return []
    w = max(1, cp // 2)
    smooth = sync.sliding_sum(metric, w) / w if metric.size >= w else metric
    runs = sync.detect_plateaus(smooth, cfg.detection_threshold, max(1, cp // 4), merge_gap=cp)
    sc_freq, lts_freq = _preamble(cfg)
    lts_t = _time_body(lts_freq)
    used = cfg.data_grid(1).used_subcarriers
    found: list[tuple[int, float]] = []
    for first, last in runs:
        centre = sync.plateau_centre(metric, first, min(last + w - 1, metric.size - 1))
        frac = sync.fractional_cfo(p[centre])
        lts1 = centre + cp // 2 + s  # estimated first sample of the first LTS body
        lo, hi = lts1 - cp - n // 4, lts1 + cp + n // 4
        if lo < 0 or hi + n + s > r.size:
            continue
        seg_start = lo
        seg = sync.correct_cfo(r[seg_start : hi + n + s], frac, n, start=0)
        a = lts1 - cp // 2 - seg_start
        y = np.fft.fftshift(np.fft.fft(seg[a : a + n], norm="ortho"))
        max_shift = int(math.ceil(cfg.max_cfo_subcarriers)) + 1
        g = sync.integer_cfo(y, lts_freq, used, max_shift, step=2)
        cfo = frac + g
        if abs(cfo) > cfg.max_cfo_subcarriers + 1:
            continue
        seg = sync.correct_cfo(r[seg_start : hi + n + s], cfo, n, start=0)
        corr = sync.cross_correlation(seg, lts_t, 0, hi - lo)
        if corr.size == 0 or corr.max() < 0.2:
            continue  # a false alarm: no long training symbol where it should be
        lts1_fine = seg_start + sync.first_path(corr, 0.5, lookback=cp)
        a, b = r[lts1_fine : lts1_fine + n], r[lts1_fine + s : lts1_fine + s + n]
        if abs(np.vdot(a, b)) < 0.3 * np.linalg.norm(a) * np.linalg.norm(b):
            continue  # the two long training symbols must repeat (whatever the channel)
        k2 = lts1_fine + s - seg_start
        if sync.cross_correlation(seg, lts_t, k2, k2 + 1).max(initial=0.0) < 0.2:
            continue  # and the second one must be there too
        start = lts1_fine - n - 2 * cp
        if start >= 0 and (not found or start - found[-1][0] > s):
            found.append((int(start), float(cfo)))
    return found


def find_frames(iq, cfg: FrameConfig = FrameConfig()) -> list[int]:
    """Start indices of every frame preamble in a capture (ascending).

    Args:
        iq: [num_samples] complex64 (numpy or torch).
    """
    return [start for start, _ in _acquire(_without_dc(_as_complex_1d(iq, "iq")), cfg)]


def _windows(
    rc: np.ndarray, body_starts: np.ndarray, shifts: np.ndarray, cfg: FrameConfig
) -> np.ndarray:
    """FFT of each OFDM symbol; window starts ``backoff - shift`` samples early, ramp removed.

    Returns [num_windows, fft_size] complex128 in centred order.
    """
    n, b = cfg.fft_size, cfg.backoff
    starts = body_starts - b + shifts
    idx = starts[:, None] + np.arange(n)[None, :]
    y = np.fft.fftshift(np.fft.fft(rc[idx], axis=-1, norm="ortho"), axes=-1)
    k = np.arange(n) - n // 2
    return y * np.exp(2j * np.pi * k[None, :] * (b - shifts)[:, None] / n)


def _not_detected(num_symbols: int) -> FrameResult:
    return FrameResult(
        symbols=torch.zeros(num_symbols, dtype=torch.complex64),
        noise_var=torch.full((num_symbols,), float("inf")),
        start_index=-1,
        cfo_hz=float("nan"),
        cfo_subcarriers=float("nan"),
        sco_ppm=float("nan"),
        snr_db_estimate=float("nan"),
        detected=False,
    )


def receive_frame(
    iq,
    cfg: FrameConfig = FrameConfig(),
    num_symbols: int = 1,
    search_from: int = 0,
    equalizer: str = "mmse",
) -> FrameResult:
    """Find the first complete frame at or after ``search_from`` and recover its symbols.

    Args:
        iq: [num_samples] complex64 (numpy or torch), full scale 1.0.
        cfg: the frame configuration the transmitter used.
        num_symbols: payload symbols the frame carries.
        search_from: sample index where the search starts.
        equalizer: ``"mmse"`` or ``"zf"`` (see :func:`phy.equalize`).
    Returns:
        :class:`FrameResult`; ``detected`` is False when no complete frame was found.
    """
    raw = _as_complex_1d(iq, "iq")
    if not isinstance(num_symbols, int) or num_symbols < 1:
        raise ValueError(f"num_symbols must be an integer >= 1, got {num_symbols!r}")
    if equalizer not in EQUALIZERS:
        raise ValueError(f"equalizer must be one of {list(EQUALIZERS)}, got {equalizer!r}")
    if not isinstance(search_from, int) or not 0 <= search_from < max(1, raw.size):
        raise ValueError(f"search_from must be an integer in [0, {raw.size}), got {search_from!r}")
    grid = cfg.data_grid(num_symbols)
    length = cfg.num_samples(num_symbols)
    for start, cfo in _acquire(_without_dc(raw[search_from:]), cfg):
        start += search_from
        if start + length <= raw.size:
            r = raw - _dc_estimate(raw, start, length)
            return _demodulate(r, start, cfo, grid, num_symbols, cfg, equalizer, length)
    return _not_detected(num_symbols)


def _dc_estimate(r: np.ndarray, start: int, length: int) -> complex:
    """The receiver's DC offset: the mean outside the frame when there are enough such
    samples (the frame's own mean is not zero once a CFO moves carriers onto DC), else
    the mean of everything."""
    outside = r.size - length
    if outside >= 256:
        return complex((r[:start].sum() + r[start + length :].sum()) / outside)
    return complex(r.mean())


def _demodulate(r, start, cfo, grid, num_symbols, cfg, equalizer, length) -> FrameResult:
    n, cp, s = cfg.fft_size, cfg.cp_length, cfg.symbol_length
    k = np.arange(n) - n // 2
    _, lts = _preamble(cfg)
    used = grid.used_subcarriers
    pad = cp + s  # room for windows that drift late
    body = np.arange(3 + grid.num_ofdm_symbols) * s + cp  # [num_ofdm_symbols + 3]
    no_shift = np.zeros(2, dtype=np.int64)

    # fine CFO from the two long training symbols (preamble only), then one rotation of
    # the whole frame, then the channel estimate (their average)
    pre = sync.correct_cfo(r[start : start + cfg.preamble_length], cfo, n)
    y1, y2 = _windows(pre, body[1:3], no_shift, cfg)
    cfo += float(np.angle(np.sum(y2[used] * np.conj(y1[used])))) * n / (2 * np.pi * s)
    rc = np.concatenate(
        [sync.correct_cfo(r[start : start + length], cfo, n), np.zeros(pad, np.complex64)]
    )
    y1, y2 = _windows(rc, body[1:3], no_shift, cfg)
    h = np.zeros(n, dtype=np.complex128)
    h[used] = (y1[used] + y2[used]) / (2 * lts[used])
    # their difference sees the random noise only (distortions repeat in both copies)
    lts_noise_var = max(float(np.mean(np.abs(y1[used] - y2[used]) ** 2)) / 2, 1e-10)

    # data symbols: pilots -> per-symbol timing drift (line fit) and common phase
    pk = grid.pilot_subcarriers
    pilots = grid.pilots.numpy().reshape(grid.num_ofdm_symbols, pk.size)
    spacing = cfg.pilot_subcarrier_spacing
    pairs = np.flatnonzero(np.diff(pk) == spacing)
    idx = np.arange(grid.num_ofdm_symbols)
    shifts = np.zeros(grid.num_ofdm_symbols, dtype=np.int64)
    for _ in range(2):
        y = _windows(rc, body[3:], shifts, cfg)  # [num_ofdm_symbols, fft_size]
        z = y[:, pk] / (h[pk][None, :] * pilots)
        slope = np.angle(np.sum(z[:, pairs + 1] * np.conj(z[:, pairs]), axis=1)) / spacing
        tau = -slope * n / (2 * np.pi)  # [num_ofdm_symbols] samples
        if grid.num_ofdm_symbols > 1:
            b, a = np.polyfit(idx, tau, 1)
        else:
            b, a = 0.0, float(tau[0])
        tau_fit = a + b * idx
        new = np.round(tau_fit).astype(np.int64)
        if np.array_equal(new, shifts) or np.any(np.abs(new) >= cp - cfg.backoff):
            break
        shifts = new
    ramp = np.exp(-2j * np.pi * np.outer(tau_fit, k) / n)  # [num_ofdm_symbols, fft_size]
    theta = np.angle(np.sum(z * np.conj(ramp[:, pk]), axis=1))
    h_all = h[None, :] * ramp * np.exp(1j * theta)[:, None]

    # noise seen by the data: pilot residuals (random noise plus distortions that differ
    # from symbol to symbol: quantisation, I/Q image, ICI), less the channel-estimate error
    # they include, corrected for the one phase fitted per symbol
    resid = float(np.mean(np.abs(y[:, pk] - h_all[:, pk] * pilots) ** 2)) / (1 - 1 / pk.size)
    noise_var = max(lts_noise_var, resid - lts_noise_var / 2)
    x_hat, nv = equalize(
        torch.from_numpy(y.astype(np.complex64))[None],
        torch.from_numpy(h_all.astype(np.complex64))[None],
        noise_var,
        equalizer,
        estimation_error_var=lts_noise_var / 2,
    )
    symbols = extract_data(x_hat, grid)[0, :num_symbols].contiguous()
    nv = extract_data(nv, grid)[0, :num_symbols].contiguous()
    signal = float(np.mean(np.abs(h[used]) ** 2))
    return FrameResult(
        symbols=symbols,
        noise_var=nv,
        start_index=int(start),
        cfo_hz=cfo * cfg.subcarrier_spacing_hz,
        cfo_subcarriers=float(cfo),
        sco_ppm=float(b / s * 1e6),
        snr_db_estimate=10 * math.log10(signal / lts_noise_var),
        effective_snr_db=10 * math.log10(signal / noise_var),
        detected=True,
    )

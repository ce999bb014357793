"""The over-the-air receiver: find frames in a capture and recover their symbols.

Acquisition (:mod:`phy.detection`): differential search over the sync preamble's segments,
coherent confirmation over CFO hypotheses, fine CFO, first-path timing. Demodulation
(:mod:`phy.estimation`): DC removal, one CFO rotation, FFT of every OFDM symbol with the
window following the sampling-clock drift, then estimates pooled over the whole frame:
common phase (residual CFO line, smoothed residual), timing drift (from the CFO when both
radios share one crystal, else from the pilots), the channel from both training symbols
and every pilot by weighted least squares with its taps inside the cyclic prefix, and the
noise variance from the residuals of every known value. One-tap ZF (unbiased, the codec's
convention) or MMSE with each symbol's effective noise variance; the payload is
de-interleaved. See :mod:`phy.frame` for the waveform.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
import torch

from common import one_blas_thread
from phy import _kernels, estimation
from phy.detection import find_preambles
from phy.frame import FrameConfig, as_complex_1d
from phy.ofdm.equalization import EQUALIZERS
from phy.receiver_layout import _Layout, _layout


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
        effective_snr_db: the same with the noise the data saw (the residuals of every
            training and pilot value against the fitted model: noise plus quantisation,
            I/Q image, ISI/ICI); what ``noise_var`` is based on.
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
    if not r.size:
        return r
    return r - _mean(r)


def _mean(r: np.ndarray) -> np.complex64:
    """The capture's mean (its DC offset), accumulated in complex128."""
    return np.complex64(_sum(r) / r.size) if r.size else np.complex64(0)


@one_blas_thread
def find_frames(iq, cfg: FrameConfig = FrameConfig()) -> list[int]:
    """Start indices of every frame preamble in a capture (ascending).

    Args:
        iq: [num_samples] complex64 (numpy or torch).
    """
    raw = as_complex_1d(iq, "iq")
    return [d.start for d in find_preambles(raw, cfg, _mean(raw))]


def _windows(
    frame: np.ndarray, starts: np.ndarray, cfo: float, fft_size: int, dc: complex = 0j
) -> np.ndarray:
    """FFT of the windows ``frame[start : start + fft_size] - dc`` with a CFO of ``cfo``
    carriers removed (:func:`phy.sync.correct_cfo` from the frame's first sample, on these
    samples only): [num_windows, fft_size] complex64 in natural (FFT) order; the window's
    early start is a delay the caller's model removes."""
    w = -2 * np.pi * cfo / fft_size
    # the rotation (and the transform's 1 / sqrt(n)) applied while the windows are gathered
    # (torch's batched FFT of short rows is the fastest at hand)
    win = torch.from_numpy(
        _kernels.rotated_windows(frame, np.asarray(starts, np.int64), w, fft_size, np.complex64(dc))
    )
    return torch.fft.fft(win, dim=-1, out=win).numpy()


_NO_SUMS = np.zeros(0, np.complex64)


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


@one_blas_thread
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
    raw = _checked(iq, num_symbols, equalizer)
    if not isinstance(search_from, int) or not 0 <= search_from < max(1, raw.size):
        raise ValueError(f"search_from must be an integer in [0, {raw.size}), got {search_from!r}")
    length = cfg.num_samples(num_symbols)
    # a complete frame starts no later than raw.size - length: search only there, and from
    # one preamble before search_from, so that a preamble cut by search_from is found as
    # itself (and skipped) rather than through its sidelobes
    first = max(0, search_from - cfg.sync_length)
    region = raw[first : max(first, raw.size - length + cfg.sync_length)]
    for det in find_preambles(region, cfg, _mean(region)):
        start, cfo = det.start + first, det.cfo
        if search_from <= start and start + length <= raw.size:
            dc = _dc_estimate(raw, start, length)
            res = _demodulate(raw[start : start + length], cfo, num_symbols, cfg, equalizer, dc)
            res.start_index = int(start)
            return res
    return _not_detected(num_symbols)


@one_blas_thread
def receive_frames(
    iq, cfg: FrameConfig = FrameConfig(), num_symbols: int = 1, equalizer: str = "mmse"
) -> list[FrameResult]:
    """Every complete frame in a capture, from one search (a stream's block of frames): the
    frames that :func:`receive_frame` finds called from each found frame onwards, without a
    search per frame. Arguments as :func:`receive_frame`'s; returns one detected
    :class:`FrameResult` per frame, ascending (none when there is no complete frame)."""
    raw = _checked(iq, num_symbols, equalizer)
    length = cfg.num_samples(num_symbols)
    region = raw[: max(0, raw.size - length + cfg.sync_length)]
    out, total = [], _sum(raw)  # the capture's sum once, not a pass over it per frame
    for det in find_preambles(region, cfg, _mean(region)):
        if det.start + length <= raw.size:
            dc = _dc_estimate(raw, det.start, length, total)
            frame = raw[det.start : det.start + length]
            out.append(_demodulate(frame, det.cfo, num_symbols, cfg, equalizer, dc))
            out[-1].start_index = int(det.start)
    return out


def _checked(iq, num_symbols, equalizer: str) -> np.ndarray:
    """The capture as [num_samples] complex64 once the arguments are checked."""
    raw = as_complex_1d(iq, "iq")
    if not isinstance(num_symbols, int) or num_symbols < 1:
        raise ValueError(f"num_symbols must be an integer >= 1, got {num_symbols!r}")
    if equalizer not in EQUALIZERS:
        raise ValueError(f"equalizer must be one of {list(EQUALIZERS)}, got {equalizer!r}")
    return raw


def _dc_estimate(r: np.ndarray, start: int, length: int, total: complex | None = None) -> complex:
    """The receiver's DC offset: the mean outside the frame when there are enough such
    samples (the frame's own mean is not zero once a CFO moves carriers onto DC), else
    the mean of everything; ``total``, the sum of ``r`` when given, spares a pass over it."""
    outside = r.size - length
    if outside >= 256 and total is not None:
        return (total - _sum(r[start : start + length])) / outside
    if outside >= 256:
        total = _sum(r[:start]) + _sum(r[start + length :])
        return total / outside
    return _sum(r) / max(r.size, 1)


def _sum(r: np.ndarray) -> complex:
    """Sum of a complex64 array, accumulated in complex128."""
    return complex(r.sum(dtype=np.complex128)) if r.size else 0j


def _demodulate(frame, cfo, num_symbols, cfg, equalizer, dc: complex = 0j) -> FrameResult:
    """Recover the payload of ``frame - dc`` (``frame`` [length] complex64 starting at the
    sync preamble's first sample, ``dc`` the receiver's DC offset, removed sample by sample
    as the OFDM windows are gathered) whose CFO is about ``cfo`` subcarriers."""
    lay = _layout(cfg, num_symbols)
    n, cp, s = cfg.fft_size, cfg.cp_length, cfg.symbol_length
    used, pk = lay.used, lay.pilots
    kr = lay.k_row
    p_mats, factors, dofs = lay.smoothers
    locked = cfg.carrier_freq_hz is not None
    eps = -cfo * cfg.subcarrier_spacing_hz / cfg.carrier_freq_hz if locked else 0.0
    h, slope_hint = None, None
    for _ in range(4):  # timing-drift iterations (one when it comes from the CFO)
        tau = eps * lay.times  # [rows] samples of drift
        shifts = np.minimum(np.maximum(np.round(tau), -(cp - cfg.backoff - 1)), cfg.backoff)
        shifts = shifts.astype(np.int64)
        y = _windows(frame, lay.body - cfg.backoff + shifts, cfo, n, dc).reshape(-1)  # [rows * n]
        delay = (tau + cfg.backoff - shifts).astype(np.float32)  # [rows] windows start early
        # y[l, k] = h[k] exp(j phi[l]) ramp[l, k] x[l, k] + noise, ramp the windows' delay
        # (exp(-2 pi j delay[l] k / n)), needed only at the known and the data entries
        yx = y[lay.k_flat] * _known_factor(cfg, num_symbols, delay)  # observations of h e^{j phi}
        if h is None:  # first look: the two training symbols
            nt = lay.num_training_values  # the training rows' values come first
            h = _channel(yx[:nt], lay, lay.smoother_training, training_only=True)
            y0, y1 = y[lay.used_nat], y[n + lay.used_nat]
            diff = y0 - y1 * np.exp(1j * np.angle(np.vdot(y1, y0)))  # common phase aligned
            noise_var = lts_noise_var = max(float(np.vdot(diff, diff).real) / diff.size / 2, 1e-12)
        h_used = h[used]
        for _ in range(2):  # common phase, then the channel without it
            rot, slope_hint, snr_row = _common_phase(yx, h_used, noise_var, slope_hint, lay)
            # the channel model with the least Mallows' Cp and the noise of its residuals
            obs, h_used, best, noise_var = _kernels.refine(
                yx, rot, kr, lay.k_pos, lay.counts, p_mats, lay.bands, dofs, lay.rows
            )
            factor = factors[best]
        h = np.zeros(n, np.complex64)
        h[used] = h_used
        if locked:
            break
        d_eps = _kernels.delay_drift(  # estimation.track_delay, compiled
            obs[lay.num_training_values :],
            h[pk],
            lay.pairs,
            cfg.pilot_subcarrier_spacing,
            lay.times[2:],
            n,
            estimation.PHASE_WINDOW_SNR,
            snr_row,
            estimation.DRIFT_SIGNIFICANCE,
        )
        eps += d_eps
        if abs(d_eps) * lay.times[-1] < 0.02:
            break

    mse = np.zeros(n, np.float32)
    mse[used] = noise_var * factor
    assert h is not None  # set on the loop's first pass
    x_hat, nv = _equalized(y, h, rot, delay, (noise_var + mse), lay, equalizer)
    h_used = h[used]
    signal = max(float(np.vdot(h_used, h_used).real - mse[used].sum()) / used.size, 1e-30)
    cfo_total = cfo + slope_hint / (2 * np.pi * s) * n
    return FrameResult(
        symbols=torch.from_numpy(np.ascontiguousarray(x_hat, np.complex64)),
        noise_var=torch.from_numpy(np.ascontiguousarray(nv, np.float32)),
        start_index=-1,
        cfo_hz=cfo_total * cfg.subcarrier_spacing_hz,
        cfo_subcarriers=float(cfo_total),
        sco_ppm=float(eps * 1e6),
        snr_db_estimate=10 * math.log10(signal / lts_noise_var),
        detected=True,
        effective_snr_db=10 * math.log10(signal / noise_var),
    )


def _common_phase(yx, h_used, noise_var, slope, lay: _Layout):
    """(exp(-j phi) [rows] complex64, slope, one data row's SNR): the rows' common phase
    (:func:`phy.estimation.track_phase`) from the observations ``yx`` against ``h_used``; the
    slope search (an FFT across the rows' sums) only when no ``slope`` is known yet."""
    a = _NO_SUMS  # the rows' sums yx conj(h): made by phase_line
    if slope is None:
        a = _kernels.row_sums(yx, h_used, lay.k_row, lay.k_pos, lay.rows)
        slope = estimation.slope_search(a)
    return _kernels.phase_line(
        yx,
        h_used,
        lay.k_row,
        lay.k_pos,
        lay.pilot_in_used,
        lay.rows,
        noise_var,
        slope,
        estimation.PHASE_WINDOW_SNR,
        a,
    )


def _known_factor(cfg: FrameConfig, num_symbols: int, delay: np.ndarray) -> np.ndarray:
    """[num_known] complex64 ``conj(x ramp)`` at the known entries: what takes their FFT
    values to observations of ``h exp(j phi)`` (one table per delay when every row has it)."""
    if delay.size and np.all(delay == delay[0]):
        return _uniform_known_factor(cfg, num_symbols, float(delay[0]))
    lay = _layout(cfg, num_symbols)
    return np.conj(lay.x_known) * np.conj(_ramp(delay, lay.k_row, lay.k_col, lay.fft_size))


@functools.lru_cache(maxsize=32)
def _uniform_known_factor(cfg: FrameConfig, num_symbols: int, delay: float) -> np.ndarray:
    lay = _layout(cfg, num_symbols)
    out = np.conj(lay.x_known) * np.conj(_ramp_table(delay, lay.fft_size)[lay.k_col])
    out.flags.writeable = False
    return out


def _equalized(y, h, rot, delay, s_car, lay: _Layout, equalizer: str):
    """(x_hat, noise variance) [num_symbols] in payload order: the one-tap equaliser against
    the model ``h[k] exp(j phi[l]) ramp[l, k]`` at the data elements of ``y`` [rows * n];
    ``s_car`` [n] the noise plus channel-estimation error per carrier (unit-power x).

    ZF: y / h as y conj(h) / |h|^2 (a real division); MMSE: y conj(h) / (|h|^2 + s). With one
    window delay for every row the row factor has unit modulus, so the weights are per
    carrier, ``conj(h_k) / (|h_k|^2 + s_k)``, applied with the row phases in one pass over the
    payload; else the model is evaluated at each data element."""
    n = lay.fft_size
    if not (delay.size and np.all(delay == delay[0])):
        h_d = _model_at_data(h, rot, delay, lay)
        gain = h_d.real * h_d.real + h_d.imag * h_d.imag
        s_eff = s_car[lay.d_col]
        inv = 1.0 / (np.maximum(gain, np.float32(1e-24)) if equalizer == "zf" else gain + s_eff)
        return y[lay.d_flat] * np.conj(h_d) * inv, s_eff * inv
    ramp = _ramp_table(float(delay[0]), n)
    return _kernels.equalize(
        y, rot, h, ramp, s_car, lay.centred, lay.d_row, lay.d_bin, equalizer == "zf"
    )


def _model_at_data(h: np.ndarray, rot: np.ndarray, delay: np.ndarray, lay: _Layout) -> np.ndarray:
    """The model ``h[k] exp(j phi[l]) ramp[l, k]`` at the payload's data elements only:
    [num_symbols] complex64 (``rot`` = exp(-j phi) per row, ``h`` in centred order)."""
    n = lay.fft_size
    h_nat = h[lay.centred]  # [fft_size] natural order
    return h_nat[lay.d_bin] * np.conj(rot)[lay.d_row] * _ramp(delay, lay.d_row, lay.d_col, n)


def _ramp(delay: np.ndarray, rows: np.ndarray, cols: np.ndarray, n: int) -> np.ndarray:
    """The delay ramp exp(-2 pi j delay[row] f / n) of each row's window at the entries
    (``rows[i]``, carrier ``cols[i]`` in centred order, f = cols - n / 2): [num_entries]
    complex64. One table of n values when every row has the same delay (no timing drift)."""
    if delay.size and np.all(delay == delay[0]):
        return _ramp_table(float(delay[0]), n)[cols]
    return _phasor(delay[rows] * (cols - n // 2).astype(np.float32) * np.float32(-2 * np.pi / n))


@functools.lru_cache(maxsize=64)
def _ramp_table(delay: float, n: int) -> np.ndarray:
    """[n] complex64: exp(-2 pi j delay f / n) at every carrier f - n / 2 (centred order)."""
    c = np.float32(-2 * np.pi / n)
    out = _phasor(np.arange(-(n // 2), n - n // 2, dtype=np.float32) * (np.float32(delay) * c))
    out.flags.writeable = False  # cached: shared by every caller
    return out


def _phasor(angle: np.ndarray) -> np.ndarray:
    """exp(1j * angle) as complex64 from float32 sine and cosine (vectorised, fast)."""
    a = np.asarray(angle, np.float32)
    out = np.empty(a.shape, np.complex64)
    out.real, out.imag = np.cos(a), np.sin(a)
    return out


def _carrier_sums(obs: np.ndarray, lay: _Layout, training_only: bool = False) -> np.ndarray:
    """[num_used] complex sums per used carrier of observations ``obs`` [num_known] (the
    training rows' alone when ``training_only``)."""
    nt = lay.num_training_values
    sums = obs[:nt].reshape(2, -1).sum(axis=0)  # training rows cover every used carrier
    if not training_only:
        sums[lay.pilot_in_used] += obs[nt:].reshape(lay.rows - 2, -1).sum(axis=0)
    return sums


def _channel(obs: np.ndarray, lay: _Layout, smoother, training_only: bool = False) -> np.ndarray:
    """Smoothed channel [fft_size] complex64 (centred order) from observations ``obs`` of
    ``h`` at the known entries (the training rows' alone when ``training_only``)."""
    h = np.zeros(lay.fft_size, np.complex64)
    h[lay.used] = smoother @ _carrier_sums(obs, lay, training_only).astype(np.complex64)
    return h

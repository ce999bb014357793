"""The previous implementation of the receiver chain: the reference search
(:mod:`benchmarks.reference_receiver.detection`) and demodulation, kept unchanged for the
benchmark's side-by-side timing and the equivalence test (the same frames, the same decoded bits).

Every function of the chain is a copy, so that changes to :mod:`phy.receiver` leave it as it
was; only the result type (:class:`phy.receiver.FrameResult`), the frame definition
(:mod:`phy.frame`) and :mod:`phy.estimation`'s constants and bases are shared.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
import scipy.fft
import torch

from benchmarks.reference_receiver.detection import find_preambles
from phy import estimation
from phy.frame import FrameConfig, as_complex_1d, interleaver, long_training_symbol
from phy.ofdm.equalization import EQUALIZERS
from phy.receiver import FrameResult


def find_frames(iq, cfg: FrameConfig = FrameConfig()) -> list[int]:
    """:func:`phy.receiver.find_frames` with the reference search."""
    return [d.start for d in find_preambles(_without_dc(as_complex_1d(iq, "iq")), cfg)]


def receive_frame(
    iq,
    cfg: FrameConfig = FrameConfig(),
    num_symbols: int = 1,
    search_from: int = 0,
    equalizer: str = "mmse",
) -> FrameResult:
    """:func:`phy.receiver.receive_frame` with the reference search and demodulation.

    Args:
        iq: [num_samples] complex64 (numpy or torch), full scale 1.0.
        cfg: the frame configuration the transmitter used.
        num_symbols: payload symbols the frame carries.
        search_from: sample index where the search starts.
        equalizer: ``"mmse"`` or ``"zf"`` (see :func:`phy.equalize`).
    Returns:
        :class:`FrameResult`; ``detected`` is False when no complete frame was found.
    """
    raw = as_complex_1d(iq, "iq")
    if not isinstance(num_symbols, int) or num_symbols < 1:
        raise ValueError(f"num_symbols must be an integer >= 1, got {num_symbols!r}")
    if equalizer not in EQUALIZERS:
        raise ValueError(f"equalizer must be one of {list(EQUALIZERS)}, got {equalizer!r}")
    if not isinstance(search_from, int) or not 0 <= search_from < max(1, raw.size):
        raise ValueError(f"search_from must be an integer in [0, {raw.size}), got {search_from!r}")
    length = cfg.num_samples(num_symbols)
    # a complete frame starts no later than raw.size - length: search only there, and from
    # one preamble before search_from, so that a preamble cut by search_from is found as
    # itself (and skipped) rather than through its sidelobes
    first = max(0, search_from - cfg.sync_length)
    region = raw[first : max(first, raw.size - length + cfg.sync_length)]
    for det in find_preambles(_without_dc(region), cfg):
        start, cfo = det.start + first, det.cfo
        if search_from <= start and start + length <= raw.size:
            frame = raw[start : start + length] - _dc_estimate(raw, start, length)
            res = _demodulate(frame, cfo, num_symbols, cfg, equalizer)
            res.start_index = int(start)
            return res
    return _not_detected(num_symbols)


def _demodulate(frame, cfo, num_symbols, cfg, equalizer) -> FrameResult:
    """Recover the payload of ``frame`` [length] complex64 (DC removed, starting at the
    sync preamble's first sample) whose CFO is about ``cfo`` subcarriers."""
    lay = _layout(cfg, num_symbols)
    n, cp, s = cfg.fft_size, cfg.cp_length, cfg.symbol_length
    used, pk = lay.used, lay.pilots
    kr, kc = lay.k_row, lay.k_col
    x_conj = np.conj(lay.x_known)
    locked = cfg.carrier_freq_hz is not None
    eps = -cfo * cfg.subcarrier_spacing_hz / cfg.carrier_freq_hz if locked else 0.0
    h, slope_hint = None, None
    for _ in range(4):  # timing-drift iterations (one when it comes from the CFO)
        tau = eps * lay.times  # [rows] samples of drift
        shifts = np.clip(np.round(tau), -(cp - cfg.backoff - 1), cfg.backoff).astype(np.int64)
        y = _windows(frame, lay.body - cfg.backoff + shifts, cfo, n).reshape(-1)  # [rows * n]
        delay = (tau + cfg.backoff - shifts).astype(np.float32)  # [rows] windows start early
        # y[l, k] = h[k] exp(j phi[l]) ramp[l, k] x[l, k] + noise, ramp the windows' delay
        # (exp(-2 pi j delay[l] k / n)), needed only at the known and the data entries
        ramp_known = _ramp(delay, kr, kc, n)
        yx = y[lay.k_flat] * x_conj * np.conj(ramp_known)  # observations of h e^{j phi}
        if h is None:  # first look: the two training symbols
            first = kr < 2
            h = _channel(yx[first], lay, lay.smoother_training, training_only=True)
            y0, y1 = y[lay.used_nat], y[n + lay.used_nat]
            diff = y0 - y1 * np.exp(1j * np.angle(np.vdot(y1, y0)))  # common phase aligned
            noise_var = lts_noise_var = max(float(np.mean(np.abs(diff) ** 2)) / 2, 1e-12)
        for _ in range(2):
            a = _row_sums(yx * np.conj(h[kc]), lay)  # [rows]
            snr_row = float(np.sum(np.abs(h[pk]) ** 2)) / noise_var  # one data row's sum
            phi, slope = _track_phase(a, snr_row, slope_hint)
            slope_hint = slope
            rot = _phasor(-phi)  # [rows]
            obs = yx * rot[kr]
            sums = _carrier_sums(obs, lay)
            # Cp's noise level from the richest model (per-carrier means): unbiased whichever
            # model is right, so a low training-difference estimate cannot pick a noisy model
            scatter = float(np.vdot(obs, obs).real) - float(np.sum(np.abs(sums) ** 2 / lay.counts))
            cp_noise = max(scatter / max(kr.size - lay.counts.size - lay.rows, 1), 1e-12)
            h, factor, taps = _best_channel(sums, lay, cp_noise)
            dof = max(kr.size - taps - lay.rows, 1)
            e = obs - h[kc]
            noise_var = max(float(np.vdot(e, e).real) / dof, 1e-12)
        if locked:
            break
        data_rows = kr >= 2
        z = (obs[data_rows] * np.conj(h[kc[data_rows]])).reshape(lay.rows - 2, -1)
        d_eps = _track_delay(z, lay.pairs, cfg.pilot_subcarrier_spacing, lay.times[2:], n, snr_row)
        eps += d_eps
        if abs(d_eps) * lay.times[-1] < 0.02:
            break

    mse = np.zeros(n, np.float32)
    mse[used] = noise_var * factor
    assert h is not None  # set on the loop's first pass
    h_nat = np.fft.ifftshift(h).astype(np.complex64)  # [fft_size] natural order
    # the model h[k] exp(j phi[l]) ramp[l, k] at the payload's data elements only
    h_d = h_nat[lay.d_bin] * np.conj(rot)[lay.d_row] * _ramp(delay, lay.d_row, lay.d_col, n)
    y_d = y[lay.d_flat]  # [num_symbols] in payload order
    s_eff = noise_var + mse[lay.d_col]  # noise plus channel-estimation error (unit-power x)
    gain = h_d.real * h_d.real + h_d.imag * h_d.imag
    # ZF: y / h as y conj(h) / |h|^2 (a real division); MMSE: y conj(h) / (|h|^2 + s_eff)
    inv = 1.0 / (np.maximum(gain, np.float32(1e-24)) if equalizer == "zf" else gain + s_eff)
    x_hat = y_d * np.conj(h_d) * inv
    nv = s_eff * inv
    signal = max(float(np.mean(np.abs(h[used]) ** 2 - mse[used])), 1e-30)
    cfo_total = cfo + slope / (2 * np.pi * s) * n
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


def _ramp(delay: np.ndarray, rows: np.ndarray, cols: np.ndarray, n: int) -> np.ndarray:
    """The delay ramp exp(-2 pi j delay[row] f / n) of each row's window at the entries
    (``rows[i]``, carrier ``cols[i]`` in centred order, f = cols - n / 2): [num_entries]
    complex64. One table of n values when every row has the same delay (no timing drift)."""
    c = np.float32(-2 * np.pi / n)
    if delay.size and np.all(delay == delay[0]):
        return _phasor(np.arange(-(n // 2), n - n // 2, dtype=np.float32) * (delay[0] * c))[cols]
    return _phasor(delay[rows] * (cols - n // 2).astype(np.float32) * c)


def _track_phase(
    a: np.ndarray, snr_row: float, slope_hint: float | None = None
) -> tuple[np.ndarray, float]:
    """Common phase of every row from its pilot sums ``a[l] = g exp(j phi[l]) + noise``.

    A line (residual CFO) found by an FFT across rows and refined by the phase between the
    halves, then the residual smoothed over as many rows as it takes to reach
    ``estimation.PHASE_WINDOW_SNR`` (1 row at high SNR: tracks phase noise; the line alone when the
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
    if slope_hint is None:
        m = 4 << max(0, math.ceil(math.log2(max(rows, 1))))
        spec = np.fft.fft(a, m)
        w = 2 * np.pi * (((int(np.argmax(np.abs(spec))) / m) + 0.5) % 1.0 - 0.5)
    else:
        w = float(slope_hint)
    if rows >= 2:
        b = a * np.exp(-1j * w * idx)
        h = rows // 2
        w += float(np.angle(b[h : 2 * h].sum() * np.conj(b[:h].sum()))) / h
    phi0 = float(np.angle(np.sum(a * np.exp(-1j * w * idx))))
    line = phi0 + w * idx
    width = int(math.ceil(estimation.PHASE_WINDOW_SNR / max(snr_row, 1e-6))) | 1
    if width >= rows:
        return line, w
    resid = a * np.exp(-1j * line)
    return line + np.angle(estimation._moving_sum(resid, width)), w


def _row_sums(v: np.ndarray, lay: _Layout) -> np.ndarray:
    """[rows] complex sums of known-value entries ``v`` [num_known] by row (the training
    rows come first, then the data rows with the same number of pilots each)."""
    nt = lay.num_training_values
    head = v[:nt].reshape(2, -1).sum(axis=1)
    tail = v[nt:].reshape(lay.rows - 2, -1).sum(axis=1)
    return np.concatenate([head, tail])


def _track_delay(
    z: np.ndarray,
    pairs: np.ndarray,
    pair_step: int,
    times: np.ndarray,
    fft_size: int,
    snr_row: float,
) -> float:
    """Timing drift (samples per sample: the sampling-clock offset) from pilot observations.

    Rows are pooled in blocks until a block's pilots reach ``estimation.PHASE_WINDOW_SNR``; each
    block's delay comes from the phase step between pilots ``pair_step`` carriers apart;
    a weighted line through the blocks' delays against time gives the drift.

    Args:
        z: [num_rows, num_pilots] complex: pilot observations with the channel, common phase
            and the current drift model removed (about ``|h|^2`` times the residual ramp).
        pairs: [num_pairs] pilot indices j whose pilot j + 1 sits ``pair_step`` carriers above.
        times: [num_rows] sample time of each row.
    Returns:
        the residual drift (add it to the current model's); 0 when it is not
        ``estimation.DRIFT_SIGNIFICANCE`` standard errors away from 0.
    """
    rows = z.shape[0]
    block = min(rows, int(math.ceil(estimation.PHASE_WINDOW_SNR / max(snr_row, 1e-6))))
    nb = rows // block
    if nb < 2:
        return 0.0
    zb = z[: nb * block].reshape(nb, block, -1).sum(axis=1)  # [num_blocks, num_pilots]
    tb = times[: nb * block].reshape(nb, block).mean(axis=1)
    g = np.sum(zb[:, pairs + 1] * np.conj(zb[:, pairs]), axis=1)  # [num_blocks]
    tau = -np.angle(g) / pair_step * fft_size / (2 * np.pi)
    wgt = np.abs(g)
    sw = max(float(wgt.sum()), 1e-30)
    tm = float(np.sum(wgt * tb)) / sw
    sxx = float(np.sum(wgt * (tb - tm) ** 2)) / sw
    if sxx <= 0 or nb < 4:
        return 0.0
    slope = float(np.sum(wgt * (tb - tm) * tau)) / sw / sxx
    resid = tau - (float(np.sum(wgt * tau)) / sw + slope * (tb - tm))
    var_slope = float(np.sum(wgt * resid**2)) / sw / sxx / (nb - 2)
    # a drift that the blocks cannot tell from zero is zero (low SNR: no random walk)
    return slope if slope**2 > estimation.DRIFT_SIGNIFICANCE**2 * var_slope else 0.0


def _without_dc(r: np.ndarray) -> np.ndarray:
    """Remove the capture's mean (an SDR's DC offset would make silence look periodic)."""
    if not r.size:
        return r
    return r - np.complex64(_sum(r) / r.size)


def _windows(frame: np.ndarray, starts: np.ndarray, cfo: float, fft_size: int) -> np.ndarray:
    """FFT of the windows ``frame[start : start + fft_size]`` with a CFO of ``cfo`` carriers
    removed (:func:`phy.sync.correct_cfo` from the frame's first sample, on these samples
    only): [num_windows, fft_size] complex64 in natural (FFT) order; the window's early
    start is a delay the caller's model removes."""
    w = -2 * np.pi * cfo / fft_size
    win = np.lib.stride_tricks.sliding_window_view(frame, fft_size)[starts]  # a copy
    win *= np.exp(1j * w * starts).astype(np.complex64)[:, None]
    win *= np.exp(1j * w * np.arange(fft_size)).astype(np.complex64)
    return scipy.fft.fft(win, axis=-1, norm="ortho", overwrite_x=True)


@dataclass(frozen=True)
class _Layout:
    """Index arrays of one frame length (cached): rows are the two training symbols, then
    the data OFDM symbols; ``known`` entries (training carriers, pilots) row-major."""

    rows: int
    body: np.ndarray  # [rows] body start of each row, samples from the frame start
    times: np.ndarray  # [rows] centre of each row's body, samples
    k_row: np.ndarray  # [num_known] row of each known value
    k_col: np.ndarray  # [num_known] carrier (centred order)
    k_flat: np.ndarray  # [num_known] row * fft_size + FFT bin (natural order) of each
    x_known: np.ndarray  # [num_known] complex64 known value (|x| = 1)
    counts: np.ndarray  # [num_used] observations per used carrier
    smoothers: tuple  # (P [num_models, num_used, num_used] complex64, mse factors
    # [num_models, num_used], dofs [num_models]): the candidate channel models, shortest
    # delay window first, per-carrier LS last
    smoother_training: np.ndarray  # [num_used, num_used] training sums -> smoothed channel
    pairs: np.ndarray  # pilot indices j whose pilot j + 1 is one comb step above
    d_col: np.ndarray  # [num_symbols] carrier of each payload symbol's data element
    d_row: np.ndarray  # [num_symbols] its row
    d_bin: np.ndarray  # [num_symbols] its FFT bin (natural order)
    d_flat: np.ndarray  # [num_symbols] row * fft_size + FFT bin (natural order)
    used: np.ndarray  # used carriers (centred order)
    used_nat: np.ndarray  # their FFT bins (natural order)
    pilots: np.ndarray  # pilot carriers (centred order)
    pilot_in_used: np.ndarray  # position of each pilot carrier among the used ones
    num_training_values: int  # known entries of the two training rows (come first)
    fft_size: int


@functools.lru_cache(maxsize=32)
def _layout(cfg: FrameConfig, num_symbols: int) -> _Layout:
    grid = cfg.data_grid(num_symbols)
    n, cp, s = cfg.fft_size, cfg.cp_length, cfg.symbol_length
    used, pk = grid.used_subcarriers, grid.pilot_subcarriers
    rows = 2 + grid.num_ofdm_symbols
    body = cfg.sync_length + cp + s * np.arange(rows)
    x = np.zeros((rows, n), np.complex64)  # [rows, fft_size]
    x[:2, used] = long_training_symbol(cfg)[used]
    x[2:, pk] = grid.pilots.numpy().reshape(grid.num_ofdm_symbols, pk.size)
    k_row, k_col = np.nonzero(x)
    data = np.zeros((rows, n), bool)
    data[2:] = grid.data_mask.numpy()
    d_row, d_col = np.nonzero(data)  # row-major: resource element j
    # payload symbol i sits on resource element perm^-1[i]
    order = np.argsort(interleaver(d_row.size)) if cfg.interleave else np.arange(d_row.size)
    d_row, d_col = d_row[order[:num_symbols]], d_col[order[:num_symbols]]
    # candidate channel models: taps from backoff samples before the detected first path,
    # as many as the comb has pilots per symbol (more are ill-determined between pilots at
    # low SNR), the whole prefix, and per-carrier LS (no smoothing: high SNR, long channels)
    counts = np.bincount(k_col, minlength=n)[used].astype(np.float64)
    smoothers = []
    for num_taps in sorted({min(cp, pk.size), cp}):
        basis = estimation.delay_basis(used, n, np.arange(num_taps) - cfg.backoff)
        p_mat, factor = estimation.channel_smoother(counts, basis)
        smoothers.append((p_mat.astype(np.complex64), factor, num_taps))
    smoothers.append((np.diag(1.0 / counts).astype(np.complex64), 1.0 / counts, used.size))
    short = estimation.delay_basis(used, n, np.arange(min(cp, pk.size)) - cfg.backoff)
    smoother_training, _ = estimation.channel_smoother(np.full(used.size, 2.0), short)
    return _Layout(
        rows=rows,
        body=body,
        times=(body + n / 2).astype(np.float64),
        k_row=k_row,
        k_col=k_col,
        k_flat=k_row * n + (k_col + n // 2) % n,
        x_known=x[k_row, k_col],
        counts=counts,
        smoothers=(
            np.stack([m[0] for m in smoothers]),
            np.stack([m[1] for m in smoothers]),
            np.array([m[2] for m in smoothers], np.float64),
        ),
        smoother_training=smoother_training.astype(np.complex64),
        pairs=np.flatnonzero(np.diff(pk) == cfg.pilot_subcarrier_spacing),
        d_col=d_col,
        d_row=d_row,
        d_bin=(d_col + n // 2) % n,
        d_flat=d_row * n + (d_col + n // 2) % n,
        used=used,
        used_nat=(used + n // 2) % n,
        pilots=pk,
        pilot_in_used=np.searchsorted(used, pk),
        num_training_values=2 * used.size,
        fft_size=n,
    )


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


def _dc_estimate(r: np.ndarray, start: int, length: int) -> complex:
    """The receiver's DC offset: the mean outside the frame when there are enough such
    samples (the frame's own mean is not zero once a CFO moves carriers onto DC), else
    the mean of everything."""
    outside = r.size - length
    if outside >= 256:
        total = _sum(r[:start]) + _sum(r[start + length :])
        return total / outside
    return _sum(r) / max(r.size, 1)


def _sum(r: np.ndarray) -> complex:
    """Sum of a complex64 array, accumulated in complex128."""
    return complex(r.sum(dtype=np.complex128)) if r.size else 0j


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


def _best_channel(sums: np.ndarray, lay: _Layout, noise_var: float):
    """The candidate channel model with the least Mallows' Cp, ``sum_k c_k |o_k - h_k|^2 +
    2 noise_var dof`` (``o_k`` the mean observation of carrier k, ``c_k`` their count): an
    unbiased estimate of the count-weighted estimation error, so a short delay window wins
    at low SNR and longer models win when truncation bias exceeds noise.

    Returns:
        (h [fft_size] complex64 centred order, mse factor [num_used], dof).
    """
    mean = sums / lay.counts
    p_mats, factors, dofs = lay.smoothers
    h_used = p_mats @ sums.astype(np.complex64)  # [num_models, num_used]
    cp = np.sum(lay.counts * np.abs(mean[None, :] - h_used) ** 2, axis=1) + 2 * noise_var * dofs
    i = int(np.argmin(cp))
    h = np.zeros(lay.fft_size, np.complex64)
    h[lay.used] = h_used[i]
    return h, factors[i], int(dofs[i])


def _channel(obs: np.ndarray, lay: _Layout, smoother, training_only: bool = False) -> np.ndarray:
    """Smoothed channel [fft_size] complex64 (centred order) from observations ``obs`` of
    ``h`` at the known entries (the training rows' alone when ``training_only``)."""
    h = np.zeros(lay.fft_size, np.complex64)
    h[lay.used] = smoother @ _carrier_sums(obs, lay, training_only).astype(np.complex64)
    return h

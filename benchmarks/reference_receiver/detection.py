"""The previous implementation of the frame search, kept unchanged as the reference that the
benchmark times beside :mod:`phy.detection` and that the equivalence test holds it to (the
same frames at the same offsets, the same CFOs to rounding).

The statistics are :mod:`phy.detection`'s (see its docstring); only the way they are computed
differs there. Every function is a copy; only the result type (:class:`phy.detection.Detection`)
and the frame definition (:mod:`phy.frame`, :mod:`phy.sync`) are shared.
"""

from __future__ import annotations

import functools

import numpy as np
import scipy.fft

from phy.detection import Detection
from phy.frame import sync_sequence
from phy.sync import correct_cfo

SEARCH_THRESHOLD = 11.0  # S above this is a candidate: low enough that a frame at -10 dB per
# sample passes it, high enough that few noise samples reach the coherent check
_OVERSAMPLE = 4  # CFO hypotheses per segment-FFT bin spacing 1 / (K L)
_SPAN = 4  # lags either side of the search peak where Q is evaluated
_CHUNK = 1 << 18  # samples per search chunk (bounded memory for long captures)
_POWER_BLOCK = 64  # samples per block of the search's noise-level estimate
_ROWS_PER_PRODUCT = 2048  # segments per matrix product of the segment correlation
_COMB_BLOCK = 1024  # segments per overlap-save block of the search's comb correlation
_COMB_BLOCKS_PER_PASS = 2  # overlap-save blocks per FFT call (keeps the temporaries in cache)
_QUICK = 0.25  # the quick look needs this share of the detection threshold
_HALF_MARGIN = 1.1  # a half-sample lag is taken when its Q is this much above the grid's
_PATH_FRACTION = 0.4  # a first path needs this share of the strongest path's Q
_PATH_PFA = 1e-6  # ... and Q above noise at this false-alarm rate


def threshold_for_pfa(pfa: float, num_samples: int) -> float:
    """The t with ``(1 - t)^(N - 1) == pfa`` (Q ~ Beta(1, N - 1) in noise)."""
    return float(1.0 - pfa ** (1.0 / (num_samples - 1)))


def segment_correlation(r: np.ndarray, base: np.ndarray) -> np.ndarray:
    """c[d] = sum_m r[d+m] conj(base[m]). [num_samples] -> [num_samples - L + 1] complex64.

    Long inputs go through matrix products: with ``r`` as rows of L samples, output
    ``c[q L + p]`` is row q (from column p) and row q + 1 (up to column p) against the
    shifted base, so ``c = rows[:-1] @ M_top + rows[1:] @ M_bottom`` for a fixed [2L, L] M.
    """
    seg = base.size
    r = np.asarray(r, np.complex64)
    b64 = np.asarray(base, np.complex64)
    q = r.size // seg
    if q < 64:
        return np.correlate(r, b64, mode="valid")
    m = _shift_matrix(b64.tobytes())
    rows = r[: q * seg].reshape(q, seg)
    out = np.empty(r.size - seg + 1, np.complex64)
    head = out[: (q - 1) * seg].reshape(q - 1, seg)
    tmp = np.empty((min(q - 1, _ROWS_PER_PRODUCT), seg), np.complex64)
    for i in range(0, q - 1, _ROWS_PER_PRODUCT):  # cache-sized products
        j = min(i + _ROWS_PER_PRODUCT, q - 1)
        np.matmul(rows[i:j], m[:seg], out=head[i:j])
        head[i:j] += np.matmul(rows[i + 1 : j + 1], m[seg:], out=tmp[: j - i])
    out[(q - 1) * seg :] = np.correlate(r[(q - 1) * seg :], b64, mode="valid")
    return out


@functools.lru_cache(maxsize=8)
def _shift_matrix(base_bytes: bytes) -> np.ndarray:
    """[2L, L] complex64: column p holds conj(base) starting at row p."""
    base = np.frombuffer(base_bytes, np.complex64)
    seg = base.size
    m = np.zeros((2 * seg, seg), np.complex64)
    for p in range(seg):
        m[p : p + seg, p] = np.conj(base)
    return m


@functools.lru_cache(maxsize=16)
def _search_plan(cfg) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(base [L] complex64, cover [K] float64, comb [K - 1] complex64): the differential
    comb ``g[k] = s_k s_{k+1}``, one tap per segment."""
    base, cover = sync_sequence(cfg)
    return base.astype(np.complex64), cover, (cover[1:] * cover[:-1]).astype(np.complex64)


@functools.lru_cache(maxsize=16)
def _comb_spectrum(comb_bytes: bytes, block: int) -> np.ndarray:
    """[block] complex64: conj(FFT(comb)) zero-padded to ``block``."""
    comb = np.frombuffer(comb_bytes, np.complex64)
    return np.conj(scipy.fft.fft(comb, block)).astype(np.complex64)


def _comb_correlate(w: np.ndarray, comb: np.ndarray, seg: int) -> np.ndarray:
    """``out[d] = sum_k comb[k] w[d + k seg]``, valid part: [num_w] -> [num_w - (T - 1) seg]
    complex64 for T taps.

    The taps sit one segment apart, so with ``w`` as rows of ``seg`` samples each column
    (one phase within the segment) is correlated with T dense taps: overlap-save FFTs of
    ``_COMB_BLOCK`` rows (fewer for a short ``w``), all columns at once.
    """
    taps = comb.size
    nout = w.size - (taps - 1) * seg
    q = -(-nout // seg)  # output rows
    block = min(_COMB_BLOCK, scipy.fft.next_fast_len(q + taps - 1))
    hop = block - taps + 1
    nb = -(-q // hop)
    whole = w.size // seg
    w_rows = w[: whole * seg].reshape(whole, seg)
    g = _comb_spectrum(comb.tobytes(), block)
    out = np.empty((nb, hop, seg), np.complex64)
    for b0 in range(0, nb, _COMB_BLOCKS_PER_PASS):  # a few blocks at a time: cache-sized
        b1 = min(b0 + _COMB_BLOCKS_PER_PASS, nb)
        r0, r1 = b0 * hop, (b1 - 1) * hop + block  # rows of w these blocks read
        wt = np.zeros((seg, r1 - r0), np.complex64)  # [seg, rows]: w by column
        wt[:, : max(0, min(r1, whole) - r0)] = w_rows[r0:r1].T
        if r0 <= whole < r1:
            wt[: w.size - whole * seg, whole - r0] = w[whole * seg :]
        frames = np.lib.stride_tricks.sliding_window_view(wt, block, axis=-1)[:, ::hop]
        spec = scipy.fft.fft(frames, axis=-1)  # [seg, blocks, block]
        spec *= g
        spec = scipy.fft.ifft(spec, axis=-1, overwrite_x=True)
        out[b0:b1] = spec[:, :, :hop].transpose(1, 2, 0)
    return out.reshape(-1)[:nout]


def _search(r: np.ndarray, cfg) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(c [num_samples - L + 1], |D|^2 [num_samples - N + 1], noise-only variance of D per
    block of ``_POWER_BLOCK`` lags [ceil((num_samples - N + 1) / _POWER_BLOCK)])."""
    base, cover, comb = _search_plan(cfg)
    seg, k = base.size, cover.size
    n = seg * k
    c = segment_correlation(r, base)
    if r.size < n:
        return c, np.zeros(0, np.float32), np.ones(0, np.float32)
    w = np.conj(c[:-seg])
    w *= c[seg:]  # [num_samples - 2L + 1]: neighbouring segments
    d = _comb_correlate(w, comb, seg)  # [num_samples - N + 1]
    sq = d.view(np.float32).reshape(-1, 2)
    np.square(sq, out=sq)
    power = sq[:, 0] + sq[:, 1]
    nb = -(-power.size // _POWER_BLOCK)
    per = n // _POWER_BLOCK
    # the variance of D is (K - 1) E|w|^2: estimated from w itself, block-wise (for white
    # noise E|w|^2 = (E|c|^2)^2; OFDM data, whose tones repeat from segment to segment,
    # has twice that, and normalising by |c|^2 would let it through 8 times as often)
    wv = w.view(np.float32)
    w2 = np.square(wv)
    p = w2[0::2] + w2[1::2]  # |w|^2
    whole = p.size // _POWER_BLOCK
    sums = np.zeros(nb + per, np.float64)
    sums[: min(whole, sums.size)] = (
        p[: whole * _POWER_BLOCK].reshape(whole, -1).sum(1, dtype=np.float64)[: sums.size]
    )
    if whole < sums.size:
        sums[whole] = float(np.sum(p[whole * _POWER_BLOCK :], dtype=np.float64))
    cs = np.concatenate([[0.0], np.cumsum(sums)])
    level = (cs[per : per + nb] - cs[:nb]) / n  # mean |w|^2 over each block's window
    return c, power, ((k - 1) * np.maximum(level, 1e-30)).astype(np.float32)


def coherent_metric(
    c: np.ndarray, energy: np.ndarray, lags: np.ndarray, cover: np.ndarray, seg: int
) -> tuple[np.ndarray, np.ndarray]:
    """Q(d, f) at the given lags over the CFO hypotheses of a zero-padded FFT across segments.

    Args:
        c: segment correlations (:func:`segment_correlation`) covering ``lags + N - L``.
        energy: [num_lags] window energies ``E[d]`` of the lags.
        lags: [num_lags] int preamble starts (indices into ``c``).
        cover: [K] the cover code; seg: L.
    Returns:
        (Q [num_lags, num_bins] float64, the segment sums' FFT [num_lags, num_bins] complex64),
        bin j at ``j / (num_bins L)`` cycles per sample (wrapped to +-1 / (2 L)).
    """
    k = cover.size
    v = c[lags[:, None] + seg * np.arange(k)[None, :]]  # [num_lags, K]
    v *= cover.astype(np.float32)
    spec = scipy.fft.fft(v, _OVERSAMPLE * k, axis=-1)
    q = (spec.real**2 + spec.imag**2) / (k * seg * np.maximum(energy, 1e-30))[:, None]
    return q, spec


def _cfo_cycles(spec_row: np.ndarray, v_bin: int, seg: int) -> float:
    """Coarse CFO (cycles/sample) from the best bin, parabolic interpolation on |spec|."""
    m = spec_row.size
    a, b, c = (abs(spec_row[(v_bin + j) % m]) for j in (-1, 0, 1))
    den = a - 2 * b + c
    delta = 0.5 * (a - c) / den if den < 0 else 0.0
    f = ((v_bin + delta) / m + 0.5) % 1.0 - 0.5  # cycles per segment
    return f / seg


def _segment_sums(c: np.ndarray, lags: np.ndarray, cover: np.ndarray, seg: int, f: float):
    """[num_lags, K] cover-removed segment correlations, CFO f (cycles/sample) removed."""
    k = cover.size
    rot = cover * np.exp(-2j * np.pi * f * seg * np.arange(k))
    return c[lags[:, None] + seg * np.arange(k)[None, :]] * rot[None, :]


@functools.lru_cache(maxsize=16)
def _half_sample_base(cfg) -> np.ndarray:
    """[L] complex64: the periodic base sequence delayed by half a sample (band-limited)."""
    base, _ = sync_sequence(cfg)
    seg = base.size
    j = np.fft.fftfreq(seg) * seg  # signed line index
    return np.fft.ifft(np.fft.fft(base) * np.exp(-1j * np.pi * j / seg)).astype(np.complex64)


def _confirm(x: np.ndarray, c: np.ndarray, d1: int, cfg, cover: np.ndarray):
    """Stage two around the search peak ``d1`` (indices into ``x`` and ``c``).

    Returns (start, cfo subcarriers, Q at the strongest path) or None.
    """
    seg, k = cfg.sync_segment_length, cfg.num_sync_segments
    n = seg * k
    look = cfg.cp_length - cfg.backoff
    lo = max(0, d1 - _SPAN - look)
    hi = min(x.size - n, d1 + _SPAN)
    if hi < max(lo, d1 - _SPAN):
        return None
    e = x[lo : hi + n]
    cs = np.concatenate([[0.0], np.cumsum(e.real.astype(np.float64) ** 2 + e.imag**2)])
    energy = cs[n:] - cs[:-n]  # [hi - lo + 1] window energies from lo
    lags = np.arange(max(lo, d1 - _SPAN), hi + 1)
    q, spec = coherent_metric(c, energy[lags - lo], lags, cover, seg)
    # a quick look at the search peak and its neighbours: most noise candidates stop here
    # (a frame's Q there is within a few dB of its peak, noise's far below threshold)
    if q[np.abs(lags - d1) <= 1].max() < _QUICK * cfg.detection_threshold:
        return None
    # the same at half-sample lags (a preamble half a sample off loses up to 1.3 dB at the
    # integer lags): the base sequence delayed by half a sample, one more set of hypotheses
    # each Beta(1, N - 1) in noise
    c_at = 0  # c[i] belongs to lag i + c_at
    if q.max() < 2 * cfg.detection_threshold:  # only where the 1.3 dB can matter
        c_half = segment_correlation(x[lo : hi + n], _half_sample_base(cfg))
        q_h, spec_h = coherent_metric(c_half, energy[lags - lo], lags - lo, cover, seg)
        if q_h.max() > _HALF_MARGIN * q.max():  # on the grid unless clearly between samples
            q, spec, c, c_at = q_h, spec_h, c_half, lo
    i, j = np.unravel_index(int(np.argmax(q)), q.shape)
    q_peak = float(q[i, j])
    if q_peak <= cfg.detection_threshold:
        return None
    peak = int(lags[i])
    f = _cfo_cycles(spec[i], int(j), seg)
    # fine CFO: the phase between the preamble's halves once the coarse f is removed
    v = _segment_sums(c, np.array([peak - c_at]), cover, seg, f)[0]
    h = k // 2
    f += float(np.angle(v[h : 2 * h].sum() * np.conj(v[:h].sum()))) / (2 * np.pi * h * seg)
    cfo = f * cfg.fft_size
    if abs(cfo) > cfg.max_cfo_subcarriers:
        return None
    # first arriving path: the earliest lag within the prefix before the peak whose Q at f
    # is a fair share of the peak's and above noise
    # (on the region with f removed sample by sample: a CFO also rotates within segments and
    # skews the correlation's peak by a sample at the edge of the CFO range, so the
    # strongest path is looked for again there)
    early = np.arange(max(lo, peak - look), min(hi, peak + 2) + 1)
    region = x[early[0] : early[-1] + n]
    region = correct_cfo(region, f * cfg.fft_size, cfg.fft_size)
    c_f = segment_correlation(region, _search_plan(cfg)[0])  # timing on the grid
    qf = np.abs(_segment_sums(c_f, early - early[0], cover, seg, 0.0).sum(axis=1)) ** 2
    qf /= n * np.maximum(energy[early - lo], 1e-30)
    near = np.abs(early - peak) <= 2
    best = int(np.flatnonzero(near)[np.argmax(qf[near])])
    floor = max(_PATH_FRACTION * qf[best], threshold_for_pfa(_PATH_PFA, n))
    ok = np.flatnonzero(qf[: best + 1] >= floor)
    start = int(early[ok[0]]) if ok.size else int(early[best])
    return start, cfo, q_peak


def _peaks(hit: np.ndarray, power: np.ndarray, width: int) -> list[int]:
    """Candidates at ``hit`` (ascending) by non-maximum suppression: the strongest by |D|
    (a normalised S also peaks where the window holds the first samples of a strong frame
    after silence), then the strongest more than ``width`` away from every one taken, ...
    (no chaining: noise candidates between two frames cannot merge them into one)."""
    left = np.ones(hit.size, bool)
    out = []
    while left.any():
        i = int(np.flatnonzero(left)[np.argmax(power[left])])
        out.append(int(hit[i]))
        left &= np.abs(hit - hit[i]) > width
    return sorted(out)


def find_preambles(r: np.ndarray, cfg) -> list[Detection]:
    """Every sync preamble in ``r`` (DC already removed), ascending.

    Args:
        r: [num_samples] complex64.
        cfg: :class:`phy.FrameConfig`.
    Returns:
        list of :class:`Detection`; starts at least ``cfg.sync_length`` apart.
    """
    _, cover, _ = _search_plan(cfg)
    n = cfg.sync_length
    margin = _SPAN + cfg.cp_length
    found: list[Detection] = []
    for a in range(0, max(r.size - n + 1, 0), _CHUNK):
        s0 = max(0, a - margin)  # the chunk searches lags [a, a + _CHUNK)
        x = r[s0 : a + _CHUNK + n - 1 + _SPAN]
        c, power, var = _search(x, cfg)
        lo, hi = a - s0, min(a - s0 + _CHUNK, power.size)
        if hi <= lo:
            continue
        thr = np.repeat(SEARCH_THRESHOLD * var, _POWER_BLOCK)[lo:hi]
        hit = np.flatnonzero(power[lo:hi] > thr) + lo
        if hit.size == 0:
            continue
        for d1 in _peaks(hit, power[hit], n):
            got = _confirm(x, c, d1, cfg, cover)
            if got is None:
                continue
            det = Detection(got[0] + s0, got[1], got[2])
            if found and det.start - found[-1].start < n:
                if det.metric > found[-1].metric:
                    found[-1] = det
                continue
            found.append(det)
    return found

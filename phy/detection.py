"""Preamble detection with processing gain: the search for frames in a capture.

The sync preamble (:mod:`phy.frame`) is K segments of one base sequence ``b`` of L samples
under a +-1 cover code ``s``. One correlation per sample, ``c[d] = sum_m r[d+m] conj(b[m])``,
gives every segment's correlation ``c[d + k L]``. Two statistics use them:

* **Search** (every sample, CFO-proof): the differential sum
  ``D[d] = sum_k s_k s_{k+1} c[d+(k+1)L] conj(c[d+kL])``. A CFO rotates every term by the
  same ``exp(2j pi f L)``, so ``|D|`` does not care; the cover code makes it peak only at the
  true alignment. Normalised by its noise-only variance,
  ``S = |D|^2 / ((K - 1) mean|w|^2)`` with ``w`` the neighbouring-segment products over
  the window, it is about Exp(1) in noise (a sum of K - 1 uncorrelated products, slightly
  heavier-tailed);
  samples with ``S > SEARCH_THRESHOLD`` become candidates.
* **Decision** (candidates only): the coherent metric over CFO hypotheses,
  ``Q(d, f) = |sum_k s_k exp(-2j pi f k L) c[d + kL]|^2 / (N E[d])`` with ``E[d]`` the energy of
  the N = K L samples of the window: the fraction of that energy along the preamble at CFO f
  (a zero-padded FFT across segments evaluates every f in +-1/(2L) cycles per sample). In
  white Gaussian noise Q ~ Beta(1, N - 1) exactly, whatever the noise level:
  ``Pfa = (1 - t)^(N - 1)`` (:func:`pfa_coherent`); with a preamble at per-sample SNR rho
  along the hypothesis, ``Q > t`` is a noncentral F event (:func:`pd_coherent`).

The coarse CFO is the best hypothesis (parabolic interpolation between bins), refined by the
phase between the two halves of the preamble; timing is the earliest lag (first arriving
path) within the prefix before the strongest one whose Q is a fair share of the peak.
"""

from __future__ import annotations

import functools
import threading
from dataclasses import dataclass

import numpy as np
import scipy.fft
from scipy import stats

from phy import _kernels
from phy.frame import sync_sequence

SEARCH_THRESHOLD = 11.0  # S above this is a candidate: low enough that a frame at -10 dB per
# sample passes it, high enough that few noise samples reach the coherent check
_OVERSAMPLE = 4  # CFO hypotheses per segment-FFT bin spacing 1 / (K L)
_SPAN = 4  # lags either side of the search peak where Q is evaluated
_CHUNK = 1 << 18  # samples per search chunk (bounded memory for long captures)
_POWER_BLOCK = 64  # samples per block of the search's noise-level estimate
_ROWS_PER_PRODUCT = 2048  # segments per matrix product of the segment correlation
_COMB_BLOCK = 1024  # segments per overlap-save block of the search's comb correlation
_QUICK = 0.25  # the quick look needs this share of the detection threshold
_HALF_MARGIN = 1.1  # a half-sample lag is taken when its Q is this much above the grid's
_PATH_FRACTION = 0.4  # a first path needs this share of the strongest path's Q
_PATH_PFA = 1e-6  # ... and Q above noise at this false-alarm rate


@dataclass(frozen=True)
class Detection:
    """One detected preamble.

    Attributes:
        start: first sample of the sync preamble (first arriving path).
        cfo: carrier-frequency offset, subcarrier spacings.
        metric: the coherent metric Q at the strongest path, in [0, 1].
    """

    start: int
    cfo: float
    metric: float


def pfa_coherent(threshold: float, num_samples: int) -> float:
    """P(Q > t) in noise alone for one lag and CFO hypothesis: Q ~ Beta(1, N - 1)."""
    return float((1.0 - threshold) ** (num_samples - 1))


def threshold_for_pfa(pfa: float, num_samples: int) -> float:
    """The t with ``pfa_coherent(t, N) == pfa``."""
    return float(1.0 - pfa ** (1.0 / (num_samples - 1)))


def pd_coherent(threshold: float, num_samples: int, snr: float) -> float:
    """P(Q > t) with a preamble at per-sample SNR ``snr`` (linear) along the hypothesis.

    ``Q = X1 / (X1 + X2)``, ``X1 ~ ncx2(2, 2 N snr)``, ``X2 ~ chi2(2 (N - 1))``, so
    ``Q > t`` iff ``(X1 / 2) / (X2 / (2 (N - 1))) > (N - 1) t / (1 - t)``: a noncentral F.
    """
    n = int(num_samples)
    f = (n - 1) * threshold / (1.0 - threshold)
    return float(stats.ncf.sf(f, 2, 2 * (n - 1), 2 * n * snr))


def segment_correlation(
    r: np.ndarray, base: np.ndarray, out: np.ndarray | None = None
) -> np.ndarray:
    """c[d] = sum_m r[d+m] conj(base[m]). [num_samples] -> [num_samples - L + 1] complex64.

    Long inputs go through matrix products: with ``r`` as rows of L samples, output
    ``c[q L + p]`` is row q (from column p) and row q + 1 (up to column p) against the
    shifted base, so ``c = rows[:-1] @ M_top + rows[1:] @ M_bottom`` for a fixed [2L, L] M.
    ``out`` (optional, [num_samples - L + 1] complex64) receives the result.
    """
    seg = base.size
    r = np.asarray(r, np.complex64)
    b64 = np.asarray(base, np.complex64)
    q = r.size // seg
    if out is None:
        out = np.empty(max(r.size - seg + 1, 0), np.complex64)
    if q < 64:
        if r.size >= seg:
            out[:] = np.correlate(r, b64, mode="valid")
        return out
    m = _shift_matrix(b64.tobytes())
    rows = r[: q * seg].reshape(q, seg)
    head = out[: (q - 1) * seg].reshape(q - 1, seg)
    tmp = np.empty((min(q - 1, _ROWS_PER_PRODUCT), seg), np.complex64)
    for i in range(0, q - 1, _ROWS_PER_PRODUCT):  # cache-sized products
        j = min(i + _ROWS_PER_PRODUCT, q - 1)
        np.matmul(rows[i:j], m[:seg], out=head[i:j])
        head[i:j] += np.matmul(rows[i + 1 : j + 1], m[seg:], out=tmp[: j - i])
    out[(q - 1) * seg :] = np.correlate(r[(q - 1) * seg :], b64, mode="valid")
    return out


def _scratch(name: str, size: int, dtype) -> np.ndarray:
    """[size] array ``name`` of this thread's search workspace, reused from call to call:
    the search's capture-sized temporaries (segment correlations, neighbour products, the
    statistic) stay mapped, so a stream of searches touches no fresh pages."""
    pool = getattr(_WORKSPACE, "pool", None)
    if pool is None:
        pool = _WORKSPACE.pool = {}
    buf = pool.get(name)
    if buf is None or buf.size < size or buf.dtype != dtype:
        buf = pool[name] = np.empty(size, dtype)
    return buf[:size]


_WORKSPACE = threading.local()


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


def _comb_power(w: np.ndarray, comb: np.ndarray, seg: int, out: np.ndarray) -> np.ndarray:
    """``|sum_k comb[k] w[d + k seg]|^2`` for every valid d, T = comb.size taps: ``w`` holds
    the num_w = out.size + (T - 1) seg products and room after them for the blocks' zero
    padding (overwritten); ``out`` [num_w - (T - 1) seg] float32 receives the result.

    The taps sit one segment apart, so with ``w`` as rows of ``seg`` samples each column
    (one phase within the segment) is correlated with T dense taps: overlap-save FFTs of
    ``_COMB_BLOCK`` rows (fewer for a short ``w``) down the columns, all columns at once,
    each block squared into ``out`` while it is in cache.
    """
    taps = comb.size
    nout = out.size
    num_w = nout + (taps - 1) * seg
    q = -(-nout // seg)  # output rows
    block = min(_COMB_BLOCK, scipy.fft.next_fast_len(q + taps - 1))
    hop = block - taps + 1
    nb = -(-q // hop)
    need = (nb - 1) * hop + block  # rows of w the blocks read (zeros past its end)
    w[num_w : need * seg] = 0
    rows = w[: need * seg].reshape(need, seg)
    g = _comb_spectrum(comb.tobytes(), block)[:, None]
    for i in range(0, nb * hop, hop):  # one block of rows, every column: cache-sized
        spec = scipy.fft.fft(rows[i : i + block], axis=0, workers=1)
        spec *= g
        d = scipy.fft.ifft(spec, axis=0, overwrite_x=True, workers=1)[:hop].reshape(-1)
        d = d[: min(hop * seg, nout - i * seg)]
        part = out[i * seg : i * seg + d.size]
        np.multiply(d.real, d.real, out=part)
        part += d.imag * d.imag
    return out


def _search(r: np.ndarray, cfg) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(c [num_samples - L + 1], |D|^2 [num_samples - N + 1], noise-only variance of D per
    block of ``_POWER_BLOCK`` lags [ceil((num_samples - N + 1) / _POWER_BLOCK)]).

    c and |D|^2 are views of this thread's workspace (:func:`_scratch`): valid until the
    thread's next search."""
    base, cover, comb = _search_plan(cfg)
    seg, k = base.size, cover.size
    n = seg * k
    c = segment_correlation(r, base, _scratch("c", max(r.size - seg + 1, 0), np.complex64))
    if r.size < n:
        return c, np.zeros(0, np.float32), np.ones(0, np.float32)
    num_w = c.size - seg  # [num_samples - 2L + 1]: neighbouring segments
    w = _scratch("w", num_w + (_COMB_BLOCK + 1) * seg, np.complex64)
    np.conjugate(c[:-seg], out=w[:num_w])
    w[:num_w] *= c[seg:]
    power = _comb_power(w, comb, seg, _scratch("power", r.size - n + 1, np.float32))
    w = w[:num_w]
    nb = -(-power.size // _POWER_BLOCK)
    per = n // _POWER_BLOCK
    # the variance of D is (K - 1) E|w|^2: estimated from w itself, block-wise (for white
    # noise E|w|^2 = (E|c|^2)^2; OFDM data, whose tones repeat from segment to segment,
    # has twice that, and normalising by |c|^2 would let it through 8 times as often)
    wv = w.view(np.float32)
    whole = w.size // _POWER_BLOCK
    sums = np.zeros(nb + per, np.float64)
    head = wv[: whole * 2 * _POWER_BLOCK].reshape(whole, -1)[: sums.size]
    sums[: head.shape[0]] = np.einsum("ij,ij->i", head, head)  # |w|^2 per block
    if whole < sums.size:
        tail = wv[whole * 2 * _POWER_BLOCK :].astype(np.float64)
        sums[whole] = float(tail @ tail)
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
    lags = np.asarray(lags, np.int64)
    if lags.size and (lags.min() < 0 or lags.max() + seg * (cover.size - 1) >= c.size):
        raise IndexError("the lags' segments run past the correlations")
    return _coherent(c, energy, lags, cover, seg)


def _coherent(c, energy, lags, cover, seg):
    """:func:`coherent_metric` without the bounds check (lags [num_lags] int64 known to be
    within ``c``; ``energy`` may run on past them)."""
    k = cover.size
    v = _kernels.segment_rows(c, lags, cover, seg, _OVERSAMPLE * k)
    spec = scipy.fft.fft(v, axis=-1, overwrite_x=True)  # zero-padded rows
    return _kernels.normalised_power(spec, np.asarray(energy, np.float64), k * seg), spec


def _cfo_cycles(spec_row: np.ndarray, v_bin: int, seg: int) -> float:
    """Coarse CFO (cycles/sample) from the best bin, parabolic interpolation on |spec|."""
    m = spec_row.size
    a, b, c = (abs(spec_row[(v_bin + j) % m]) for j in (-1, 0, 1))
    den = a - 2 * b + c
    delta = 0.5 * (a - c) / den if den < 0 else 0.0
    f = ((v_bin + delta) / m + 0.5) % 1.0 - 0.5  # cycles per segment
    return f / seg


@functools.lru_cache(maxsize=16)
def _half_sample_base(cfg) -> np.ndarray:
    """[L] complex64: the periodic base sequence delayed by half a sample (band-limited)."""
    base, _ = sync_sequence(cfg)
    seg = base.size
    j = np.fft.fftfreq(seg) * seg  # signed line index
    return np.fft.ifft(np.fft.fft(base) * np.exp(-1j * np.pi * j / seg)).astype(np.complex64)


@functools.lru_cache(maxsize=16)
def _preamble(cfg) -> np.ndarray:
    """[N] complex64: the sync preamble at unit power, ``cover[j // L] base[j % L]``."""
    base, cover, _ = _search_plan(cfg)
    return (cover[:, None] * base[None, :]).reshape(-1).astype(np.complex64)


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
    energy = _kernels.window_energies(x[lo : hi + n], n)  # [hi - lo + 1] windows from lo
    l0 = max(lo, d1 - _SPAN)  # lags l0 .. hi (within c by construction)
    lags = np.arange(l0, hi + 1)
    q, spec = _coherent(c, energy[l0 - lo :], lags, cover, seg)
    # a quick look at the search peak and its neighbours: most noise candidates stop here
    # (a frame's Q there is within a few dB of its peak, noise's far below threshold)
    if q[max(d1 - 1 - l0, 0) : d1 + 2 - l0].max() < _QUICK * cfg.detection_threshold:
        return None
    # the same at half-sample lags (a preamble half a sample off loses up to 1.3 dB at the
    # integer lags): the base sequence delayed by half a sample, one more set of hypotheses
    # each Beta(1, N - 1) in noise
    c_at = 0  # c[i] belongs to lag i + c_at
    if q.max() < 2 * cfg.detection_threshold:  # only where the 1.3 dB can matter
        c_half = segment_correlation(x[lo : hi + n], _half_sample_base(cfg))
        q_h, spec_h = _coherent(c_half, energy[l0 - lo :], lags - lo, cover, seg)
        if q_h.max() > _HALF_MARGIN * q.max():  # on the grid unless clearly between samples
            q, spec, c, c_at = q_h, spec_h, c_half, lo
    i, j = divmod(int(np.argmax(q)), q.shape[1])
    q_peak = float(q[i, j])
    if q_peak <= cfg.detection_threshold:
        return None
    peak = int(lags[i])
    f = _cfo_cycles(spec[i], int(j), seg)
    # fine CFO: the phase between the preamble's halves once the coarse f is removed
    f += _kernels.half_phase(c, peak - c_at, cover, seg, f) / (2 * np.pi * (k // 2) * seg)
    cfo = f * cfg.fft_size
    if abs(cfo) > cfg.max_cfo_subcarriers:
        return None
    # first arriving path: the earliest lag within the prefix before the peak whose Q at f
    # is a fair share of the peak's and above noise
    # (on the region with f removed sample by sample: a CFO also rotates within segments and
    # skews the correlation's peak by a sample at the edge of the CFO range, so the
    # strongest path is looked for again there)
    e0, e1 = max(lo, peak - look), min(hi, peak + 2)  # lags e0 .. e1
    # (the whole preamble with f applied against the region: the same sums as correlating
    # the corrected region segment by segment; exp(2j pi f (k L + m)) as segment x sample)
    template = _kernels.cfo_template(_preamble(cfg), f, seg, k)
    qf = np.abs(np.correlate(x[e0 : e1 + n], template, "valid")) ** 2
    qf /= n * np.maximum(energy[e0 - lo : e1 - lo + 1], 1e-30)
    near = max(peak - 2 - e0, 0)  # lags within 2 of the peak: near .. near + 4
    best = near + int(np.argmax(qf[near : peak + 3 - e0]))
    floor = max(_PATH_FRACTION * qf[best], threshold_for_pfa(_PATH_PFA, n))
    ok = np.flatnonzero(qf[: best + 1] >= floor)
    start = e0 + int(ok[0] if ok.size else best)
    return start, cfo, q_peak


def _peaks(hit: np.ndarray, power: np.ndarray, width: int) -> list[int]:
    """Candidates at ``hit`` (ascending) by non-maximum suppression: the strongest by |D|
    (a normalised S also peaks where the window holds the first samples of a strong frame
    after silence), then the strongest more than ``width`` away from every one taken, ...
    (no chaining: noise candidates between two frames cannot merge them into one)."""
    return _kernels.peaks(np.asarray(hit, np.int64), power, width).tolist()


def find_preambles(r: np.ndarray, cfg, offset: complex | np.complexfloating = 0) -> list[Detection]:
    """Every sync preamble in ``r - offset``, ascending.

    Args:
        r: [num_samples] complex64.
        cfg: :class:`phy.FrameConfig`.
        offset: the capture's DC offset, subtracted chunk by chunk as it is searched
            (0 when ``r`` has none).
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
        if offset:
            x = np.subtract(x, np.complex64(offset), out=_scratch("x", x.size, np.complex64))
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

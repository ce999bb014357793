"""Synchronisation for real radios: Schmidl-Cox detection, CFO and timing estimation.

Pure numpy functions on IQ streams ``[num_samples] complex64``. CFO is expressed in
subcarrier spacings (``cfo_hz = cfo * sample_rate_hz / fft_size``); timing in samples.

T. M. Schmidl and D. C. Cox, "Robust frequency and timing synchronization for OFDM",
IEEE Trans. Commun. 45(12), 1997: a training symbol whose two halves are identical gives
a timing metric with a plateau over the cyclic prefix and the fractional CFO (modulo two
subcarriers) from the phase between the halves; the even integer part comes from a second
known symbol, here by a differential correlation across neighbouring carriers that the
channel's frequency selectivity barely disturbs.
"""

from __future__ import annotations

import numpy as np


def sliding_sum(v: np.ndarray, length: int) -> np.ndarray:
    """s[d] = sum(v[d : d + length]) for d in [0, len(v) - length]."""
    c = np.concatenate([[0], np.cumsum(v)])
    return c[length:] - c[:-length]


def schmidl_cox_metric(iq: np.ndarray, half_length: int):
    """Timing metric and half-symbol correlation.

    ``P[d] = sum_m conj(r[d+m]) r[d+m+L]``, ``M[d] = |P|^2 / (E1 E2)`` with E1, E2 the
    energies of the two halves (so 0 <= M <= 1).

    Args:
        iq: [num_samples] complex.
        half_length: L, half the FFT size.
    Returns:
        (M [num_samples - 2L + 1] float64, P [num_samples - 2L + 1] complex128).
    """
    r = np.asarray(iq, dtype=np.complex64)
    L = int(half_length)
    if r.size < 2 * L:
        return np.zeros(0), np.zeros(0, dtype=np.complex128)
    c = np.conj(r[:-L]) * r[L:]
    p = sliding_sum(c.astype(np.complex128), L)  # float64 sums: no drift over long captures
    e = sliding_sum((r.real**2 + r.imag**2).astype(np.float64), L)  # energy of each L-window
    e1, e2 = e[: p.size], e[L : L + p.size]
    m = (p.real**2 + p.imag**2) / np.maximum(e1 * e2, 1e-30)
    return m, p


def detect_plateaus(
    metric: np.ndarray, threshold: float, min_length: int, merge_gap: int
) -> list[tuple[int, int]]:
    """Runs where ``metric > threshold`` lasting at least ``min_length`` samples.

    Runs closer than ``merge_gap`` are merged. Returns [(first, last)] inclusive indices.
    """
    above = metric > threshold
    if not above.any():
        return []
    edges = np.flatnonzero(np.diff(np.r_[0, above.astype(np.int8), 0]))
    runs = [(int(a), int(b) - 1) for a, b in zip(edges[::2], edges[1::2])]
    merged: list[tuple[int, int]] = []
    for a, b in runs:
        if merged and a - merged[-1][1] <= merge_gap:
            merged[-1] = (merged[-1][0], b)
        else:
            merged.append((a, b))
    return [(a, b) for a, b in merged if b - a + 1 >= min_length]


def plateau_centre(metric: np.ndarray, first: int, last: int, fraction: float = 0.9) -> int:
    """Centre of the samples of a run within ``fraction`` of its maximum."""
    seg = metric[first : last + 1]
    idx = np.flatnonzero(seg >= fraction * seg.max())
    return first + int(round((idx[0] + idx[-1]) / 2))


def fractional_cfo(p_value: complex) -> float:
    """CFO in subcarriers modulo 2 from the Schmidl-Cox correlation, in (-1, 1]."""
    return float(np.angle(p_value) / np.pi)


def correct_cfo(
    iq: np.ndarray, cfo_subcarriers: float, fft_size: int, start: int = 0
) -> np.ndarray:
    """Multiply by ``exp(-2j pi cfo (n - start) / fft_size)``: removes a CFO of ``cfo`` carriers."""
    n = np.arange(len(iq), dtype=np.float64) - start
    phase = np.mod(n * (-2 * np.pi * cfo_subcarriers / fft_size), 2 * np.pi).astype(np.float32)
    rot = np.empty(len(iq), dtype=np.complex64)
    rot.real, rot.imag = np.cos(phase), np.sin(phase)
    return np.asarray(iq, dtype=np.complex64) * rot


def integer_cfo(
    y_freq: np.ndarray, x_known: np.ndarray, used: np.ndarray, max_shift: int, step: int = 2
) -> int:
    """Integer carrier shift of a received known symbol, by differential correlation.

    For a shift g, ``sum_k Y[k+1+g] conj(Y[k+g]) * conj(X[k+1] conj(X[k]))`` over pairs of
    adjacent used carriers: a channel that varies slowly across carriers only rotates it.

    Args:
        y_freq: [fft_size] received symbol after FFT (centred order).
        x_known: [fft_size] the transmitted symbol (centred order).
        used: indices of the used carriers (centred order).
        max_shift: search g in [-max_shift, max_shift] in steps of ``step`` (2 after a
            Schmidl-Cox fractional estimate, whose ambiguity is two carriers).
    Returns:
        g (int): the received symbol sits ``g`` carriers above its nominal position.
    """
    n = len(y_freq)
    used = np.asarray(used)
    pairs = used[:-1][np.diff(used) == 1]  # k with k and k+1 both used
    dx = x_known[pairs + 1] * np.conj(x_known[pairs])
    best, best_g = -1.0, 0
    for g in range(-int(max_shift) // step * step, int(max_shift) + 1, step):
        k = pairs + g
        ok = (k >= 0) & (k + 1 < n)
        if not ok.any():
            continue
        dy = y_freq[k[ok] + 1] * np.conj(y_freq[k[ok]])
        v = abs(np.sum(dy * np.conj(dx[ok])))
        if v > best:
            best, best_g = v, g
    return best_g


def cross_correlation(iq: np.ndarray, reference: np.ndarray, start: int, stop: int) -> np.ndarray:
    """|sum_m r[d+m] conj(ref[m])| / (|ref| * |r[d:d+len(ref)]|) for d in [start, stop).

    Normalised to [0, 1]; indices outside the stream give 0.
    """
    ref = np.asarray(reference, dtype=np.complex128)
    L = len(ref)
    start, stop = max(0, int(start)), min(int(stop), len(iq) - L + 1)
    if stop <= start:
        return np.zeros(0)
    seg = np.asarray(iq[start : stop + L - 1], dtype=np.complex128)
    num = np.abs(np.correlate(seg, ref, mode="valid"))
    energy = sliding_sum(np.abs(seg) ** 2, L)
    return num / np.maximum(np.sqrt(energy) * np.linalg.norm(ref), 1e-30)


def first_path(corr: np.ndarray, fraction: float = 0.5, lookback: int = 16) -> int:
    """Index of the earliest sample within ``lookback`` before the peak reaching
    ``fraction`` of it: the first arriving path rather than the strongest."""
    peak = int(np.argmax(corr))
    lo = max(0, peak - lookback)
    cand = np.flatnonzero(corr[lo : peak + 1] >= fraction * corr[peak])
    return lo + int(cand[0])

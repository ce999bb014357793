"""Compiled loops of the receiver's estimation and equalisation (numba, cached on disk): the
per-frame work that numpy would spread over dozens of calls on small arrays, as one pass over
the known (or the payload's) entries. Products of complex64 values stay complex64; sums
accumulate in 64 bits.
"""

from __future__ import annotations

import numpy as np

from common import lazy_njit


def _compile_helpers(numba) -> None:
    """What kernels call, compiled before the first kernel (module globals, so the kernels'
    compiled code calls the compiled helpers)."""
    for name, fn in _HELPERS.items():
        if not isinstance(globals()[name], numba.core.registry.CPUDispatcher):
            globals()[name] = numba.njit(cache=True)(fn)


def njit(**options):
    """:func:`common.lazy_njit` with the helpers compiled first."""
    return lazy_njit(before=_compile_helpers, **options)


_HELPERS: dict = {}


def helper(python_function):
    """A function that kernels call: compiled by numba with the first kernel compiled (until
    then, and for Python callers, it stays plain Python)."""
    _HELPERS[python_function.__name__] = python_function
    return python_function


@njit(cache=True)
def row_sums(yx, h_used, k_row, k_pos, rows):  # pragma: no cover - compiled
    """[rows] complex64: by row, the sum of ``yx[i] conj(h_used[k_pos[i]])``."""
    acc = np.zeros(rows, np.complex128)
    for i in range(yx.size):
        acc[k_row[i]] += yx[i] * np.conj(h_used[k_pos[i]])
    return acc.astype(np.complex64)


@njit(cache=True)
def refine(yx, rot, k_row, k_pos, counts, p_mats, bands, dofs, rows):  # pragma: no cover
    """One channel update with the common phase ``rot`` [rows] removed.

    The observations ``obs = yx rot[k_row]`` of ``h`` are summed per used carrier (``k_pos``);
    each candidate model j (``h_j = p_mats[j] @ sums``, ``dofs[j]`` taps) is scored by
    Mallows' Cp, ``sum_k c_k |o_k - h_jk|^2 + 2 noise dofs[j]`` (``o_k`` the mean observation
    of carrier k, ``c_k = counts[k]`` their number): an unbiased estimate of the count-weighted
    estimation error, so a short delay window wins at low SNR and longer models win when
    truncation bias exceeds noise. Cp's noise level comes from the richest model (per-carrier
    means): unbiased whichever model is right, so a low training-difference estimate cannot
    pick a noisy model. Row k of model j has its non-zeros in columns
    ``bands[j, k, 0] <= q < bands[j, k, 1]`` (the products outside are exact zeros).

    Returns:
        (obs [num_known] complex64, h [num_used] complex64 of the least-Cp model, its index,
        the noise variance of the residuals ``obs - h[k_pos]`` over their degrees of freedom).
    """
    m, nu, nm = yx.size, counts.size, p_mats.shape[0]
    obs = np.empty(m, np.complex64)
    sums = np.zeros(nu, np.complex128)
    energy = 0.0
    for i in range(m):
        o = yx[i] * rot[k_row[i]]
        obs[i] = o
        sums[k_pos[i]] += o
        energy += o.real * o.real + o.imag * o.imag
    spread = 0.0
    for k in range(nu):
        spread += (sums[k].real ** 2 + sums[k].imag ** 2) / counts[k]
    cp_noise = max((energy - spread) / max(m - nu - rows, 1), 1e-12)
    sums64 = sums.astype(np.complex64)
    best, best_cp = 0, np.inf
    h_best = np.zeros(nu, np.complex64)
    h = np.empty(nu, np.complex64)
    for j in range(nm):
        cp = 2.0 * cp_noise * dofs[j]
        for k in range(nu):
            v = 0j
            for q in range(bands[j, k, 0], bands[j, k, 1]):
                v += p_mats[j, k, q] * sums64[q]
            h[k] = v
            d = sums[k] / counts[k] - h[k]
            cp += counts[k] * (d.real * d.real + d.imag * d.imag)
        if cp < best_cp:
            best, best_cp = j, cp
            h_best[:] = h
    dof = max(m - int(dofs[best]) - rows, 1)
    resid = 0.0
    for i in range(m):
        e = obs[i] - h_best[k_pos[i]]
        resid += e.real * e.real + e.imag * e.imag
    return obs, h_best, best, max(resid / dof, 1e-12)


@njit(cache=True)
def equalize(y, rot, h, ramp, s_car, centred, d_row, d_bin, zf):  # pragma: no cover - compiled
    """One-tap equalisation of the payload's data elements of ``y`` [rows * n] when every row
    has the same window delay: per FFT bin b (carrier ``centred[b]``) the model
    ``g = h ramp`` and the weight ``conj(g) / |g|^2`` (ZF) or ``conj(g) / (|g|^2 + s)``
    (MMSE, ``s = s_car``), applied with the row phase ``rot[row]`` (``exp(-j phi)``).
    Returns (x [num_symbols] complex64, noise variance ``s / (|g|^2 [+ s])`` float32)."""
    n = centred.size
    weight = np.empty(n, np.complex64)
    noise = np.empty(n, np.float32)
    for b in range(n):
        k = centred[b]
        g = h[k] * ramp[k]
        gain = g.real * g.real + g.imag * g.imag
        inv = np.float32(1.0) / (max(gain, np.float32(1e-24)) if zf else gain + s_car[k])
        weight[b] = np.conj(g) * inv
        noise[b] = s_car[k] * inv
    m = d_row.size
    x = np.empty(m, np.complex64)
    nv = np.empty(m, np.float32)
    for i in range(m):
        r, b = d_row[i], d_bin[i]
        x[i] = y[r * n + b] * (rot[r] * weight[b])
        nv[i] = noise[b]
    return x, nv


@njit(cache=True)
def window_energies(e, n):  # pragma: no cover - compiled
    """[e.size - n + 1] float64: the energy of each window of ``n`` samples of ``e``
    (differences of the running sum of |e|^2, as a cumulative sum would give them)."""
    cs = np.empty(e.size + 1, np.float64)
    cs[0] = 0.0
    acc = 0.0
    for i in range(e.size):
        re = np.float64(e[i].real)
        acc += re * re + np.float64(e[i].imag * e[i].imag)
        cs[i + 1] = acc
    return cs[n:] - cs[: cs.size - n]


@njit(cache=True)
def half_phase(c, at, cover, seg, f):  # pragma: no cover - compiled
    """The phase from the first to the second half of the preamble's cover-removed segment
    correlations ``c[at + k seg] cover[k]`` once a CFO of ``f`` cycles/sample is removed."""
    k = cover.size
    h = k // 2
    first, second = 0j, 0j
    for i in range(2 * h):
        v = c[at + seg * i] * (cover[i] * np.exp(-2j * np.pi * f * seg * i))
        if i < h:
            first += v
        else:
            second += v
    return np.angle(second * np.conj(first))


@njit(cache=True)
def cfo_template(preamble, f, seg, k):  # pragma: no cover - compiled
    """[k seg] complex64: the preamble with a CFO of ``f`` cycles/sample applied,
    ``exp(2j pi f (i seg + m))`` as segment phase times sample phase."""
    out = np.empty(k * seg, np.complex64)
    b = np.exp(2j * np.pi * f * np.arange(seg))
    for i in range(k):
        a = np.exp(2j * np.pi * f * seg * i)
        for m in range(seg):
            out[i * seg + m] = preamble[i * seg + m] * np.complex64(a * b[m])
    return out


@njit(cache=True)
def rotated_windows(frame, starts, w, n, dc):  # pragma: no cover - compiled
    """[num_windows, n] complex64: ``frame[s : s + n] - dc`` for each start s, times
    ``exp(1j w (s + m)) / sqrt(n)`` at its sample m (row phase times sample phase)."""
    col = (np.exp(1j * w * np.arange(n)) / np.sqrt(n)).astype(np.complex64)
    out = np.empty((starts.size, n), np.complex64)
    for r in range(starts.size):
        s = starts[r]
        if s < 0 or s + n > frame.size:
            raise IndexError("a window runs past the frame")
        a = np.complex64(np.exp(1j * w * s))
        for m in range(n):
            out[r, m] = (frame[s + m] - dc) * (a * col[m])
    return out


@njit(cache=True)
def phase_line(
    yx, h_used, k_row, k_pos, pilot_in_used, rows, noise_var, w, window_snr, a
):  # pragma: no cover - compiled
    """The common phase of every row: :func:`phy.estimation.track_phase` once its slope
    search gave ``w`` (radians per row), on the rows' sums ``a = sum yx conj(h_used[k_pos])``
    by row (:func:`row_sums`; computed here when ``a`` is empty): ``w`` refined by the phase
    between the halves, the line through ``a``, then the residual smoothed over as many rows
    as it takes to reach ``window_snr`` at one data row's SNR ``|h at the pilots|^2 /
    noise_var``. Returns (``exp(-j phi)`` [rows] complex64, slope, the row SNR)."""
    if a.size != rows:
        acc = np.zeros(rows, np.complex128)
        for i in range(yx.size):
            acc[k_row[i]] += yx[i] * np.conj(h_used[k_pos[i]])
        a = acc.astype(np.complex64)
    snr_row = 0.0
    for p in pilot_in_used:
        snr_row += h_used[p].real ** 2 + h_used[p].imag ** 2
    snr_row /= noise_var
    phi, w = _line(a, w, window_snr, snr_row)
    rot = np.empty(rows, np.complex64)
    for i in range(rows):
        angle = np.float32(-phi[i])
        rot[i] = np.complex64(np.cos(angle) + 1j * np.sin(angle))
    return rot, w, snr_row


@helper
def _line(a, w, window_snr, snr_row):  # pragma: no cover - compiled
    """(phi [rows] float64, slope) for :func:`phase_line`."""
    rows = a.size
    h = rows // 2
    if rows >= 2:
        first, second = 0j, 0j
        step, z = np.exp(-1j * w), 1.0 + 0j  # z = exp(-j w i) by recurrence
        for i in range(2 * h):
            v = a[i] * z
            if i < h:
                first += v
            else:
                second += v
            z *= step
        w += np.angle(second * np.conj(first)) / h
    unrotated = np.empty(rows, np.complex128)
    step, z = np.exp(-1j * w), 1.0 + 0j
    total = 0j
    for i in range(rows):
        unrotated[i] = z
        total += a[i] * z
        z *= step
    phi0 = np.angle(total)
    line = phi0 + w * np.arange(rows)
    width = int(np.ceil(window_snr / max(snr_row, 1e-6))) | 1
    if width >= rows:
        return line, w
    resid = a * unrotated * np.exp(-1j * phi0)
    if width > 1:  # centred moving sum over width rows, truncated at the ends
        half = width // 2
        cs = np.zeros(rows + 1, np.complex128)
        for i in range(rows):
            cs[i + 1] = cs[i] + resid[i]
        for i in range(rows):
            resid[i] = cs[min(i + half + 1, rows)] - cs[max(i - half, 0)]
    return line + np.angle(resid), w


@njit(cache=True)
def delay_drift(
    obs, h_pk, pairs, pair_step, times, fft_size, window_snr, snr_row, significance
):  # pragma: no cover - compiled
    """:func:`phy.estimation.track_delay` on ``z = obs conj(h_pk)`` (``obs`` the data rows'
    pilot observations, [rows * num_pilots] row-major): the residual drift, or 0."""
    rows, npk = times.size, h_pk.size
    block = min(rows, int(np.ceil(window_snr / max(snr_row, 1e-6))))
    nb = rows // block
    if nb < 2:
        return 0.0
    g = np.zeros(nb, np.complex128)
    tb = np.zeros(nb, np.float64)
    zb = np.empty(npk, np.complex128)
    hc = np.conj(h_pk)
    for b in range(nb):
        zb[:] = 0
        for r in range(b * block, (b + 1) * block):
            for p in range(npk):
                zb[p] += obs[r * npk + p] * hc[p]
            tb[b] += times[r]
        tb[b] /= block
        for j in pairs:
            g[b] += zb[j + 1] * np.conj(zb[j])
    tau = np.angle(g) * (-fft_size / (2 * np.pi * pair_step))
    wgt = np.abs(g)
    sw = max(wgt.sum(), 1e-30)
    dt = tb - (wgt * tb).sum() / sw
    wdt = wgt * dt
    sxx = (wdt * dt).sum() / sw
    if sxx <= 0 or nb < 4:
        return 0.0
    slope = (wdt * tau).sum() / sw / sxx
    resid = tau - ((wgt * tau).sum() / sw + slope * dt)
    var_slope = (wgt * resid * resid).sum() / sw / sxx / (nb - 2)
    # a drift that the blocks cannot tell from zero is zero (low SNR: no random walk)
    return slope if slope**2 > significance**2 * var_slope else 0.0


@njit(cache=True)
def segment_rows(c, lags, cover, seg, width):  # pragma: no cover - compiled
    """[num_lags, width] complex64: ``c[lag + k seg] cover[k]`` for k < K, zeros after."""
    k = cover.size
    v = np.zeros((lags.size, width), np.complex64)
    for i in range(lags.size):
        for j in range(k):
            v[i, j] = c[lags[i] + seg * j] * np.float32(cover[j])
    return v


@njit(cache=True)
def normalised_power(spec, energy, scale):  # pragma: no cover - compiled
    """[num_lags, num_bins] float64: ``|spec|^2 / (scale max(energy, 1e-30))`` by row."""
    q = np.empty(spec.shape, np.float64)
    for i in range(spec.shape[0]):
        den = scale * max(energy[i], 1e-30)
        for j in range(spec.shape[1]):
            s = spec[i, j]
            q[i, j] = np.float32(s.real * s.real + s.imag * s.imag) / den
    return q


@njit(cache=True)
def peaks(hit, power, width):  # pragma: no cover - compiled
    """Non-maximum suppression of the candidates ``hit`` [num_hits] (ascending) with
    ``power`` [num_hits]: the strongest (the first of equals), then the strongest more than
    ``width`` away from every one taken, ... Returns the taken hits, ascending."""
    left = np.ones(hit.size, np.bool_)
    taken = np.empty(hit.size, np.int64)
    count = 0
    while True:
        best = -1
        for i in range(hit.size):
            if left[i] and (best < 0 or power[i] > power[best]):
                best = i
        if best < 0:
            break
        taken[count] = hit[best]
        count += 1
        for i in range(hit.size):
            if abs(hit[i] - hit[best]) <= width:
                left[i] = False
    return np.sort(taken[:count])

"""Time-varying multipath of the emulated air: propagation paths with delay, gain and Doppler.

A path set holds paths ``i``, each a delay ``tau_i`` (seconds after the air's bulk delay
``AirChannel.delay_s``), a complex baseband gain ``a_i`` and a Doppler shift ``f_i`` (Hz).
Segments hold one path set each from their start time ``t_k`` on (the last one for ever),
as ``phy.raytrace.MovingCIR`` re-traces a flight::

    h(t, tau) = sum_i a_i exp(2j pi f_i (t - t_k)) delta(tau - tau_i),   t_k <= t < t_{k+1}

Time ``t`` counts on the transmitter's clock from the channel's epoch, the first sample
sent after the channel was set (:meth:`hil.Medium.set_channel`). A ray-traced path set at
rest has every ``f_i = 0``. Continuity across a segment boundary is the paths' own: a
re-trace whose gains carry the carrier phase on (as ``MovingCIR`` does) is continuous.

At a sample rate ``fs`` each path becomes a band-limited fractional-delay filter: the
Kaiser(7)-windowed sinc of the air's resampler (``RESAMPLER_TAPS`` taps, exact for integer
delays), so ``y[n] = sum_i a_i exp(2j pi f_i t_n) (g_i * x)[n]`` evolves sample by sample.
Paths with the same Doppler shift share one filter (a static set costs one convolution).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

RESAMPLER_TAPS = 48  # the air's band-limited interpolator length (hil.emulation.air re-exports it)
KAISER_BETA = 7.0
MAX_PATH_DELAY_S = 100e-6  # AirPath.delay_s in [0, MAX_PATH_DELAY_S]
MAX_DOPPLER_HZ = 1e5  # |AirPath.doppler_hz| <= MAX_DOPPLER_HZ
MAX_PATHS = 4096  # paths per segment
MAX_SEGMENTS = 4096


def _real(name: str, v) -> float:
    if isinstance(v, bool) or not isinstance(v, int | float | np.floating | np.integer):
        raise ValueError(f"{name} must be a finite number, got {v!r}")
    if not math.isfinite(float(v)):
        raise ValueError(f"{name} must be a finite number, got {v!r}")
    return float(v)


@dataclass(frozen=True)
class AirPath:
    """One propagation path.

    Attributes:
        delay_s: delay after the air's bulk delay, seconds in [0, MAX_PATH_DELAY_S].
        gain: complex baseband gain ``a_i`` (finite).
        doppler_hz: Doppler shift ``f_i``, Hz in [-MAX_DOPPLER_HZ, MAX_DOPPLER_HZ].
    """

    delay_s: float
    gain: complex
    doppler_hz: float = 0.0

    def __post_init__(self):
        d = _real("path delay_s", self.delay_s)
        if not 0 <= d <= MAX_PATH_DELAY_S:
            raise ValueError(f"path delay_s must be in [0, {MAX_PATH_DELAY_S:g}] s, got {d!r}")
        try:
            g = complex(self.gain)
        except (TypeError, ValueError):
            raise ValueError(
                f"path gain must be a finite complex number, got {self.gain!r}"
            ) from None
        if not (math.isfinite(g.real) and math.isfinite(g.imag)):
            raise ValueError(f"path gain must be a finite complex number, got {self.gain!r}")
        f = _real("path doppler_hz", self.doppler_hz)
        if abs(f) > MAX_DOPPLER_HZ:
            raise ValueError(
                f"path doppler_hz must be in [{-MAX_DOPPLER_HZ:g}, {MAX_DOPPLER_HZ:g}] Hz, got "
                f"{f!r}"
            )
        object.__setattr__(self, "delay_s", d)
        object.__setattr__(self, "gain", g)
        object.__setattr__(self, "doppler_hz", f)


@dataclass(frozen=True)
class PathSegment:
    """The paths that hold from ``start_s`` (channel time, seconds >= 0) to the next segment.

    Attributes:
        start_s: seconds from the channel's epoch.
        paths: 1 to MAX_PATHS :class:`AirPath` s.
    """

    start_s: float
    paths: tuple[AirPath, ...]

    def __post_init__(self):
        s = _real("segment start_s", self.start_s)
        if s < 0:
            raise ValueError(f"segment start_s must be >= 0 s, got {s!r}")
        paths = tuple(self.paths)
        if not 1 <= len(paths) <= MAX_PATHS or not all(isinstance(p, AirPath) for p in paths):
            raise ValueError(f"segment paths must be 1 to {MAX_PATHS} AirPath, got {len(paths)}")
        object.__setattr__(self, "start_s", s)
        object.__setattr__(self, "paths", paths)

    @property
    def energy(self) -> float:
        """sum_i |a_i|^2: the segment's mean power gain."""
        return float(sum(abs(p.gain) ** 2 for p in self.paths))


def check_segments(segments) -> tuple[PathSegment, ...]:
    """``segments`` as a validated tuple: the first starts at 0, starts strictly increase.

    Raises:
        ValueError: naming ``path_segments`` and what is wrong.
    """
    segs = tuple(segments)
    if len(segs) > MAX_SEGMENTS or not all(isinstance(s, PathSegment) for s in segs):
        raise ValueError(f"path_segments must be at most {MAX_SEGMENTS} PathSegment")
    if segs and segs[0].start_s != 0:
        raise ValueError(
            f"path_segments: the first segment must start at 0 s, got {segs[0].start_s!r}"
        )
    starts = [s.start_s for s in segs]
    if any(b <= a for a, b in zip(starts, starts[1:])):
        raise ValueError(f"path_segments: start_s must strictly increase, got {starts}")
    if segs and not any(s.energy > 0 for s in segs):
        raise ValueError("path_segments: every path gain is zero")
    return segs


def segments_from_arrays(a, tau_s, doppler_hz=None, start_s=None) -> tuple[PathSegment, ...]:
    """Segments from path arrays (``phy.raytrace.MovingCIR``'s layout); zero gains (padding)
    are dropped, a segment left without paths keeps one silent path.

    Args:
        a: [num_segments, max_paths] (or [max_paths]) complex gains.
        tau_s: the same shape, path delays in seconds (after the first arrival).
        doppler_hz: the same shape, Hz (None: all 0, a channel at rest).
        start_s: [num_segments] seconds (None: 0 for one segment).
    """
    a = np.atleast_2d(np.asarray(a, np.complex128))
    tau = np.atleast_2d(np.asarray(tau_s, np.float64))
    fd = (
        np.zeros_like(tau)
        if doppler_hz is None
        else np.atleast_2d(np.asarray(doppler_hz, np.float64))
    )
    starts = np.zeros(1) if start_s is None else np.asarray(start_s, np.float64).reshape(-1)
    if not (a.shape == tau.shape == fd.shape and a.ndim == 2 and len(starts) == a.shape[0]):
        raise ValueError(
            f"path arrays must share one [num_segments, max_paths] shape with [num_segments] "
            f"start_s, got a {a.shape}, tau_s {tau.shape}, doppler_hz {fd.shape}, "
            f"start_s {starts.shape}"
        )
    segs = []
    for k in range(a.shape[0]):
        live = a[k] != 0
        paths = [
            AirPath(float(t), complex(g), float(f))
            for g, t, f in zip(a[k][live], tau[k][live], fd[k][live])
        ]
        segs.append(PathSegment(float(starts[k]), tuple(paths) or (AirPath(0.0, 0j),)))
    return check_segments(segs)


def kaiser_sinc(offsets: np.ndarray) -> np.ndarray:
    """The air's interpolation kernel: the Kaiser(:data:`KAISER_BETA`)-windowed sinc over
    :data:`RESAMPLER_TAPS` taps, at ``offsets`` (tap position minus the interpolated point,
    samples; any shape). Returns float64 of the same shape."""
    r = np.clip(offsets / (RESAMPLER_TAPS // 2 + 1.0), -1, 1)
    return np.sinc(offsets) * np.i0(KAISER_BETA * np.sqrt(1 - r * r)) / np.i0(KAISER_BETA)


def fractional_delay_taps(delay_samples: float) -> tuple[int, np.ndarray]:
    """The band-limited filter of a delay: ``(l0, g)`` with ``y[n] = sum_j g[j] x[n - l0 - j]``.

    Args:
        delay_samples: delay in samples (>= 0).
    Returns:
        l0 (the first tap's delay, may be negative) and g [num_taps] float64: the
        Kaiser(7)-windowed sinc over RESAMPLER_TAPS taps; one tap 1.0 for an integer delay.
    """
    d = float(delay_samples)
    if abs(d - round(d)) < 1e-9:
        return int(round(d)), np.ones(1)
    half = RESAMPLER_TAPS // 2
    base = math.floor(d)
    lags = np.arange(base - half + 1, base + half + 1)  # [num_taps]
    return int(lags[0]), kaiser_sinc(lags - d)


@dataclass(frozen=True)
class _Group:
    """Paths sharing one Doppler shift, as one FIR: ``y[n] = sum_j taps[j] x[n - l0 - j]``."""

    doppler_hz: float
    l0: int
    taps: np.ndarray  # [num_taps] complex64


class TimeVaryingFir:
    """The air's multipath at one sample rate: what :class:`hil.Medium` filters with.

    Args:
        starts_s: [num_segments] segment starts, seconds.
        groups: per segment, its :class:`_Group` s.
        sample_rate_hz: the rate of the samples it filters.
    """

    def __init__(self, starts_s, groups: list[list[_Group]], sample_rate_hz: float):
        self.starts_s = np.asarray(starts_s, np.float64)
        self.groups = groups
        self.fs = float(sample_rate_hz)
        every = [g for seg in groups for g in seg]
        self.lead = max(0, max(-g.l0 for g in every))  # samples of the future a sample needs
        self.span = max(g.l0 + len(g.taps) for g in every)  # samples of the past it needs
        self.identity = (
            len(every) == 1
            and every[0].doppler_hz == 0
            and every[0].l0 == 0
            and len(every[0].taps) == 1
            and every[0].taps[0] == 1
        )

    @classmethod
    def static(cls, taps: np.ndarray, sample_rate_hz: float = 1.0) -> TimeVaryingFir:
        """One fixed FIR (tap ``l`` delays ``l`` samples)."""
        return cls([0.0], [[_Group(0.0, 0, np.asarray(taps, np.complex64))]], sample_rate_hz)

    @classmethod
    def from_segments(cls, segments, sample_rate_hz: float, scale: float = 1.0) -> TimeVaryingFir:
        """Each segment's paths as band-limited filters at ``sample_rate_hz``, gains times
        ``scale``; paths of equal Doppler summed into one filter."""
        fs = float(sample_rate_hz)
        groups = []
        for seg in segments:
            by_doppler: dict[float, list[tuple[int, np.ndarray]]] = {}
            for p in seg.paths:
                l0, g = fractional_delay_taps(p.delay_s * fs)
                by_doppler.setdefault(p.doppler_hz, []).append((l0, g * (p.gain * scale)))
            out = []
            for f, parts in by_doppler.items():
                lo = min(l0 for l0, _ in parts)
                taps = np.zeros(max(l0 + len(g) for l0, g in parts) - lo, np.complex128)
                for l0, g in parts:
                    taps[l0 - lo : l0 - lo + len(g)] += g
                out.append(_Group(f, lo, taps.astype(np.complex64)))
            groups.append(out)
        return cls([s.start_s for s in segments], groups, fs)

    def apply(self, x: np.ndarray, t0_s: float) -> np.ndarray:
        """Filter ``x`` through the time-varying channel.

        Args:
            x: [num_samples] complex64 at ``fs``; samples outside it are zeros.
            t0_s: channel time of ``x[0]`` (seconds from the epoch).
        Returns:
            [num_samples] complex64, ``y[m] = sum_i a_i exp(2j pi f_i (t_m - t_k))
            (g_i * x)[m]`` with ``t_m = t0_s + m / fs`` in segment ``k``.
        """
        n = len(x)
        # sample m is in segment k from m >= (start_k - t0) fs on (a start within 1e-6
        # sample of a sample's time counts as reached)
        first = np.ceil((self.starts_s - t0_s) * self.fs - 1e-6)
        edges = np.clip(first, 0, n).astype(np.int64)  # [num_segments]
        y: np.ndarray | None = None
        for k in range(len(edges)):
            m0, m1 = int(edges[k]), int(edges[k + 1]) if k + 1 < len(edges) else n
            if k == 0:
                m0 = 0  # before the first start: the first segment, run backwards
            if m1 <= m0:
                continue
            for g in self.groups[k]:
                part = _fir_range(x, g.taps, g.l0, m0, m1)
                if g.doppler_hz != 0:
                    t_m0 = t0_s + m0 / self.fs - self.starts_s[k]
                    part = part * _phasor(g.doppler_hz, t_m0, m1 - m0, self.fs)
                if y is None and (m0, m1) == (0, n):
                    y = part  # a fresh array (never a view of x): safe to add into
                    continue
                if y is None:
                    y = np.zeros(n, np.complex64)
                y[m0:m1] += part
        return np.zeros(n, np.complex64) if y is None else y


def _phasor(f_hz: float, t0_s: float, n: int, fs: float, block: int = 1024) -> np.ndarray:
    """[n] complex64 ``exp(2j pi f_hz (t0_s + m / fs))``: a coarse phasor per block of
    ``block`` samples times one fine table (two small ``exp`` s instead of ``n``)."""
    fine = np.exp(2j * np.pi * f_hz * np.arange(block) / fs)  # [block]
    starts = t0_s + np.arange(-(-n // block)) * (block / fs)  # [num_blocks]
    coarse = np.exp(2j * np.pi * f_hz * starts)
    return (coarse[:, None] * fine[None, :]).reshape(-1)[:n].astype(np.complex64)


def fir_full(x: np.ndarray, taps: np.ndarray) -> np.ndarray:
    """The full convolution of ``x`` [num_samples] complex64 with the FIR ``taps`` (tap ``l``
    delays ``l`` samples): [num_samples + num_taps - 1] complex64. A few non-zero taps (fixed
    echoes) are summed as shifted copies, which is cheaper than ``np.convolve``."""
    nz = np.flatnonzero(taps)
    if len(nz) > 8:
        return np.convolve(x, taps.astype(np.complex64)).astype(np.complex64, copy=False)
    y = np.zeros(len(x) + len(taps) - 1, np.complex64)
    for d in nz:
        y[d : d + len(x)] += x * np.complex64(taps[d])
    return y


def _fir_range(x: np.ndarray, g: np.ndarray, l0: int, m0: int, m1: int) -> np.ndarray:
    """``y[m] = sum_j g[j] x[m - l0 - j]`` for m in [m0, m1), x zero outside its length.

    Returns:
        [m1 - m0] complex64.
    """
    xa, xb = max(0, m0 - l0 - len(g) + 1), min(len(x), m1 - l0)  # the x the outputs read
    if xb <= xa:
        return np.zeros(m1 - m0, np.complex64)
    full = fir_full(x[xa:xb], g)  # full[i] = y[xa + l0 + i]
    lo = xa + l0 - m0  # where full[0] lands in the output
    if lo == 0 and len(full) >= m1 - m0:
        return full[: m1 - m0]
    out = np.zeros(m1 - m0, np.complex64)
    a, b = max(0, lo), min(m1 - m0, lo + len(full))
    out[a:b] = full[a - lo : b - lo]
    return out

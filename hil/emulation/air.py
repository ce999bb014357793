"""The air between emulated radios: a channel config and the pure maths it needs.

Conventions: IQ streams are ``[num_samples] complex64`` with full scale 1.0. A radio with
crystal error ``ppm`` runs its sample clock at ``fs * (1 + ppm * 1e-6)`` and its LO at
``f_c * (1 + ppm * 1e-6)``, so two radios ``ppm`` apart see a carrier offset
``f_c * (ppm_tx - ppm_rx) * 1e-6`` and a sampling-clock drift of the same ratio.
"""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass

import numpy as np

from common import lazy_njit
from hil.emulation.paths import (
    RESAMPLER_TAPS,
    AirPath,
    PathSegment,
    TimeVaryingFir,
    check_segments,
    kaiser_sinc,
    segments_from_arrays,
)

AIR_SNR_DB_RANGE = (-30.0, 100.0)  # AirChannel.snr_db, dB
MAX_DELAY_S = 1.0  # AirChannel.delay_s in [0, MAX_DELAY_S]
MAX_MULTIPATH_DELAY = 4096  # AirChannel.multipath delays in [1, MAX_MULTIPATH_DELAY] samples


@dataclass(frozen=True)
class AirChannel:
    """What happens between the transmitter's DAC and the receiver's ADC.

    Attributes:
        snr_db: SNR at the receiver input of a transmitted signal whose mean power is
            ``reference_power_dbfs`` sent at TX VGA ``reference_txvga_db`` (amp off).
            Raising the TX gain raises the SNR; the RX gains scale signal and noise alike.
        reference_power_dbfs: mean |x|^2 of that reference signal, dB re full scale 1.0.
        reference_txvga_db: TX VGA gain of the reference, dB.
        reference_rx_gain_db: LNA + VGA (+ 14 dB with the amp) at which the received
            reference arrives at ``reference_power_dbfs`` (before noise); other RX gains
            scale it by the difference, then the int8 ADC clips.
        delay_s: propagation delay, s (fractional samples allowed).
        multipath: extra echoes as ``(delay_samples, gain)`` pairs at the TX sample rate
            (integer delays >= 1, complex gains) after the direct path.
        direct_gain: complex gain of the direct path (tap 0).
        path_segments: instead of ``multipath`` and ``direct_gain``, a time-varying
            multipath of :class:`hil.emulation.PathSegment` s (paths with fractional delays in
            seconds, complex gains and Doppler shifts; see :mod:`hil.emulation.paths`), e.g. a
            ray-traced channel (:meth:`from_paths`). Empty: the fixed taps above.
        normalize_taps: scale the taps to unit energy (a pure multipath profile; with
            ``path_segments``: their mean ``sum |a_i|^2`` over segments to 1); False
            keeps the gains as given (a fading realisation, e.g. from a ``phy`` channel).
        dc_offset: complex DC added at the receiver's ADC input, full-scale units.
        iq_gain_imbalance_db: receiver I/Q amplitude imbalance, dB.
        iq_phase_imbalance_deg: receiver I/Q phase imbalance, degrees.
    """

    snr_db: float = 30.0
    reference_power_dbfs: float = -15.0
    reference_txvga_db: float = 30.0
    reference_rx_gain_db: float = 40.0
    delay_s: float = 0.0
    multipath: tuple[tuple[int, complex], ...] = ()
    direct_gain: complex = 1 + 0j
    path_segments: tuple[PathSegment, ...] = ()
    normalize_taps: bool = True
    dc_offset: complex = 0j
    iq_gain_imbalance_db: float = 0.0
    iq_phase_imbalance_deg: float = 0.0

    def __post_init__(self):
        lo, hi = AIR_SNR_DB_RANGE
        if not math.isfinite(self.snr_db) or not lo <= self.snr_db <= hi:
            raise ValueError(f"snr_db must be in [{lo:g}, {hi:g}] dB, got {self.snr_db!r}")
        if not -60 <= self.reference_power_dbfs <= 0:
            raise ValueError(
                f"reference_power_dbfs must be in [-60, 0] dBFS, got {self.reference_power_dbfs!r}"
            )
        if not 0 <= self.delay_s <= MAX_DELAY_S:
            raise ValueError(f"delay_s must be in [0, {MAX_DELAY_S:g}] s, got {self.delay_s!r}")
        for d, _ in self.multipath:
            if int(d) != d or not 1 <= d <= MAX_MULTIPATH_DELAY:
                raise ValueError(
                    f"multipath delays must be integers in [1, {MAX_MULTIPATH_DELAY}] samples, "
                    f"got {d!r}"
                )
        object.__setattr__(self, "path_segments", check_segments(self.path_segments))
        if self.path_segments and (self.multipath or complex(self.direct_gain) != 1):
            raise ValueError(
                "path_segments replace multipath and direct_gain: give one or the other"
            )
        if abs(self.iq_gain_imbalance_db) > 6 or abs(self.iq_phase_imbalance_deg) > 30:
            raise ValueError(
                "iq_gain_imbalance_db must be in [-6, 6] and iq_phase_imbalance_deg in [-30, 30]"
            )

    def to_json(self) -> str:
        """The channel as one line of JSON (complex numbers as ``[re, im]``), what an emulated
        board's ``osnerf_air`` attribute holds; :meth:`from_json` reads it back."""
        d = dataclasses.asdict(self)
        d["multipath"] = [[int(k), complex(g).real, complex(g).imag] for k, g in self.multipath]
        for name in ("direct_gain", "dc_offset"):
            d[name] = [complex(d[name]).real, complex(d[name]).imag]
        d["path_segments"] = [
            [s.start_s, [[p.delay_s, p.gain.real, p.gain.imag, p.doppler_hz] for p in s.paths]]
            for s in self.path_segments
        ]
        return json.dumps(d, separators=(",", ":"))

    @classmethod
    def from_json(cls, text: str) -> AirChannel:
        """The channel :meth:`to_json` wrote; ``ValueError`` naming what is wrong otherwise."""
        try:
            d = json.loads(text)
            d["multipath"] = tuple((int(k), complex(re, im)) for k, re, im in d["multipath"])
            for name in ("direct_gain", "dc_offset"):
                d[name] = complex(*d[name])
            d["path_segments"] = tuple(
                PathSegment(start, tuple(AirPath(t, complex(re, im), f) for t, re, im, f in ps))
                for start, ps in d.get("path_segments", ())
            )
            return cls(**d)
        except (TypeError, KeyError, json.JSONDecodeError) as e:
            raise ValueError(f"not an AirChannel in JSON: {e}") from None

    @classmethod
    def from_taps(cls, taps, normalize: bool = False, **kwargs) -> AirChannel:
        """A channel whose FIR is ``taps`` [num_taps] complex (numpy or torch; tap l delays l
        samples), e.g. one realisation of a ``phy`` TDL or Rayleigh channel; ``kwargs`` set
        the other fields."""
        t = np.asarray(
            taps.detach().cpu().numpy() if hasattr(taps, "detach") else taps, np.complex128
        ).reshape(-1)
        if t.size == 0 or not np.all(np.isfinite(t)) or not np.any(t):
            raise ValueError("taps must be a non-empty, finite, non-zero [num_taps] complex array")
        echoes = tuple((int(d), complex(t[d])) for d in range(1, len(t)) if t[d] != 0)
        return cls(multipath=echoes, direct_gain=complex(t[0]), normalize_taps=normalize, **kwargs)

    @classmethod
    def from_paths(cls, a, tau_s, doppler_hz=None, start_s=None, **kwargs) -> AirChannel:
        """A channel of propagation paths, e.g. a ray-traced one (``phy.raytrace.RayCIR`` or
        ``MovingCIR`` arrays; Doppler None: at rest); ``kwargs`` set the other fields
        (``normalize_taps`` defaults to False here: the gains are kept as given).

        Args:
            a: [num_segments, max_paths] (or [max_paths]) complex gains; 0 is padding.
            tau_s: the same shape, seconds after the first arrival (after ``delay_s``).
            doppler_hz: the same shape, Hz, or None.
            start_s: [num_segments] seconds from the channel's epoch, or None (one segment).
        """
        kwargs.setdefault("normalize_taps", False)
        return cls(path_segments=segments_from_arrays(a, tau_s, doppler_hz, start_s), **kwargs)

    @property
    def max_doppler_hz(self) -> float:
        """The largest |Doppler shift| of any path (0 for fixed taps)."""
        return max((abs(p.doppler_hz) for s in self.path_segments for p in s.paths), default=0.0)

    def fir(self, sample_rate_hz: float) -> TimeVaryingFir:
        """The multipath as a (time-varying) band-limited FIR at ``sample_rate_hz``: the
        fixed taps, or the paths' fractional-delay filters (see :mod:`hil.emulation.paths`)."""
        if not self.path_segments:
            return TimeVaryingFir.static(self.taps, sample_rate_hz)
        scale = 1.0
        if self.normalize_taps:
            energy = float(np.mean([s.energy for s in self.path_segments]))
            scale = 1 / math.sqrt(energy)
        return TimeVaryingFir.from_segments(self.path_segments, sample_rate_hz, scale)

    @property
    def taps(self) -> np.ndarray:
        """[max_delay + 1] complex128 FIR: direct path then echoes (unit energy if normalize_taps).

        Raises:
            ValueError: a channel of ``path_segments`` (its FIR depends on the sample rate:
                see :meth:`fir`).
        """
        if self.path_segments:
            raise ValueError(
                "a channel of path_segments has no fixed taps: use fir(sample_rate_hz)"
            )
        n = 1 + max((int(d) for d, _ in self.multipath), default=0)
        h = np.zeros(n, np.complex128)
        h[0] = complex(self.direct_gain)
        for d, g in self.multipath:
            h[int(d)] += complex(g)
        energy = np.sum(np.abs(h) ** 2)
        if energy == 0:
            raise ValueError("the channel taps are all zero")
        return h / np.sqrt(energy) if self.normalize_taps else h

    @property
    def noise_var(self) -> float:
        """Noise variance per complex sample at the receiver input (full-scale units)."""
        return 10 ** (self.reference_power_dbfs / 10) / 10 ** (self.snr_db / 10)


_PHASES = 1024  # fractional-delay table resolution (timing error <= 1/2048 sample)


def _window_table(phases: int = _PHASES) -> np.ndarray:
    """[phases + 1, RESAMPLER_TAPS] float32: the kernel at each fractional delay k / phases."""
    half = RESAMPLER_TAPS // 2
    offsets = np.arange(-half + 1, half + 1)
    frac = np.arange(phases + 1) / phases
    return kaiser_sinc(offsets[None, :] - frac[:, None]).astype(np.float32)


_TABLE = _window_table()


@lazy_njit(cache=True, nogil=True, fastmath={"reassoc", "contract", "nsz"})  # SIMD sums
def _resample_kernel(x, positions, table, phases, out):  # pragma: no cover - compiled
    """``out[k]``: the ``table`` row of ``positions[k]``'s fractional part (rounded to
    ``1 / phases``) over ``x`` around its integer part, zeros outside ``x``."""
    num_taps = table.shape[1]
    first = 1 - num_taps // 2
    n = x.size
    for k in range(positions.size):
        base = np.floor(positions[k])
        w = table[int(np.rint((positions[k] - base) * phases))]
        lo = int(base) + first
        acc_re = np.float32(0.0)
        acc_im = np.float32(0.0)
        if 0 <= lo and lo + num_taps <= n:
            for j in range(num_taps):
                acc_re += x[lo + j].real * w[j]
                acc_im += x[lo + j].imag * w[j]
        else:
            for j in range(num_taps):
                if 0 <= lo + j < n:
                    acc_re += x[lo + j].real * w[j]
                    acc_im += x[lo + j].imag * w[j]
        out[k] = complex(acc_re, acc_im)


def prepare_resampler() -> None:
    """Compile the resampler now (numba's import and its on-disk cache take a while the
    first time): a paced board's first receive is then as quick as the rest."""
    fractional_resample(np.zeros(64, np.complex64), np.arange(8) + 0.5)


def fractional_resample(x: np.ndarray, positions: np.ndarray) -> np.ndarray:
    """Band-limited interpolation of ``x`` at fractional indices (polyphase Kaiser-windowed sinc).

    Args:
        x: [num_in] complex.
        positions: [num_samples] float64 indices into ``x``; points outside read zeros.
    Returns:
        [num_samples] complex64. Integer positions return ``x`` exactly; otherwise the
        delay is quantised to 1/1024 sample; error below -60 dB for |f| <= 0.45 fs.
    """
    positions = np.ascontiguousarray(positions, np.float64)
    base = np.floor(positions).astype(np.int64)
    out = np.zeros(len(positions), np.complex64)
    if np.array_equal(base, positions):
        ok = (base >= 0) & (base < len(x))
        out[ok] = x[base[ok]]
        return out
    _resample_kernel(np.ascontiguousarray(x, np.complex64), positions, _TABLE, _PHASES, out)
    return out


def iq_imbalance(y: np.ndarray, gain_db: float, phase_deg: float) -> np.ndarray:
    """Receiver I/Q imbalance as ``mu y + nu conj(y)``: I' = I, Q' = g (Q cos(phi) - I sin(phi)).

    Args:
        y: [num_samples] complex.
    Returns:
        [num_samples] complex64; identity when both imbalances are 0.
    """
    if gain_db == 0 and phase_deg == 0:
        return y.astype(np.complex64, copy=False)
    g = 10 ** (gain_db / 20)
    phi = math.radians(phase_deg)
    mu = (1 + g * np.exp(-1j * phi)) / 2
    nu = (1 - g * np.exp(1j * phi)) / 2
    return (mu * y + nu * np.conj(y)).astype(np.complex64)

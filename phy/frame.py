"""Over-the-air frames: preamble + pilot-bearing OFDM symbols, and the receiver that finds them.

Frame layout (each OFDM symbol is ``cp_length + fft_size`` samples)::

    [ Schmidl-Cox symbol | long training | long training | data OFDM symbols ... ]

* Schmidl-Cox symbol: QPSK on the even used carriers only, so its two halves are equal:
  detection, coarse timing and the CFO modulo two carriers.
* Long training symbol, twice: BPSK on every used carrier: the even integer CFO, fine
  timing (first arriving path), a fine CFO from the phase between the copies, the channel
  estimate (their average) and the noise variance (their difference).
* Data symbols: the payload on a :class:`ResourceGrid` whose every OFDM symbol carries
  comb pilots, from which each symbol's common phase (residual CFO, phase noise) and
  timing drift (sampling-clock offset) are tracked; a drift beyond half a sample moves the
  FFT window.

IQ is numpy ``[num_samples] complex64`` with full scale 1.0 (the radio side); received
symbols and noise variances are torch tensors (the codec side).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
import torch

from phy import sync
from phy.ofdm.equalization import EQUALIZERS, equalize
from phy.ofdm.resource_grid import ResourceGrid, extract_data, map_to_grid

_SC_SEED, _LTS_SEED = 0x5C, 0x17


@dataclass(frozen=True)
class FrameConfig:
    """Waveform and receiver settings shared by transmitter and receiver.

    Attributes:
        fft_size: FFT size, a multiple of 4 in [16, 4096].
        cp_length: cyclic prefix in samples, in [4, fft_size // 2].
        num_guard_carriers: (lower, upper) empty carriers at the band edges.
        dc_null: leave the DC carrier empty (SDRs have a DC offset there).
        pilot_subcarrier_spacing: a comb pilot every this many used carriers in every data
            OFDM symbol, in [2, 16].
        sample_rate_hz: sample rate (only converts CFO to Hz), > 0.
        rms_amplitude: RMS of the transmitted IQ, full scale 1.0, in (0, 0.7]; peaks
            above 1.0 are clipped.
        detection_threshold: Schmidl-Cox metric that triggers a detection, in (0, 1).
            Candidates are then confirmed by the two long training symbols (each present,
            and repeating): with the default 0.2 every frame is found at 0 dB SNR per
            sample with multipath, none in 10^6 samples of noise (tests/phy).
        max_cfo_subcarriers: largest |CFO| searched, in subcarrier spacings, in [1, fft_size / 4].
        timing_backoff: samples the FFT window starts inside the prefix, in [0, cp_length);
            ``None`` = ``cp_length // 4``. The receiver tolerates a delay spread up to
            ``cp_length - timing_backoff`` samples.
    """

    fft_size: int = 64
    cp_length: int = 16
    num_guard_carriers: tuple[int, int] = (6, 5)
    dc_null: bool = True
    pilot_subcarrier_spacing: int = 4
    sample_rate_hz: float = 4e6
    rms_amplitude: float = 0.25
    detection_threshold: float = 0.2
    max_cfo_subcarriers: float = 8.0
    timing_backoff: int | None = None

    def __post_init__(self):
        if (
            not isinstance(self.fft_size, int)
            or self.fft_size % 4
            or not 16 <= self.fft_size <= 4096
        ):
            raise ValueError(
                f"fft_size must be a multiple of 4 in [16, 4096], got {self.fft_size!r}"
            )
        if not isinstance(self.cp_length, int) or not 4 <= self.cp_length <= self.fft_size // 2:
            raise ValueError(
                f"cp_length must be an integer in [4, {self.fft_size // 2}], got {self.cp_length!r}"
            )
        if (
            not isinstance(self.pilot_subcarrier_spacing, int)
            or not 2 <= self.pilot_subcarrier_spacing <= 16
        ):
            raise ValueError(
                f"pilot_subcarrier_spacing must be an integer in [2, 16], got {self.pilot_subcarrier_spacing!r}"
            )
        if not math.isfinite(self.sample_rate_hz) or self.sample_rate_hz <= 0:
            raise ValueError(f"sample_rate_hz must be > 0, got {self.sample_rate_hz!r}")
        if not 0 < self.rms_amplitude <= 0.7:
            raise ValueError(f"rms_amplitude must be in (0, 0.7], got {self.rms_amplitude!r}")
        if not 0 < self.detection_threshold < 1:
            raise ValueError(
                f"detection_threshold must be in (0, 1), got {self.detection_threshold!r}"
            )
        if not 1 <= self.max_cfo_subcarriers <= self.fft_size / 4:
            raise ValueError(
                f"max_cfo_subcarriers must be in [1, {self.fft_size / 4:g}], got {self.max_cfo_subcarriers!r}"
            )
        if self.timing_backoff is not None and (
            not isinstance(self.timing_backoff, int)
            or not 0 <= self.timing_backoff < self.cp_length
        ):
            raise ValueError(
                f"timing_backoff must be None or an integer in [0, {self.cp_length - 1}], got {self.timing_backoff!r}"
            )
        object.__setattr__(self, "num_guard_carriers", tuple(self.num_guard_carriers))
        self.data_grid(1)  # validates the carrier layout

    @property
    def backoff(self) -> int:
        return self.cp_length // 4 if self.timing_backoff is None else self.timing_backoff

    @property
    def subcarrier_spacing_hz(self) -> float:
        return self.sample_rate_hz / self.fft_size

    @property
    def symbol_length(self) -> int:
        return self.fft_size + self.cp_length

    @property
    def preamble_length(self) -> int:
        return 3 * self.symbol_length

    def data_grid(self, num_symbols: int) -> ResourceGrid:
        """The resource grid carrying ``num_symbols`` data symbols (pilots in every OFDM symbol)."""
        return _data_grid(self, int(num_symbols))

    def num_samples(self, num_symbols: int) -> int:
        """IQ samples of a frame carrying ``num_symbols`` data symbols."""
        return self.preamble_length + self.data_grid(num_symbols).num_samples


@functools.lru_cache(maxsize=64)
def _data_grid(cfg: FrameConfig, num_symbols: int) -> ResourceGrid:
    """Cached: building the masks of a long grid is not free."""
    one = ResourceGrid(
        fft_size=cfg.fft_size,
        cp_length=cfg.cp_length,
        num_ofdm_symbols=1,
        num_guard_carriers=cfg.num_guard_carriers,
        dc_null=cfg.dc_null,
        pilot_ofdm_symbols=(0,),
        pilot_subcarrier_spacing=cfg.pilot_subcarrier_spacing,
        subcarrier_spacing_hz=cfg.subcarrier_spacing_hz,
    )
    n = max(1, -(-int(num_symbols) // one.num_data_symbols))
    return ResourceGrid(
        fft_size=cfg.fft_size,
        cp_length=cfg.cp_length,
        num_ofdm_symbols=n,
        num_guard_carriers=cfg.num_guard_carriers,
        dc_null=cfg.dc_null,
        pilot_ofdm_symbols=tuple(range(n)),
        pilot_subcarrier_spacing=cfg.pilot_subcarrier_spacing,
        subcarrier_spacing_hz=cfg.subcarrier_spacing_hz,
    )


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


@functools.cache
def _preamble(cfg: FrameConfig):
    """(sc_freq [fft_size], lts_freq [fft_size]) centred-order training symbols, numpy."""
    n = cfg.fft_size
    used = cfg.data_grid(1).used_subcarriers
    sc = np.zeros(n, dtype=np.complex128)
    even = used[(used - n // 2) % 2 == 0]  # even natural bins -> two equal halves in time
    b = np.random.default_rng(_SC_SEED).integers(0, 2, size=(even.size, 2))
    sc[even] = (1 - 2 * b[:, 0]) + 1j * (1 - 2 * b[:, 1])  # |.|^2 = 2: same power as LTS
    lts = np.zeros(n, dtype=np.complex128)
    lts[used] = 1 - 2 * np.random.default_rng(_LTS_SEED).integers(0, 2, size=used.size)
    return sc, lts


def _time_body(freq: np.ndarray) -> np.ndarray:
    return np.fft.ifft(np.fft.ifftshift(freq), norm="ortho")


def _amplitude_scale(cfg: FrameConfig) -> float:
    used = cfg.data_grid(1).used_subcarriers.size
    return cfg.rms_amplitude / math.sqrt(used / cfg.fft_size)


def _as_complex_1d(x, name: str) -> np.ndarray:
    if isinstance(x, torch.Tensor):
        x = x.detach().cpu().numpy()
    x = np.asarray(x)
    if x.ndim != 1 or not np.iscomplexobj(x):
        raise ValueError(
            f"{name} must be a 1-D complex64 array [num_samples], got shape {x.shape} dtype {x.dtype}"
        )
    if not np.all(np.isfinite(x)):
        raise ValueError(f"{name} must be finite")
    return x.astype(np.complex64, copy=False)


def _without_dc(r: np.ndarray) -> np.ndarray:
    """Remove the capture's mean (an SDR's DC offset would make silence look periodic)."""
    return (r - r.mean()).astype(np.complex64) if r.size else r


def build_frame(symbols, cfg: FrameConfig = FrameConfig()) -> np.ndarray:
    """Payload symbols -> one frame of IQ samples.

    Args:
        symbols: [num_symbols] complex64 (torch or numpy), unit mean power.
        cfg: the frame configuration.
    Returns:
        [cfg.num_samples(num_symbols)] complex64 numpy, RMS ``cfg.rms_amplitude``,
        |x| <= 1 (clipped).
    """
    x = _as_complex_1d(symbols, "symbols")
    if x.size < 1:
        raise ValueError("symbols must hold at least 1 symbol")
    grid = cfg.data_grid(x.size)
    xp = torch.zeros(1, grid.num_data_symbols, dtype=torch.complex64)
    xp[0, : x.size] = torch.from_numpy(np.ascontiguousarray(x))
    data = map_to_grid(xp, grid)[0].numpy()  # [num_ofdm_symbols, fft_size]
    sc, lts = _preamble(cfg)
    freq = np.concatenate([sc[None], lts[None], lts[None], data], axis=0)
    body = np.fft.ifft(np.fft.ifftshift(freq, axes=-1), axis=-1, norm="ortho")
    t = np.concatenate([body[:, -cfg.cp_length :], body], axis=-1).reshape(-1)
    t = t * _amplitude_scale(cfg)
    mag = np.abs(t)
    t = np.where(mag > 1.0, t / np.maximum(mag, 1e-30), t)
    return t.astype(np.complex64)


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

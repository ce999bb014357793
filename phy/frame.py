"""Over-the-air frames: a detection preamble, two training symbols, pilot-bearing OFDM symbols.

Frame layout::

    [ sync: K segments of L samples | long training | long training | data OFDM symbols ... ]

* Sync (``sync_length`` = K * L samples): one short base sequence of ``L`` samples (unit
  modulus lines on every ``fft_size / L``-th used carrier in the inner half of the band),
  repeated K times under a random
  +-1 cover code. Correlating with the base sequence once per sample gives each segment's
  correlation; the receiver combines them differentially (CFO-proof, for the search) and
  then coherently over CFO hypotheses (an FFT across segments): the processing gain of
  all K * L samples with a CFO range of +-1 / (2 L) cycles per sample (see
  :mod:`phy.detection` for the statistics and their closed forms).
* Long training symbol, twice (CP + BPSK on every used carrier): channel estimate, noise.
* Data symbols: the payload on a :class:`ResourceGrid` whose every OFDM symbol carries
  comb pilots. The payload is interleaved over all data resource elements of the frame
  (:func:`interleaver`), so neighbouring symbols of an image see different subcarriers
  and OFDM symbols.

IQ is numpy ``[num_samples] complex64`` with full scale 1.0 (the radio side); received
symbols and noise variances are torch tensors (the codec side). The receiver is
:mod:`phy.receiver`.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
import torch

from phy.ofdm.resource_grid import ResourceGrid, map_to_grid

_SYNC_SEED, _COVER_SEED, _LTS_SEED, _INTERLEAVER_SEED = 0x5C, 0xC0, 0x17, 0x1EAF


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
        sample_rate_hz: sample rate (converts CFO to Hz), > 0.
        rms_amplitude: RMS of the transmitted IQ, full scale 1.0, in (0, 0.7]; peaks
            above 1.0 are clipped.
        sync_length: samples of the detection preamble (N = K * L), a multiple of
            ``sync_segment_length`` with K in [8, 512]. Coherent processing gain
            10 log10(N): 33 dB for the default 2048; the CFO-proof search statistic grows
            with K, so a shorter preamble finds fewer frames at low SNR.
        sync_segment_length: L, samples per coherently summed segment, dividing
            ``fft_size``, in [2, fft_size]. The CFO range is +-fft_size / (2 L) subcarriers
            (+-2 for 64 / 16: 125 kHz at 4 MS/s, 625 kHz at 20 MS/s); a CFO f loses
            ``sinc(f L)^2`` of the segment energy.
        detection_threshold: t, the normalised coherent preamble metric
            ``Q = |<r, q_f>|^2 / (|q_f|^2 |r|^2)`` over the N-sample window that declares a
            frame, in (0, 1). In noise alone Q ~ Beta(1, N - 1) per lag and CFO hypothesis:
            ``Pfa = (1 - t)^(N - 1)``; the default 0.015 with N = 2048 gives 4e-14 per
            hypothesis, each candidate sample being checked on 2 x 17 lags x 4K hypotheses.
            A clean preamble at per-sample SNR rho gives Q ~ rho / (1 + rho) less the CFO
            and multipath losses; Pd from the noncentral F (:func:`phy.detection.pd_coherent`).
        max_cfo_subcarriers: largest |CFO| accepted, subcarriers, in (0, fft_size / (2 L)].
        timing_backoff: samples the FFT window starts inside the prefix, in [0, cp_length);
            ``None`` = ``cp_length // 4``. The receiver tolerates a delay spread up to
            ``cp_length - timing_backoff`` samples.
        interleave: spread the payload over every data resource element of the frame.
        carrier_freq_hz: None, or the carrier frequency when both radios derive their
            local oscillator and sample clock from one crystal (HackRF): the receiver then
            takes the sampling-clock offset from the CFO (``-cfo_hz / carrier_freq_hz``)
            instead of estimating it from the pilots, which stays exact at any SNR.
    """

    fft_size: int = 64
    cp_length: int = 16
    num_guard_carriers: tuple[int, int] = (6, 5)
    dc_null: bool = True
    pilot_subcarrier_spacing: int = 4
    sample_rate_hz: float = 4e6
    rms_amplitude: float = 0.25
    sync_length: int = 2048
    sync_segment_length: int = 16
    detection_threshold: float = 0.015
    max_cfo_subcarriers: float = 2.0
    timing_backoff: int | None = None
    interleave: bool = True
    carrier_freq_hz: float | None = None

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
                "pilot_subcarrier_spacing must be an integer in [2, 16], got "
                f"{self.pilot_subcarrier_spacing!r}"
            )
        if not math.isfinite(self.sample_rate_hz) or self.sample_rate_hz <= 0:
            raise ValueError(f"sample_rate_hz must be > 0, got {self.sample_rate_hz!r}")
        if not 0 < self.rms_amplitude <= 0.7:
            raise ValueError(f"rms_amplitude must be in (0, 0.7], got {self.rms_amplitude!r}")
        seg = self.sync_segment_length
        if not isinstance(seg, int) or not 2 <= seg <= self.fft_size or self.fft_size % seg:
            raise ValueError(
                f"sync_segment_length must be an integer in [2, {self.fft_size}] dividing "
                f"fft_size, got {seg!r}"
            )
        if (
            not isinstance(self.sync_length, int)
            or self.sync_length % seg
            or not 8 <= self.sync_length // seg <= 512
        ):
            raise ValueError(
                f"sync_length must be a multiple of sync_segment_length ({seg}) with 8..512 "
                f"segments, got {self.sync_length!r}"
            )
        if not 0 < self.detection_threshold < 1:
            raise ValueError(
                f"detection_threshold must be in (0, 1), got {self.detection_threshold!r}"
            )
        if not 0 < self.max_cfo_subcarriers <= self.fft_size / (2 * seg):
            raise ValueError(
                f"max_cfo_subcarriers must be in (0, {self.fft_size / (2 * seg):g}] (fft_size / (2 "
                f"sync_segment_length)), got {self.max_cfo_subcarriers!r}"
            )
        if self.timing_backoff is not None and (
            not isinstance(self.timing_backoff, int)
            or not 0 <= self.timing_backoff < self.cp_length
        ):
            raise ValueError(
                f"timing_backoff must be None or an integer in [0, {self.cp_length - 1}], got "
                f"{self.timing_backoff!r}"
            )
        if self.carrier_freq_hz is not None and not (
            math.isfinite(self.carrier_freq_hz) and self.carrier_freq_hz > 0
        ):
            raise ValueError(f"carrier_freq_hz must be None or > 0, got {self.carrier_freq_hz!r}")
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
    def num_sync_segments(self) -> int:
        return self.sync_length // self.sync_segment_length

    @property
    def preamble_length(self) -> int:
        """Sync plus the two long training symbols, samples."""
        return self.sync_length + 2 * self.symbol_length

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


@functools.cache
def sync_sequence(cfg: FrameConfig) -> tuple[np.ndarray, np.ndarray]:
    """The detection preamble's base sequence and cover code.

    The base sequence has unit-modulus random QPSK lines on the carriers ``j * fft_size / L``
    with |j| <= L / 4 that are used carriers (none on guards or DC), scaled to unit mean
    power.

    Returns:
        (base [L] complex128 with mean |base|^2 == 1, cover [K] float64 of +-1).
    """
    n, seg = cfg.fft_size, cfg.sync_segment_length
    used = set(cfg.data_grid(1).used_subcarriers.tolist())
    # lines in the inner half of the band: a preamble arriving half a sample off the
    # sampling grid keeps 74 % of its correlation energy (the full band: 53 %)
    lines = np.array(
        [
            j
            for j in range(seg)
            if ((j * (n // seg)) + n // 2) % n in used
            and abs((j + seg // 2) % seg - seg // 2) <= seg // 4
        ]
    )
    q = np.random.default_rng(_SYNC_SEED).integers(0, 4, size=lines.size)
    bins = np.zeros(seg, np.complex128)
    bins[lines] = np.exp(0.5j * np.pi * (q + 0.5))
    base = np.fft.ifft(bins) * seg / math.sqrt(lines.size)
    cover = 1.0 - 2.0 * np.random.default_rng(_COVER_SEED).integers(0, 2, cfg.num_sync_segments)
    return base, cover


@functools.cache
def long_training_symbol(cfg: FrameConfig) -> np.ndarray:
    """[fft_size] centred-order long training symbol: BPSK on every used carrier."""
    used = cfg.data_grid(1).used_subcarriers
    lts = np.zeros(cfg.fft_size, dtype=np.complex128)
    lts[used] = 1 - 2 * np.random.default_rng(_LTS_SEED).integers(0, 2, size=used.size)
    return lts


@functools.lru_cache(maxsize=64)
def interleaver(num_elements: int) -> np.ndarray:
    """The payload interleaver of a frame with ``num_elements`` data resource elements.

    Resource element ``j`` (row-major over OFDM symbols and carriers) carries payload symbol
    ``perm[j]``: a fixed pseudo-random permutation, so payload neighbours land on
    different subcarriers and OFDM symbols (frequency and time diversity per image).

    Returns:
        perm [num_elements] int64, a permutation of ``range(num_elements)``.
    """
    return np.random.default_rng(_INTERLEAVER_SEED).permutation(int(num_elements))


def _amplitude_scale(cfg: FrameConfig) -> float:
    used = cfg.data_grid(1).used_subcarriers.size
    return cfg.rms_amplitude / math.sqrt(used / cfg.fft_size)


def as_complex_1d(x, name: str) -> np.ndarray:
    if isinstance(x, torch.Tensor):
        x = x.detach().cpu().numpy()
    x = np.asarray(x)
    if x.ndim != 1 or not np.iscomplexobj(x):
        raise ValueError(
            f"{name} must be a 1-D complex64 array [num_samples], got shape {x.shape} dtype "
            f"{x.dtype}"
        )
    x = np.ascontiguousarray(x, dtype=np.complex64)
    if not np.isfinite(x.view(np.float32)).all():  # on the real view: fast
        raise ValueError(f"{name} must be finite")
    return x


def build_frame(symbols, cfg: FrameConfig = FrameConfig()) -> np.ndarray:
    """Payload symbols -> one frame of IQ samples.

    Args:
        symbols: [num_symbols] complex64 (torch or numpy), unit mean power.
        cfg: the frame configuration.
    Returns:
        [cfg.num_samples(num_symbols)] complex64 numpy, RMS ``cfg.rms_amplitude``,
        |x| <= 1 (clipped).
    """
    x = as_complex_1d(symbols, "symbols")
    if x.size < 1:
        raise ValueError("symbols must hold at least 1 symbol")
    grid = cfg.data_grid(x.size)
    payload = np.zeros(grid.num_data_symbols, np.complex64)
    payload[: x.size] = x
    if cfg.interleave:
        payload = payload[interleaver(grid.num_data_symbols)]
    data = map_to_grid(torch.from_numpy(payload)[None], grid)[0].numpy()
    lts = long_training_symbol(cfg)
    freq = np.concatenate([lts[None], lts[None], data], axis=0)  # [2 + num_ofdm_symbols, fft_size]
    body = np.fft.ifft(np.fft.ifftshift(freq, axes=-1), axis=-1, norm="ortho")
    ofdm = np.concatenate([body[:, -cfg.cp_length :], body], axis=-1).reshape(-1)
    base, cover = sync_sequence(cfg)
    sync = (cover[:, None] * base[None, :]).reshape(-1) * cfg.rms_amplitude
    t = np.concatenate([sync, ofdm * _amplitude_scale(cfg)])
    mag = np.abs(t)
    t = np.where(mag > 1.0, t / np.maximum(mag, 1e-30), t)
    return t.astype(np.complex64)

"""Over the air: blocks of channel symbols -> phy frames -> TX HackRF -> air -> RX HackRF -> back.

The frame (preamble, pilots, OFDM, synchronisation, equalisation) is ``phy``'s
(``phy.FrameConfig``, ``build_frame``, ``find_frames``, ``receive_frame``). This module
adds what the radio link needs around it:

* each frame starts with a header (12-bit frame number + 4-bit check, BPSK, the word
  repeated ``header_repeat`` times), so frames can be lost or found out of order without
  mixing up images, and a corrupted header drops its frame instead of misplacing it;
* PAPR control (``phy.clip_papr``) and one scale for all frames so the clip level is
  exactly full scale: a frame of unit-power symbols has mean power ``-max_papr_db`` dBFS
  and the int8 DAC never clips;
* the transmit burst (frames separated by silent gaps) is sent while the receiver
  captures, on two threads, with the driver's clean end-of-burst;
* per-frame reports (detected, SNR from the pilots, CFO) and SigMF files of the burst and
  the capture, with one annotation per frame.
"""

from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from hil.errors import HilError
from hil.pluto_emulator import DEFAULT_RX_GAIN_DB, DEFAULT_TX_GAIN_DB
from hil.sigmf_io import Annotation, write_sigmf

HEADER_BITS = 16
MAX_FRAMES = 4096  # 12-bit frame numbers (+ a 4-bit check)
ERASED_NOISE_VAR = 1e3  # noise variance reported for symbols of lost frames (an erasure)


@dataclass(frozen=True)
class OtaConfig:
    """Radio settings and framing of an over-the-air run.

    Attributes:
        sample_rate_hz: both radios, 2-20 MS/s.
        center_freq_hz: both radios, Hz.
        symbols_per_frame: data symbols per frame (after the header), >= 64.
        header_repeat: repetitions of each header bit, >= 1.
        max_papr_db: PAPR limit of each frame's waveform, dB; the burst's mean power is
            ``-max_papr_db`` dBFS so the clipped peak is full scale.
        gap_samples: silence before, between and after frames, samples.
        rx_margin_samples: extra samples captured after the burst.
        rx_lead_s: the transmitter starts this long after the receiver streams, s (the
            capture is longer by as many samples).
        detection_threshold: the receiver's normalised coherent preamble metric that counts
            as a frame, in (0, 1) (``phy.FrameConfig.detection_threshold``: in noise alone it
            is Beta(1, N - 1) distributed, so 0.015 with the 2048-sample preamble
            has a false-alarm probability of 4e-14 per lag and CFO hypothesis, while a
            preamble at -10 dB per sample reaches about 0.045 through the emulated boards);
            a detection where no frame of the burst starts is dropped.
        lna_gain_db, vga_gain_db, txvga_gain_db: HackRF gains (quantised by the driver).
        ad9361_rx_gain_db, ad9361_tx_gain_db: Pluto (AD9361) gains: manual RX gain, and TX
            gain (minus the attenuation, <= 0), dB.
        max_rx_overruns: receive overruns (lost samples) tolerated before the capture
            fails with :class:`hil.StreamError` (None: warn only).
    """

    sample_rate_hz: float = 4e6
    center_freq_hz: float = 2.45e9
    symbols_per_frame: int = 2048
    header_repeat: int = 8
    max_papr_db: float = 9.0
    gap_samples: int = 2000
    rx_margin_samples: int = 20000
    rx_lead_s: float = 0.02
    detection_threshold: float = 0.015
    lna_gain_db: float = 16
    vga_gain_db: float = 24
    txvga_gain_db: float = 30
    ad9361_rx_gain_db: float = DEFAULT_RX_GAIN_DB
    ad9361_tx_gain_db: float = DEFAULT_TX_GAIN_DB
    max_rx_overruns: int | None = None

    def __post_init__(self):
        from hil.protocol import FREQ_RANGE_HZ

        if not 2e6 <= self.sample_rate_hz <= 20e6:
            raise ValueError(f"sample_rate_hz must be in [2e6, 20e6], got {self.sample_rate_hz!r}")
        lo, hi = FREQ_RANGE_HZ
        if not lo <= self.center_freq_hz <= hi:
            raise ValueError(
                f"center_freq_hz must be in [{lo:g}, {hi:g}] Hz, got {self.center_freq_hz!r}"
            )
        if self.max_rx_overruns is not None and self.max_rx_overruns < 0:
            raise ValueError(f"max_rx_overruns must be >= 0 or None, got {self.max_rx_overruns!r}")
        if not isinstance(self.symbols_per_frame, int) or self.symbols_per_frame < 64:
            raise ValueError(
                f"symbols_per_frame must be an integer >= 64, got {self.symbols_per_frame!r}"
            )
        if not isinstance(self.header_repeat, int) or not 1 <= self.header_repeat <= 64:
            raise ValueError(
                f"header_repeat must be an integer in [1, 64], got {self.header_repeat!r}"
            )
        if not 3.0 <= self.max_papr_db <= 20.0:
            raise ValueError(f"max_papr_db must be in [3, 20] dB, got {self.max_papr_db!r}")
        if not 0 < self.detection_threshold < 1:
            raise ValueError(
                f"detection_threshold must be in (0, 1), got {self.detection_threshold!r}"
            )
        if not 0 <= self.rx_lead_s <= 1:
            raise ValueError(f"rx_lead_s must be in [0, 1] s, got {self.rx_lead_s!r}")
        if self.gap_samples < 0 or self.rx_margin_samples < 0:
            raise ValueError("gap_samples and rx_margin_samples must be >= 0")

    @property
    def tx_power_dbfs(self) -> float:
        """Mean power of the transmitted frames, dB re full scale."""
        return -self.max_papr_db

    @property
    def header_symbols(self) -> int:
        return HEADER_BITS * self.header_repeat


def _check_nibble(number: int) -> int:
    return (number ^ (number >> 4) ^ (number >> 8) ^ 0x5) & 0xF


def header_symbols(frame_number: int, repeat: int) -> np.ndarray:
    """The frame header: 12-bit frame number + 4-bit check, BPSK (+1 for a 0 bit), LSB first.

    The 16-bit word is sent ``repeat`` times in a row (not bit by bit), so the copies land on
    different subcarriers and OFDM symbols and fade independently.

    Returns:
        [16 * repeat] complex64.
    """
    if not 0 <= int(frame_number) < MAX_FRAMES:
        raise ValueError(f"frame_number must be in [0, {MAX_FRAMES - 1}], got {frame_number!r}")
    word = int(frame_number) | (_check_nibble(int(frame_number)) << 12)
    bits = (word >> np.arange(HEADER_BITS)) & 1
    return np.tile(1.0 - 2.0 * bits, repeat).astype(np.complex64)


def decode_header(x_hat: np.ndarray, repeat: int, noise_var=None) -> int | None:
    """Inverse of :func:`header_symbols`: soft-combines the copies (weighted by 1/noise_var);
    None when the check nibble does not match (a corrupted header)."""
    n = HEADER_BITS * repeat
    x = np.real(np.asarray(x_hat)[:n]).astype(np.float64)
    w = 1.0 if noise_var is None else 1.0 / np.maximum(np.asarray(noise_var, np.float64)[:n], 1e-6)
    soft = (x * w).reshape(repeat, HEADER_BITS).sum(axis=0)
    word = int(np.sum((soft < 0).astype(np.int64) << np.arange(HEADER_BITS)))
    number = word & (MAX_FRAMES - 1)
    return number if (word >> 12) == _check_nibble(number) else None


def _np(x) -> np.ndarray:
    if hasattr(x, "detach"):
        x = x.detach().cpu().numpy()
    return np.asarray(x)


class PhyFrames:
    """``phy``'s over-the-air frame (FrameConfig, build_frame, find_frames, receive_frame).

    The receiver equalises by zero-forcing: unbiased symbols with each symbol's effective
    noise variance, the codec's convention (``semcodec.model.lmmse_input``).

    Args:
        frame_config: a ``phy.FrameConfig``; None builds one from ``frame_kwargs``
            (e.g. ``sample_rate_hz``, ``detection_threshold``, ``carrier_freq_hz``).
    """

    def __init__(self, frame_config=None, **frame_kwargs):
        import phy

        missing = [
            n
            for n in ("FrameConfig", "build_frame", "find_frames", "receive_frame")
            if not hasattr(phy, n)
        ]
        if missing:
            raise HilError(
                f"phy's frame API is not in this checkout (missing phy.{', phy.'.join(missing)})"
            )
        self.phy = phy
        self.cfg = frame_config if frame_config is not None else phy.FrameConfig(**frame_kwargs)

    def build(self, symbols: np.ndarray) -> np.ndarray:
        import torch

        return _np(
            self.phy.build_frame(torch.as_tensor(symbols, dtype=torch.complex64), self.cfg)
        ).astype(np.complex64)

    def find(self, iq: np.ndarray) -> list[int]:
        import torch

        return [
            int(s)
            for s in self.phy.find_frames(torch.as_tensor(iq, dtype=torch.complex64), self.cfg)
        ]

    def receive(self, iq: np.ndarray, num_symbols: int):
        import torch

        return self.phy.receive_frame(
            torch.as_tensor(iq, dtype=torch.complex64), self.cfg, num_symbols, equalizer="zf"
        )


@dataclass
class FrameReport:
    """What the receiver made of one transmitted frame."""

    number: int
    block: int
    detected: bool = False
    start_index: int | None = None
    num_samples: int = 0
    snr_db: float | None = None
    cfo_hz: float | None = None
    crc_ok: bool | None = None


@dataclass
class BurstResult:
    """Received blocks and per-frame reports of one over-the-air burst.

    Attributes:
        blocks: per input block, ``(x_hat [num_symbols] complex64, noise_var [num_symbols]
            float32)``; symbols of lost frames are 0 with noise_var ``ERASED_NOISE_VAR``.
        frames: one :class:`FrameReport` per transmitted frame.
        burst: [num_samples] complex64 as transmitted (full scale 1.0).
        capture: [num_samples] complex64 as received.
    """

    blocks: list
    frames: list
    burst: np.ndarray
    capture: np.ndarray
    sigmf: list = field(default_factory=list)

    @property
    def frames_sent(self) -> int:
        return len(self.frames)

    @property
    def frames_lost(self) -> int:
        return sum(not f.detected for f in self.frames)

    def block_frames(self, block: int) -> list:
        return [f for f in self.frames if f.block == block]

    def snr_db_measured(self, block: int | None = None) -> float | None:
        """Mean SNR (linear mean, in dB) over the detected frames (of one block)."""
        frames = self.frames if block is None else self.block_frames(block)
        snrs = [f.snr_db for f in frames if f.detected and f.snr_db is not None]
        return float(10 * np.log10(np.mean(10 ** (np.array(snrs) / 10)))) if snrs else None


def build_burst(
    blocks: list, cfg: OtaConfig, frames
) -> tuple[np.ndarray, list[FrameReport], list[tuple]]:
    """Frame every block and lay the frames out with gaps, PAPR-clipped and scaled.

    Args:
        blocks: list of [num_symbols] complex64 arrays (unit mean power by convention).
    Returns:
        (burst [num_samples] complex64 with |I|, |Q| <= 1, reports, layout) where layout
        holds ``(block, offset, length)`` of each frame's data symbols.
    """
    import torch

    from phy import clip_papr

    reports, layout, parts = [], [], [np.zeros(cfg.gap_samples, np.complex64)]
    # one scale for every frame: a frame of unit-power symbols has mean power p_nominal and
    # is clipped at sqrt(PAPR * p_nominal), which becomes full scale (|x| = 1)
    # random (not periodic: a periodic probe is impulsive in time and gets clipped) QPSK
    quadrants = np.random.default_rng(0).integers(0, 4, cfg.header_symbols + cfg.symbols_per_frame)
    probe = np.exp(2j * np.pi * (quadrants + 0.5) / 4)
    p_nominal = float(np.mean(np.abs(frames.build(probe.astype(np.complex64))) ** 2))
    limit = math.sqrt(10 ** (cfg.max_papr_db / 10) * p_nominal)
    number = 0
    for b, block in enumerate(blocks):
        block = np.asarray(block, np.complex64).reshape(-1)
        for offset in range(0, max(len(block), 1), cfg.symbols_per_frame):
            if number >= MAX_FRAMES:
                raise ValueError(
                    f"blocks need more than {MAX_FRAMES} frames; send fewer or larger frames"
                )
            chunk = block[offset : offset + cfg.symbols_per_frame]
            data = np.zeros(cfg.symbols_per_frame, np.complex64)
            data[: len(chunk)] = chunk
            iq = frames.build(np.concatenate([header_symbols(number, cfg.header_repeat), data]))
            p_frame = float(np.mean(np.abs(iq) ** 2))
            papr_db = max(0.0, 10 * math.log10(limit**2 / p_frame))  # the same clip level for all
            iq = clip_papr(torch.as_tensor(iq)[None], papr_db)[0].numpy() / limit
            iq = (np.clip(iq.real, -1, 1) + 1j * np.clip(iq.imag, -1, 1)).astype(np.complex64)
            reports.append(FrameReport(number, b, num_samples=len(iq)))
            layout.append((b, offset, len(chunk)))
            parts += [iq, np.zeros(cfg.gap_samples, np.complex64)]
            number += 1
    return np.concatenate(parts), reports, layout


def _configure(dev, cfg: OtaConfig) -> None:
    if hasattr(dev, "apply_ota_config"):  # a front end with its own knobs (Pluto)
        dev.apply_ota_config(cfg)
        return
    dev.sample_rate_hz = cfg.sample_rate_hz
    dev.center_freq_hz = cfg.center_freq_hz
    dev.lna_gain_db = cfg.lna_gain_db
    dev.vga_gain_db = cfg.vga_gain_db
    dev.txvga_gain_db = cfg.txvga_gain_db


def transmit_and_capture(
    tx,
    rx,
    burst: np.ndarray,
    num_rx_samples: int,
    lead_s: float = 0.0,
    max_rx_overruns: int | None = None,
) -> np.ndarray:
    """Capture ``num_rx_samples`` on ``rx`` (own thread) while ``tx`` sends ``burst``.

    The transmitter starts ``lead_s`` after the receiver is streaming (on emulated boards
    the virtual clock makes this irrelevant: both start at virtual time 0).

    Returns:
        [num_rx_samples] complex64. Errors of either side are raised here, the receive
        error when both sides fail (a board that is gone); it carries the capture so far as
        ``error.capture`` (see :func:`save_partial_capture`).
    """
    out: dict = {}

    def receive():
        try:
            out["capture"] = rx.rx(num_rx_samples, max_shortfalls=max_rx_overruns)
        except BaseException as e:  # noqa: BLE001 - re-raised in the caller's thread
            out["error"] = e

    thread = threading.Thread(target=receive, name="ota-rx", daemon=True)
    thread.start()
    deadline = time.monotonic() + 5.0  # real radios: let the receiver stream before TX starts
    while not getattr(rx, "receiving", True) and thread.is_alive() and time.monotonic() < deadline:
        time.sleep(0.001)
    time.sleep(lead_s)
    try:
        tx.tx(burst)
    except BaseException as tx_error:
        # a board that dies fails both sides; the receive error carries what arrived
        thread.join(timeout=120)
        if isinstance(out.get("error"), HilError):
            raise out["error"] from tx_error
        raise
    thread.join(timeout=120)
    if "error" in out:
        raise out["error"]
    if "capture" not in out:
        raise HilError("receive did not finish within 120 s")
    return out["capture"][0]


def assign_frames(
    starts: np.ndarray, headers: list, positions: np.ndarray, repeat: int, tolerance: float
) -> list:
    """The frame number of each detected frame, from its header and its place in the burst.

    At -10 dB one header (128 BPSK symbols) does not decode reliably on its own, but the
    burst's layout is known: frame i starts ``positions[i]`` samples after the burst. Every
    (detection, frame) pair proposes a burst offset; the offset under which the detections'
    soft header correlations with their frames' headers sum highest wins, and each
    detection is the frame that starts there (within ``tolerance`` samples), else None.

    Args:
        starts: [num_detected] start of each detected frame in the capture.
        headers: per detection ``(x_hat [>= 16 * repeat] complex, noise_var [same])``.
        positions: [num_frames] ascending start of each frame in the burst.
    Returns:
        list of frame numbers (int) or None, one per detection.
    """
    starts = np.asarray(starts, np.float64)
    positions = np.asarray(positions, np.float64)
    if starts.size == 0 or positions.size == 0:
        return [None] * starts.size
    n = HEADER_BITS * repeat
    codes = np.stack([header_symbols(i, repeat).real for i in range(positions.size)])  # [F, n]
    score = np.zeros((starts.size, positions.size))
    for j, (x_hat, nv) in enumerate(headers):
        w = 1.0 / np.maximum(np.asarray(nv, np.float64)[:n], 1e-6)  # MRC of unbiased symbols
        soft = w * np.real(np.asarray(x_hat)[:n])
        score[j] = codes @ soft / np.sqrt(max(float(w.sum()), 1e-12) / 2)  # N(0, 1) if wrong

    def explain(offset):
        rel = starts - offset
        i = np.clip(np.searchsorted(positions, rel), 1, positions.size - 1)
        i = np.where(np.abs(positions[i - 1] - rel) <= np.abs(positions[i] - rel), i - 1, i)
        if positions.size == 1:
            i = np.zeros(starts.size, np.int64)
        ok = np.abs(positions[i] - rel) <= tolerance
        return i, ok, float(score[np.flatnonzero(ok), i[ok]].sum())

    offsets = (starts[:, None] - positions[None, :]).reshape(-1)
    best = max((explain(o) for o in offsets), key=lambda e: e[2])
    return [int(i) if ok else None for i, ok in zip(*best[:2])]


def receive_burst(
    capture: np.ndarray, reports: list, layout: list, block_sizes: list, cfg: OtaConfig, frames
):
    """Find, synchronise and equalise every frame of ``capture``; reassemble the blocks.

    Frame numbers come from the headers and the burst's layout together
    (:func:`assign_frames`). Fills ``reports`` (detected, start, SNR, CFO) in place.
    Returns:
        list of ``(x_hat [n] complex64, noise_var [n] float32)``, one per block.
    """
    x_hats = [np.zeros(n, np.complex64) for n in block_sizes]
    nvs = [np.full(n, ERASED_NOISE_VAR, np.float32) for n in block_sizes]
    n_frame_syms = cfg.header_symbols + cfg.symbols_per_frame
    frame_len = max(r.num_samples for r in reports) if reports else 0
    found = []
    for start in frames.find(capture):
        lo = max(0, start - cfg.gap_samples // 2)
        seg = capture[lo : start + frame_len + cfg.gap_samples // 2]
        res = frames.receive(seg, n_frame_syms)
        if not bool(getattr(res, "detected", True)):
            continue
        sym = _np(res.symbols).reshape(-1).astype(np.complex64)
        nv = np.broadcast_to(_np(res.noise_var).astype(np.float32).reshape(-1), sym.shape)
        found.append((lo + int(getattr(res, "start_index", start - lo)), sym, nv, res))
    sizes = np.array([r.num_samples + cfg.gap_samples for r in reports], np.float64)
    positions = cfg.gap_samples + np.concatenate([[0.0], np.cumsum(sizes)[:-1]])
    span = float(positions[-1]) if positions.size else 0.0
    numbers = assign_frames(
        np.array([f[0] for f in found]),
        [(f[1], f[2]) for f in found],
        positions,
        cfg.header_repeat,
        tolerance=8 + 1e-4 * span,  # sampling clocks up to 100 ppm apart
    )
    for (start, sym, nv, res), number in zip(found, numbers):
        if number is None or reports[number].detected:
            continue  # not where a frame of this burst starts, or a duplicate detection
        rep = reports[number]
        rep.detected = True
        rep.start_index = start
        snr = getattr(res, "snr_db_estimate", None)
        rep.snr_db = None if snr is None else float(_np(snr))
        cfo = getattr(res, "cfo_hz", None)
        rep.cfo_hz = None if cfo is None else float(_np(cfo))
        b, offset, length = layout[number]
        x_hats[b][offset : offset + length] = sym[cfg.header_symbols : cfg.header_symbols + length]
        nvs[b][offset : offset + length] = nv[cfg.header_symbols : cfg.header_symbols + length]
    return list(zip(x_hats, nvs))


def _default_frames(cfg: OtaConfig) -> PhyFrames:
    return PhyFrames(
        sample_rate_hz=cfg.sample_rate_hz,
        detection_threshold=cfg.detection_threshold,
        # a HackRF derives its LO and sample clock from one crystal: the receiver takes the
        # sampling-clock offset from the CFO, which stays exact at -10 dB
        carrier_freq_hz=cfg.center_freq_hz,
    )


def decode_capture(capture, block_sizes: list, cfg: OtaConfig | None = None, frames=None):
    """Decode a recorded capture again, offline (e.g. the RX SigMF file of a run): the same
    receiver as :func:`send_blocks`, given only the symbols per block that were sent (the
    burst's layout follows from them).

    Args:
        capture: [num_samples] complex64, full scale 1.0 (``hil.read_sigmf(path).samples``).
        block_sizes: symbols of each block sent, in order.
    Returns:
        :class:`BurstResult` (its ``burst`` is the layout's zero-payload rebuild).
    """
    cfg = cfg or OtaConfig()
    frames = frames or _default_frames(cfg)
    zeros = [np.zeros(int(n), np.complex64) for n in block_sizes]
    burst, reports, layout = build_burst(zeros, cfg, frames)
    capture = np.asarray(capture, np.complex64).reshape(-1)
    received = receive_burst(capture, reports, layout, list(block_sizes), cfg, frames)
    return BurstResult(received, reports, burst, capture)


def send_blocks(tx, rx, blocks: list, cfg: OtaConfig | None = None, frames=None) -> BurstResult:
    """Send symbol blocks from ``tx`` to ``rx`` (HackRFs, real, emulated or loopback).

    Args:
        tx, rx: open :class:`hil.HackRF` devices (configured here from ``cfg``).
        blocks: list of [num_symbols] complex64, unit mean power each (one per image).
        cfg: :class:`OtaConfig`.
        frames: the frame layer (default :class:`PhyFrames`).
    Returns:
        :class:`BurstResult`.
    """
    cfg = cfg or OtaConfig()
    frames = frames or _default_frames(cfg)
    for dev in (tx, rx) if rx is not tx else (tx,):
        _configure(dev, cfg)
    burst, reports, layout = build_burst(blocks, cfg, frames)
    # a front end that needs time to start transmitting (a Pluto's buffer set-up) captures longer
    late_s = float(getattr(tx, "tx_start_latency_s", 0.0))
    lead = int((cfg.rx_lead_s + late_s) * cfg.sample_rate_hz)
    capture = transmit_and_capture(
        tx,
        rx,
        burst,
        len(burst) + lead + cfg.rx_margin_samples,
        lead_s=cfg.rx_lead_s,
        max_rx_overruns=cfg.max_rx_overruns,
    )
    sizes = [len(np.asarray(b).reshape(-1)) for b in blocks]
    received = receive_burst(capture, reports, layout, sizes, cfg, frames)
    return BurstResult(received, reports, burst, capture)


def save_partial_capture(
    error: HilError, stem, cfg: OtaConfig, hw: str = "HackRF One"
) -> Path | None:
    """Write what the receiver got before ``error`` as ci8 SigMF at ``<stem>_rx_partial``.

    Sets ``error.sigmf_path``. Returns the ``.sigmf-meta`` path, or None when the error
    carries no samples (SigMF cannot hold an empty recording).
    """
    capture = getattr(error, "capture", None)
    if capture is None or np.asarray(capture).size == 0:
        return None
    stem = Path(stem)
    error.sigmf_path = write_sigmf(
        stem.with_name(stem.name + "_rx_partial"),
        np.asarray(capture).reshape(-1),
        sample_rate_hz=cfg.sample_rate_hz,
        center_freq_hz=cfg.center_freq_hz,
        hw=f"{hw} (RX)",
        description=f"capture so far, stopped by: {error}",
    )
    return error.sigmf_path


def save_sigmf(result: BurstResult, stem, cfg: OtaConfig, hw: str = "HackRF One") -> list[Path]:
    """Write the burst (TX) and the capture (RX, one annotation per detected frame) as ci8 SigMF."""
    stem = Path(stem)
    anns = [
        Annotation(
            f.start_index,
            f.num_samples,
            f"frame {f.number}",
            f.snr_db,
            f.crc_ok,
            {"block": f.block, "cfo_hz": f.cfo_hz},
        )
        for f in result.frames
        if f.detected and f.start_index is not None
    ]
    paths = [
        write_sigmf(
            stem.with_name(stem.name + "_tx"),
            result.burst,
            sample_rate_hz=cfg.sample_rate_hz,
            center_freq_hz=cfg.center_freq_hz,
            hw=f"{hw} (TX)",
            description="transmitted burst",
        ),
        write_sigmf(
            stem.with_name(stem.name + "_rx"),
            result.capture,
            sample_rate_hz=cfg.sample_rate_hz,
            center_freq_hz=cfg.center_freq_hz,
            annotations=anns,
            hw=f"{hw} (RX)",
            description="received capture; annotations: detected frames",
        ),
    ]
    result.sigmf = [str(p) for p in paths]
    return paths

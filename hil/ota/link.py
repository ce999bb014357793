"""Over the air: blocks of channel symbols -> phy frames -> TX HackRF -> air -> RX HackRF -> back.

The frame (preamble, pilots, OFDM, synchronisation, equalisation) is ``phy``'s
(``phy.FrameConfig``, ``build_frame``, ``find_frames``, ``receive_frame``). Around it,
what the radio link needs, one module each:

* :mod:`hil.ota.header`: each frame starts with a header (12-bit frame number + 4-bit
  check, BPSK, the word repeated ``header_repeat`` times), so frames can be lost or found
  out of order without mixing up images, and a corrupted header drops its frame instead
  of misplacing it;
* :mod:`hil.ota.burst`: PAPR control (``phy.clip_papr``) and one scale for all frames so
  the clip level is exactly full scale: a frame of unit-power symbols has mean power
  ``-max_papr_db`` dBFS and the int8 DAC never clips;
* :mod:`hil.ota.receiver`: per-frame reports (detected, SNR from the pilots, CFO) and
  the blocks reassembled;
* :mod:`hil.ota.capture`: SigMF files of the burst and the capture, with one annotation
  per frame.

This module sends the burst (frames separated by silent gaps) while the receiver
captures, on two threads, with the driver's clean end-of-burst.
"""

from __future__ import annotations

import threading
import time

import numpy as np

from hil.errors import HilError
from hil.ota.burst import BurstResult, PhyFrames, build_burst
from hil.ota.config import OtaConfig
from hil.ota.receiver import receive_burst
from hil.radio import Radio


def transmit_and_capture(
    tx: Radio,
    rx: Radio,
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
    while not rx.receiving and thread.is_alive() and time.monotonic() < deadline:
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


def _default_frames(cfg: OtaConfig) -> PhyFrames:
    return PhyFrames(
        sample_rate_hz=cfg.sample_rate_hz,
        detection_threshold=cfg.detection_threshold,
        # a HackRF derives its LO and sample clock from one crystal: the receiver takes the
        # sampling-clock offset from the CFO, which stays exact at -10 dB
        carrier_freq_hz=cfg.center_freq_hz,
    )


def burst_num_samples(block_sizes: list, cfg: OtaConfig | None = None, frames=None) -> int:
    """Samples of the burst that :func:`send_blocks` sends for blocks of ``block_sizes``
    symbols (frames and gaps; the receiver's lead and margin not counted)."""
    cfg = cfg or OtaConfig()
    frames = frames or _default_frames(cfg)
    num_frames = sum(max(1, -(-int(n) // cfg.symbols_per_frame)) for n in block_sizes)
    frame = len(frames.build(np.zeros(cfg.header_symbols + cfg.symbols_per_frame, np.complex64)))
    return cfg.gap_samples + num_frames * (frame + cfg.gap_samples)


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


def send_blocks(
    tx: Radio, rx: Radio, blocks: list, cfg: OtaConfig | None = None, frames=None
) -> BurstResult:
    """Send symbol blocks from ``tx`` to ``rx`` (HackRFs, real, emulated or loopback).

    Args:
        tx, rx: open front ends (:class:`hil.Radio`: HackRFs, real, emulated or loopback, or
            one full-duplex Pluto as both), configured here from ``cfg``.
        blocks: list of [num_symbols] complex64, unit mean power each (one per image).
        cfg: :class:`OtaConfig`.
        frames: the frame layer (default :class:`PhyFrames`).
    Returns:
        :class:`BurstResult`.
    """
    cfg = cfg or OtaConfig()
    frames = frames or _default_frames(cfg)
    for dev in (tx, rx) if rx is not tx else (tx,):
        dev.apply_ota_config(cfg)  # each front end's own knobs
    burst, reports, layout = build_burst(blocks, cfg, frames)
    # a front end that needs time to start transmitting (a Pluto's buffer set-up) captures longer
    lead = int((cfg.rx_lead_s + tx.tx_start_latency_s) * cfg.sample_rate_hz)
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

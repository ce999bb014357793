"""A streaming over-the-air link: the transmitter sends views one after another, as a
flying drone would, while the receiver streams without pause and decodes as frames arrive.

Three threads: the transmitter (one burst per view, a view every ``interval_s``), the
receiver's producer (the driver's blocks into a :class:`hil.ota.stream.RingBuffer`) and the
decoder (:class:`hil.ota.stream.StreamReceiver`, on the calling thread). What the run did
is in a :class:`StreamRun`: the samples received, dropped and overrun, counted by the
driver (the host's queue), the board (its M0 overruns; an emulated board's own count of
the samples lost) and the ring, and the frames found, decoded and lost.
"""

from __future__ import annotations

import gc
import threading
import time
import warnings
from dataclasses import dataclass, field

import numpy as np

from hil.errors import HilError
from hil.ota.config import OtaConfig
from hil.ota.link import _default_frames
from hil.ota.stream import (
    RingBuffer,
    StreamCounts,
    StreamReceiver,
    StreamView,
    stream_block_samples,
)
from hil.radio import Radio, StreamingRadio


@dataclass
class StreamRun:
    """What one streaming run did; every count is exact.

    Attributes:
        samples_received: samples the driver handed to the ring.
        driver_samples: samples the driver delivered by its own count (the same, unless
            the producer failed between the two).
        ring_dropped_samples, ring_drop_events: samples (blocks) the ring had no room for.
        driver_dropped_samples: samples the driver's reader thread dropped (its queue full).
        device_overruns: overruns the board's M0 counted (-1: the firmware cannot tell).
        device_longest_overrun_bytes: the longest of them.
        emulator_overrun_samples: samples an emulated receiver lost to overruns (None: a
            real board, which does not say).
        emulator_underrun_samples: silence an emulated transmitter sent when the host wrote
            late (None: a real board).
        emulator_overruns, emulator_lost_buffers: an emulated Pluto's overruns and the
            receive buffers (DMA blocks) it lost to them (None: a real board, or a HackRF,
            whose overruns are ``device_overruns``).
        emulator_late_max_s: the most an emulated HackRF delivered a transfer later than a
            real board would have (its own delay rendering the air, not charged to the
            host; None: a real board or a Pluto).
        counts: frames found, decoded, ... (:class:`hil.ota.stream.StreamCounts`).
        warnings: the driver's warnings, one line each.
    """

    samples_received: int = 0
    driver_samples: int = 0
    ring_dropped_samples: int = 0
    ring_drop_events: int = 0
    driver_dropped_samples: int = 0
    device_overruns: int = -1
    device_longest_overrun_bytes: int = 0
    emulator_overrun_samples: int | None = None
    emulator_underrun_samples: int | None = None
    emulator_overruns: int | None = None
    emulator_lost_buffers: int | None = None
    emulator_late_max_s: float | None = None
    counts: StreamCounts = field(default_factory=StreamCounts)
    warnings: list = field(default_factory=list)

    @property
    def dropped_samples(self) -> int:
        """Samples lost anywhere between the air and the decoder."""
        return (
            self.ring_dropped_samples
            + self.driver_dropped_samples
            + (self.emulator_overrun_samples or 0)
        )

    @property
    def overruns(self) -> int:
        """Events in which samples were lost: the ring's drops, the driver's, the board's
        (an emulated Pluto's own count where libiio reports none)."""
        board = max(self.device_overruns, 0) + (self.emulator_overruns or 0)
        return self.ring_drop_events + (self.driver_dropped_samples > 0) + board

    def as_dict(self) -> dict:
        out = {k: v for k, v in vars(self).items() if k != "counts"}
        out.update(vars(self.counts), dropped_samples=self.dropped_samples, overruns=self.overruns)
        return out


def _produce(
    rx: StreamingRadio, ring: RingBuffer, block_samples: int, stop: threading.Event, out: dict
) -> None:
    """The receiver's producer thread: the driver's blocks into the ring until ``stop``
    (a HackRF's blocks are ``block_samples`` long; a Pluto's are its receive buffers, at
    least ``rx.rx_transfer_samples``: a late reader has four of them to catch up in)."""
    blocks = rx.stream(block_samples)
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            try:
                for block in blocks:
                    ring.push(np.asarray(block).reshape(-1))
                    if stop.is_set():
                        break
            finally:
                blocks.close()  # the driver stops the stream and reads the M0 counters
        out["warnings"] = [str(w.message) for w in caught]
    except BaseException as e:  # noqa: BLE001 - re-raised on the decoder's thread
        out["error"] = e
    finally:
        ring.close()


def _transmit(
    tx: Radio, views: list, interval_s: float, start: float, out: dict, stop: threading.Event
) -> None:
    """The transmitter's thread: view ``v`` at ``start + v * interval_s`` (or as soon as
    the previous one is out); no view goes out once ``stop`` is set."""
    try:
        for view in views:
            wait = start + view.index * interval_s - time.monotonic()
            if stop.wait(wait) if wait > 0 else stop.is_set():
                return
            view.sent_at = time.monotonic()
            tx.tx(view.burst)
    except BaseException as e:  # noqa: BLE001 - re-raised on the decoder's thread
        out["error"] = e


def stream_over_the_air(
    tx: Radio,
    rx: StreamingRadio,
    views: list[StreamView],
    cfg: OtaConfig,
    on_view,
    *,
    interval_s: float,
    ring_s: float,
    emulator=None,
    frames=None,
) -> StreamRun:
    """Send ``views`` from ``tx`` while ``rx`` streams; decode on this thread.

    Args:
        tx, rx: open front ends (HackRFs, real or emulated, or one Pluto as both;
            configured here from ``cfg``).
        views: :func:`hil.ota.stream.build_views` of the blocks to send.
        on_view: called on this thread with each view as the receiver hands it on.
        interval_s: a view every this many seconds (0: back to back).
        ring_s: the ring buffer holds this much air time.
        emulator: the ``hil.Emulator`` of emulated boards, for their own loss counts.
    Returns:
        :class:`StreamRun`. A stream that stops early (a radio's ``hil.HilError``, Ctrl-C)
        raises that exception once both threads ended, within :data:`STOP_S` of the stop,
        with what it got so far attached: ``stream_run`` (a :class:`StreamRun` of the
        frames and samples until then) and ``capture`` (the ring's last samples).
    Raises:
        ValueError: ``ring_s`` holds less than one frame with its search window
            (:meth:`StreamReceiver.ring_samples_needed`), before any radio is touched.
    """
    frames = frames or _default_frames(cfg)
    fs = cfg.sample_rate_hz
    block = stream_block_samples(cfg)
    _check_ring(ring_s, views, cfg, block)
    for dev in (tx, rx) if rx is not tx else (tx,):
        dev.apply_ota_config(cfg)  # each front end's own knobs
    ring = RingBuffer(max(int(ring_s * fs), 1))
    receiver = StreamReceiver(ring, views, cfg, frames, on_view, block_samples=block)
    receiver.warm_up()  # the first frame costs no more than the others
    # the collector's full passes over everything imported hold the interpreter for tens
    # of ms, longer than a board's buffer lasts; what the stream allocates stays collected
    gc.collect()
    gc.freeze()
    stop = threading.Event()
    rx_out: dict = {}
    tx_out: dict = {}
    producer = _start_producer(rx, ring, block, stop, rx_out)
    sender = threading.Thread(
        target=_transmit,
        args=(tx, views, interval_s, time.monotonic() + cfg.rx_lead_s, tx_out, stop),
        name="ota-stream-tx",
        daemon=True,
    )
    sender.start()
    stopper = threading.Thread(
        target=_stop_after_last_view,
        args=(sender, views, cfg, rx, block, receiver, stop),
        name="ota-stream-stop",
        daemon=True,
    )
    stopper.start()
    stopped: BaseException | None = None
    try:
        receiver.run()
    except BaseException as e:  # noqa: BLE001 - Ctrl-C or the decoder: raised again below
        stopped = e
    finally:
        stop.set()  # the transmitter sends nothing more; the producer ends its stream
        for thread in (sender, producer, stopper):
            thread.join(timeout=STOP_S / 3)
        gc.unfreeze()
    stopped = stopped or rx_out.get("error") or tx_out.get("error")
    if stopped is None:
        return _run_record(rx, ring, receiver.counts, emulator, rx_out.get("warnings", []))
    raise _with_what_it_got(stopped, rx, ring, receiver.counts, emulator, rx_out)


def _check_ring(ring_s: float, views: list[StreamView], cfg: OtaConfig, block: int) -> None:
    """ValueError unless ``ring_s`` holds one frame with its search window."""
    fs = cfg.sample_rate_hz
    need = StreamReceiver.ring_samples_needed(views, cfg, block)
    if int(ring_s * fs) < need:
        raise ValueError(
            f"ring_s {ring_s:g} s holds {int(ring_s * fs)} samples, less than one frame with "
            f"its search window ({need} samples, {need / fs:.4g} s)"
        )


def _start_producer(
    rx: StreamingRadio, ring: RingBuffer, block: int, stop: threading.Event, out: dict
):
    """The receiver's thread, started; returns once ``rx`` streams (or the thread ended, or
    after 5 s), before the first view goes out."""
    producer = threading.Thread(
        target=_produce, args=(rx, ring, block, stop, out), name="ota-stream-rx", daemon=True
    )
    producer.start()
    deadline = time.monotonic() + 5.0  # the receiver streams before the first view goes out
    while not rx.receiving and producer.is_alive() and time.monotonic() < deadline:
        time.sleep(0.001)
    return producer


def _stop_after_last_view(
    sender, views, cfg: OtaConfig, rx: StreamingRadio, block: int, receiver, stop
) -> None:
    """The stopper's thread: once the last view is sent, wait for it (and what the board and
    the driver still hold) to reach the ring, then stop the stream."""
    sender.join()
    # the last frame, then what the board and the driver still hold, reach the ring
    tail = max(r.num_samples for r in views[-1].reports) + cfg.rx_margin_samples
    transfer = max(int(block), rx.rx_transfer_samples)  # what the driver may still hold
    deadline = time.monotonic() + (tail + transfer + 4 * block) / cfg.sample_rate_hz + 0.05
    while time.monotonic() < deadline and receiver.next_view < len(views):
        if stop.wait(0.005):  # ends early once the last view is decoded, or on a stop
            return
    stop.set()


def _with_what_it_got(
    stopped: BaseException, rx: StreamingRadio, ring: RingBuffer, counts, emulator, rx_out
):
    """``stopped`` with ``stream_run`` (what the stream got until then) and ``capture`` (the
    ring's last samples) attached."""
    try:
        run = _run_record(rx, ring, counts, emulator, rx_out.get("warnings", []))
    except Exception:  # noqa: BLE001 - a board gone: what the receiver counted
        run = StreamRun(samples_received=ring.received_samples, counts=counts)
    stopped.stream_run = run  # type: ignore[attr-defined]
    if getattr(stopped, "capture", None) is None:
        stopped.capture = ring.held()  # type: ignore[attr-defined]
    return stopped


STOP_S = 1.0
"""A stream that is stopped early (Ctrl-C, a board gone) ends its threads within this."""


def _run_record(
    rx: StreamingRadio, ring: RingBuffer, counts: StreamCounts, emulator, caught: list
) -> StreamRun:
    stats = rx.last_stats
    if stats is None:
        raise HilError("the receive stream ended without the driver's counters")
    run = StreamRun(
        samples_received=ring.received_samples,
        driver_samples=stats.num_samples,
        ring_dropped_samples=ring.dropped_samples,
        ring_drop_events=ring.drop_events,
        driver_dropped_samples=stats.host_dropped_bytes // 2,
        device_overruns=stats.device_shortfalls,
        device_longest_overrun_bytes=stats.longest_shortfall_bytes,
        counts=counts,
        warnings=list(caught),
    )
    if emulator is not None:
        run.emulator_overrun_samples = int(emulator.radios[1].overrun_samples)
        run.emulator_underrun_samples = int(emulator.radios[0].underrun_samples)
        run.emulator_late_max_s = float(emulator.radios[1].rx_late_max_s)
    loss = rx.emulated_rx_loss  # an emulated Pluto's late-reader losses
    if loss is not None:
        run.emulator_overruns, run.emulator_lost_buffers, run.emulator_overrun_samples = loss
    return run

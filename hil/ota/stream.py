"""A receiver that keeps up with a radio that never stops: the driver's blocks go into a
:class:`RingBuffer`, and :class:`StreamReceiver` searches the buffer for frames as blocks
arrive, decodes each frame once, and hands every view (one burst of frames, e.g. one image a
drone sends) on as soon as it is complete.

Frame search in blocks with carry-over: each search covers the new samples plus the last
``frame_len + gap / 2`` samples of the previous one, and owns the starts in
``[own_from, own_to)``; the owned intervals tile the stream and a frame is only decoded
when all of its samples are in the window, so a frame across a block boundary is found
exactly once. Frames are numbered on across the stream (``hil.ota.burst.build_burst``'s
``first_number``); a frame's view follows from its header.

Every sample is accounted for: the ring counts the samples it received and the ones it had
to drop (the decoder fell more than the ring behind: the newest block is dropped whole and
the search restarts after it), exactly; frames found, decoded and lost are counted per view.
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass, field

import numpy as np

from common import one_blas_thread
from hil.ota.burst import BurstResult, FrameReport, as_numpy, build_burst
from hil.ota.config import OtaConfig
from hil.ota.header import MAX_FRAMES, decode_header
from hil.ota.link import _default_frames
from hil.ota.receiver import ERASED_NOISE_VAR


class RingBuffer:
    """A bounded buffer of complex64 samples between a producer (the driver) and a
    consumer (the frame search), on absolute sample positions (thread-safe).

    A block that does not fit behind what the consumer still holds (positions map to
    slots modulo ``capacity``, so dropped samples take room too until the consumer passes
    them) is dropped whole and counted (``dropped_samples``, ``drop_events``); its interval is kept
    in ``gaps`` so the consumer never joins samples across it.

    Args:
        capacity: samples held at most.
    """

    def __init__(self, capacity: int):
        if capacity <= 0:
            raise ValueError(f"capacity must be > 0 samples, got {capacity!r}")
        self.capacity = int(capacity)
        self._buf = np.zeros(self.capacity, np.complex64)
        self.cond = threading.Condition()
        self.write_pos = 0  # samples the producer pushed, dropped ones included
        self.read_pos = 0  # the consumer no longer needs samples before this
        self.received_samples = 0
        self.dropped_samples = 0
        self.drop_events = 0
        self.gaps: list[tuple[int, int]] = []
        self.closed = False

    def push(self, x: np.ndarray) -> bool:
        """Append ``x`` [num_samples] complex64; False when it was dropped (no room)."""
        x = np.asarray(x, np.complex64).reshape(-1)
        n = len(x)
        with self.cond:
            if self.write_pos + n - self.read_pos > self.capacity:
                self.drop(n)
                return False
            self.received_samples += n
            i = self.write_pos % self.capacity
            first = min(n, self.capacity - i)
            self._buf[i : i + first] = x[:first]
            self._buf[: n - first] = x[first:]
            self.write_pos += n
            self.cond.notify_all()
            return True

    def drop(self, num_samples: int) -> None:
        """Count ``num_samples`` that arrived with no room for them: one drop event, a gap
        in the stream."""
        with self.cond:
            n = int(num_samples)
            self.received_samples += n
            self.dropped_samples += n
            self.drop_events += 1
            if self.gaps and self.gaps[-1][1] == self.write_pos:
                self.gaps[-1] = (self.gaps[-1][0], self.write_pos + n)
            else:
                self.gaps.append((self.write_pos, self.write_pos + n))
            self.write_pos += n
            self.cond.notify_all()

    def close(self) -> None:
        """The producer ended: no more samples."""
        with self.cond:
            self.closed = True
            self.cond.notify_all()

    def wait(self, position: int, timeout_s: float = 0.1) -> int:
        """Wait until ``position`` samples were pushed or the ring is closed (at most
        ``timeout_s``); returns the samples pushed so far."""
        with self.cond:
            self.cond.wait_for(lambda: self.write_pos >= position or self.closed, timeout_s)
            return self.write_pos

    def next_gap(self, position: int) -> tuple[int, int] | None:
        """The first dropped interval that ends after ``position``, or None."""
        with self.cond:
            return next((g for g in self.gaps if g[1] > position), None)

    def read(self, lo: int, hi: int) -> np.ndarray:
        """A copy of samples ``lo .. hi - 1`` [hi - lo] complex64 (held, none dropped)."""
        with self.cond:
            if lo < self.read_pos or hi > self.write_pos or hi - lo > self.capacity:
                raise ValueError(f"samples [{lo}, {hi}) are not held ({self.read_pos}..)")
            i, n = lo % self.capacity, hi - lo
            if i + n <= self.capacity:
                return self._buf[i : i + n].copy()
            return np.concatenate([self._buf[i:], self._buf[: i + n - self.capacity]])

    def held(self) -> np.ndarray:
        """The last samples the ring holds, up to ``capacity`` ([num_samples] complex64,
        dropped ones as zeros): what a stream that stopped early keeps as its capture."""
        with self.cond:
            lo = max(0, self.write_pos - self.capacity)
            i, n = lo % self.capacity, self.write_pos - lo
            first = min(n, self.capacity - i)  # two slices of the ring, no index arrays
            out = np.concatenate([self._buf[i : i + first], self._buf[: n - first]])
            for g0, g1 in self.gaps:
                if g1 > lo:
                    out[max(g0, lo) - lo : g1 - lo] = 0
            return out

    def release(self, position: int) -> None:
        """The consumer needs no sample before ``position`` any more."""
        with self.cond:
            self.read_pos = max(self.read_pos, min(int(position), self.write_pos))


@dataclass
class StreamView:
    """One view of the stream: its frames (numbered on from ``first_number``) and what
    arrived of them.

    Attributes:
        index: the view's place in the stream.
        first_number: the stream-wide number of its first frame.
        reports: one ``hil.ota.FrameReport`` per frame (``number`` is the frame within the view).
        layout: per frame ``(block, offset, length)`` of its data symbols.
        block_size: symbols of the view's block.
        burst: [num_samples] complex64 as sent.
        sent_at: when the transmitter started sending it (``time.monotonic``), None before.
        done_at: when the receiver handed it on (``time.monotonic``), None before.
    """

    index: int
    first_number: int
    reports: list
    layout: list
    block_size: int
    burst: np.ndarray
    sent_at: float | None = None
    done_at: float | None = None
    x_hat: np.ndarray = field(init=False)
    noise_var: np.ndarray = field(init=False)

    def __post_init__(self):
        self.x_hat = np.zeros(self.block_size, np.complex64)
        self.noise_var = np.full(self.block_size, ERASED_NOISE_VAR, np.float32)

    @property
    def complete(self) -> bool:
        return all(r.detected for r in self.reports)

    def result(self) -> BurstResult:
        """What arrived, as a ``hil.ota.BurstResult`` of one block (no capture kept)."""
        return BurstResult(
            [(self.x_hat, self.noise_var)], self.reports, self.burst, np.zeros(0, np.complex64)
        )


def build_views(blocks: list, cfg: OtaConfig, frames=None) -> list[StreamView]:
    """One :class:`StreamView` per block, its frames numbered on from the previous view's
    (``hil.ota.burst.build_burst``), each a burst of its own.

    Args:
        blocks: one [num_symbols] complex64 array per view, unit mean power each.
        frames: the frame layer (default ``phy``'s, as :func:`hil.send_blocks`).
    """
    frames = frames or _default_frames(cfg)

    views, number = [], 0
    for v, block in enumerate(blocks):
        burst, reports, layout = build_burst([block], cfg, frames, first_number=number)
        size = len(np.asarray(block).reshape(-1))
        views.append(StreamView(v, number, reports, layout, size, burst))
        number += len(reports)
    return views


@dataclass
class StreamCounts:
    """Frames of one stream, counted exactly.

    Attributes:
        frames_found: preamble detections, each counted once.
        frames_decoded: found frames whose header named a frame of the stream, placed.
        header_errors: found frames whose header failed its check.
        not_received: found frames the receiver could not synchronise.
        duplicates: detections of a frame already decoded.
        receiver_cpu_s: CPU seconds of the decoder's thread in the frame layer (searching
            the ring and receiving frames; not the scheme's decoding of the views).
        samples_searched: samples the searches covered (each once).
    """

    frames_found: int = 0
    frames_decoded: int = 0
    header_errors: int = 0
    not_received: int = 0
    duplicates: int = 0
    receiver_cpu_s: float = 0.0
    samples_searched: int = 0


BLOCK_SECONDS = 0.01  # driver blocks of about this much air time go into the ring


def stream_block_samples(cfg: OtaConfig) -> int:
    """Samples of one driver block a stream pushes into its ring (:data:`BLOCK_SECONDS`)."""
    return max(int(BLOCK_SECONDS * cfg.sample_rate_hz), 512)


class StreamReceiver:
    """Frame search and decoding on a :class:`RingBuffer`, one view handed on at a time.

    Args:
        ring: the samples, as the driver delivers them.
        views: the stream's views (:func:`build_views`), in sending order.
        cfg: ``hil.OtaConfig``.
        frames: the frame layer (``hil.ota.PhyFrames``): ``find(iq)`` and ``receive_all(iq, n)``.
        on_view: called with each :class:`StreamView` once it is complete, or once a
            frame of a later view (or the end of the stream) shows it never will be.
        block_samples: new samples per search (at least one frame's worth is sensible).
    """

    def __init__(self, ring, views: list, cfg: OtaConfig, frames, on_view, block_samples: int):
        self.ring, self.views, self.cfg, self.frames = ring, views, cfg, frames
        self.on_view = on_view
        self.frame_len = max((r.num_samples for v in views for r in v.reports), default=0)
        self.pre = cfg.gap_samples // 2
        self.need = self.frame_len + self.pre  # samples from a frame's start to decode it
        self.block_samples = max(int(block_samples), 1)
        self.owner = {}  # stream-wide frame number -> (view, frame within the view)
        for view in views:
            for i in range(len(view.reports)):
                self.owner[view.first_number + i] = (view, i)
        self.counts = StreamCounts()
        # stream-wide number of the last frame decoded (before any: the one before the first)
        self.last_number = views[0].first_number - 1 if views else -1
        self.next_view = 0  # views before this one were handed on
        self._view_cpu_s = 0.0  # CPU of on_view within the current search

    @staticmethod
    def ring_samples_needed(views: list, cfg: OtaConfig, block_samples: int | None = None) -> int:
        """The smallest ring that can hold a frame with the samples searched around it: the
        longest frame, the lead-in before it on both sides, one block of new samples
        (``block_samples``; None: a stream's, :func:`stream_block_samples`)."""
        frame_len = max((r.num_samples for v in views for r in v.reports), default=0)
        block = stream_block_samples(cfg) if block_samples is None else int(block_samples)
        return frame_len + 2 * (cfg.gap_samples // 2) + max(block, 1)

    def warm_up(self) -> None:
        """Search and receive the first view's burst as sent, once, counting nothing: the
        frame layer's one-off set-up is done before the stream starts."""
        if self.views:
            burst = np.concatenate([self.views[0].burst, np.zeros(self.pre, np.complex64)])
            self.frames.find(burst)
            self.frames.receive_all(burst, self.cfg.header_symbols + self.cfg.symbols_per_frame)

    @one_blas_thread
    def run(self) -> StreamCounts:
        """Search and decode until the ring is closed and every sample was searched (numpy's
        BLAS pool at one thread meanwhile)."""
        own_from = seg_lo = 0
        while True:
            target = own_from + self.need + self.block_samples
            avail = self.ring.wait(target)
            gap = self.ring.next_gap(own_from)
            hi = avail if gap is None else min(avail, gap[0])
            at_gap = gap is not None and hi == gap[0]
            ended = self.ring.closed and gap is None and hi >= self.ring.write_pos
            if not (at_gap or ended) and hi < target:
                continue
            own_to = hi if (at_gap or ended) else hi - self.need
            if own_to > own_from:
                cpu, self._view_cpu_s = time.thread_time(), 0.0
                self._search(max(seg_lo, own_from - self.pre), own_from, own_to, hi)
                self.counts.receiver_cpu_s += time.thread_time() - cpu - self._view_cpu_s
                self.counts.samples_searched += own_to - own_from
            own_from = own_to
            if at_gap and gap is not None:  # nothing joins across dropped samples
                own_from = seg_lo = gap[1]
            self.ring.release(max(seg_lo, own_from - self.pre))
            if ended:
                break
        self._hand_on(len(self.views))
        return self.counts

    def _search(self, lo: int, own_from: int, own_to: int, hi: int) -> None:
        """Find and decode the frames that start in ``[own_from, own_to)`` in samples
        ``lo .. hi-1``: every complete frame from one search (``receive_all``); the frames
        cut off by dropped samples or the end (only when ``own_to`` comes that near ``hi``)
        are counted from ``find`` on the block's last frame length."""
        iq = self.ring.read(lo, hi)
        for res in self.frames.receive_all(
            iq, self.cfg.header_symbols + self.cfg.symbols_per_frame
        ):
            start = lo + int(res.start_index)
            if own_from <= start < own_to and start + self.frame_len <= hi:
                self.counts.frames_found += 1
                self._decode(res, start)
        if own_to + self.frame_len > hi:  # the tail where a frame can start and not fit
            tail = max(own_from - self.pre, hi - self.frame_len - self.need) - lo
            for k in self.frames.find(iq[max(0, tail) :]):
                start = lo + max(0, tail) + int(k)
                if own_from <= start < own_to and start + self.frame_len > hi:
                    self.counts.frames_found += 1
                    self.counts.not_received += 1

    def _decode(self, res, start: int) -> None:
        """Place the frame received at ``start`` (``res``, a ``phy.FrameResult``) by its header."""
        cfg = self.cfg
        if not bool(getattr(res, "detected", True)):
            self.counts.not_received += 1
            return
        sym = as_numpy(res.symbols).reshape(-1).astype(np.complex64)
        nv = np.broadcast_to(as_numpy(res.noise_var).astype(np.float32).reshape(-1), sym.shape)
        header = decode_header(sym, cfg.header_repeat, nv)
        if header is None:
            self.counts.header_errors += 1
            return
        # the stream-wide number nearest the last one decoded with this header's residue
        number = self.last_number + 1 + (header - self.last_number - 1) % MAX_FRAMES
        if number - self.last_number > MAX_FRAMES // 2:
            number -= MAX_FRAMES
        if number not in self.owner:
            self.counts.header_errors += 1
            return
        view, i = self.owner[number]
        rep: FrameReport = view.reports[i]
        if rep.detected:
            self.counts.duplicates += 1
            return
        if view.index < self.next_view:  # a view already handed on: a header gone wrong
            self.counts.header_errors += 1
            return
        self.counts.frames_decoded += 1
        self.last_number = max(self.last_number, number)
        rep.detected = True
        rep.start_index = start
        snr, cfo = getattr(res, "snr_db_estimate", None), getattr(res, "cfo_hz", None)
        rep.snr_db = None if snr is None else float(as_numpy(snr))
        rep.cfo_hz = None if cfo is None else float(as_numpy(cfo))
        _, offset, length = view.layout[i]
        h = cfg.header_symbols
        view.x_hat[offset : offset + length] = sym[h : h + length]
        view.noise_var[offset : offset + length] = nv[h : h + length]
        self._hand_on(view.index + (1 if view.complete else 0))

    def _hand_on(self, upto: int) -> None:
        """Hand on every view before ``upto`` not handed on yet, in order."""
        while self.next_view < min(upto, len(self.views)):
            view = self.views[self.next_view]
            self.next_view += 1
            view.done_at = time.monotonic()
            cpu = time.thread_time()
            self.on_view(view)
            self._view_cpu_s += time.thread_time() - cpu

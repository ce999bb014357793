"""A radio whose air is a GNU Radio flowgraph: :class:`ZmqRadio`, in gr-zeromq's stream format.

``osnerf ota --tx zmq:tcp://127.0.0.1:5555 --rx zmq:tcp://127.0.0.1:5556`` sends through
any flowgraph that pulls complex64 items from the first address (a ``zeromq.pull_source``,
which connects) and pushes what it makes of them to the second (a ``zeromq.push_sink``,
which binds), with tags off: each message is just the items, 8 bytes each. This is how
srsRAN connects its ZMQ radios to GNU Radio.

The radio's DAC and ADC share one clock, as a board's do: while a capture runs, the
transmitter pushes samples at the sample rate, silence unless a burst is queued (a burst
starts at the next chunk), and the capture takes whatever the flowgraph returns. Between
captures nothing is pushed; what the flowgraph still held is thrown away when the next
capture starts (:data:`STALE_S` of silence).
"""

from __future__ import annotations

import queue
import threading
import time
from dataclasses import dataclass

import numpy as np

from hil.errors import DeviceNotFoundError, HilError, TimedOutError
from hil.hackrf.stream import StreamStats
from hil.iq import full_scale_samples

ITEM = np.complex64  # gr_complex
CHUNK_SAMPLES = 8192
STALE_S = 0.05  # silence to drain at a capture's start: what the flowgraph still held


@dataclass(frozen=True)
class ZmqCounts:
    """What one capture saw: samples received, messages, and waits with nothing (timeouts)."""

    num_samples: int
    messages: int
    timeouts: int
    late_chunks: int  # the transmitter fell behind its clock (the host was too slow)


class ZmqRadio:
    """Both ends of a link through a GNU Radio flowgraph over ZeroMQ.

    Args:
        tx_endpoint: where the transmitter's PUSH socket binds (the flowgraph's
            ``zeromq.pull_source`` address), e.g. ``tcp://127.0.0.1:5555``; None: receive only.
        rx_endpoint: where the receiver's PULL socket connects (the flowgraph's
            ``zeromq.push_sink`` address); None: transmit only.
        sample_rate_hz: the clock of both (:meth:`apply_ota_config` sets it).
        timeout_s: how long a capture may receive nothing before it fails.
    """

    def __init__(
        self,
        tx_endpoint: str | None,
        rx_endpoint: str | None,
        *,
        sample_rate_hz: float = 4e6,
        timeout_s: float = 5.0,
    ):
        try:
            import zmq
        except ImportError as e:
            raise DeviceNotFoundError("the ZMQ radio needs pyzmq (pip install pyzmq)") from e
        self._zmq = zmq
        self.tx_endpoint, self.rx_endpoint = tx_endpoint, rx_endpoint
        self.sample_rate_hz = float(sample_rate_hz)
        self.center_freq_hz = 0.0  # the flowgraph's: nothing to tune here
        self.timeout_s = float(timeout_s)
        self.tx_start_latency_s = 0.25  # the pipe through the flowgraph, filled at the start
        self._ctx = zmq.Context()
        self._push = self._pull = None
        try:
            if tx_endpoint is not None:
                self._push = self._ctx.socket(zmq.PUSH)
                self._push.setsockopt(zmq.SNDHWM, 2)
                self._push.setsockopt(zmq.LINGER, 0)
                self._push.bind(tx_endpoint)
            if rx_endpoint is not None:
                self._pull = self._ctx.socket(zmq.PULL)
                self._pull.setsockopt(zmq.RCVHWM, 2)
                self._pull.setsockopt(zmq.LINGER, 0)
                self._pull.connect(rx_endpoint)
        except zmq.ZMQError as e:
            self.close()
            raise DeviceNotFoundError(f"ZMQ radio {tx_endpoint} / {rx_endpoint}: {e}") from e
        self._bursts: queue.Queue = queue.Queue()
        self._clock_on = threading.Event()
        self._clock: threading.Thread | None = None
        self._receiving = False
        self._closed = False
        self.late_chunks = 0
        self.last_counts: ZmqCounts | None = None
        self.last_stats: StreamStats | None = None

    def apply_ota_config(self, cfg) -> None:
        """The sample rate of ``cfg`` (``hil.OtaConfig``); frequency and gains are the
        flowgraph's."""
        self.sample_rate_hz = float(cfg.sample_rate_hz)

    @property
    def air_settable(self) -> bool:
        """False: the air is the flowgraph's, not the host's to set."""
        return False

    def set_air(self, channel, *, ppm: float = 0.0, seed: int = 0) -> None:
        """``HilError``: the air is the flowgraph's."""
        raise HilError("the ZMQ radio's air is its GNU Radio flowgraph's, not the host's to set")

    @property
    def receiving(self) -> bool:
        return self._receiving

    # ------------------------------------------------------------------ transmit clock
    def _dac(self) -> None:
        """Push one chunk per ``CHUNK_SAMPLES / fs`` seconds while the clock runs: queued
        burst samples first, silence otherwise."""
        silence = np.zeros(CHUNK_SAMPLES, ITEM)
        burst: np.ndarray | None = None
        done = threading.Event()
        pos = 0
        t0, sent = time.monotonic(), 0
        while self._clock_on.is_set():
            if burst is None:
                try:
                    burst, done = self._bursts.get_nowait()
                    pos = 0
                except queue.Empty:
                    pass
            if burst is not None:
                chunk = burst[pos : pos + CHUNK_SAMPLES]
                pos += len(chunk)
            else:
                chunk = silence
            due = t0 + sent / self.sample_rate_hz
            wait = due - time.monotonic()
            if wait > 0:
                time.sleep(wait)
            elif wait < -0.05:  # behind its clock (the flowgraph or the host stalled): resume
                self.late_chunks += 1
                t0, sent = time.monotonic(), 0
            if not self._send(chunk):
                return
            sent += len(chunk)
            if burst is not None and pos >= len(burst):
                done.set()
                burst = None

    def _send(self, chunk: np.ndarray) -> bool:
        """Push one chunk, waiting while the flowgraph is full; False once the clock stopped
        (or the socket failed) before it went."""
        zmq = self._zmq
        raw = chunk.tobytes()
        assert self._push is not None
        while self._clock_on.is_set():
            try:
                self._push.send(raw, flags=zmq.NOBLOCK)
                return True
            except zmq.Again:
                time.sleep(0.001)
            except zmq.ZMQError:
                return False
        return False

    def _start_clock(self) -> None:
        if self._push is None or self._clock_on.is_set():
            return
        self._clock_on.set()
        self._clock = threading.Thread(target=self._dac, name="zmq-dac", daemon=True)
        self._clock.start()

    def _stop_clock(self) -> None:
        self._clock_on.clear()
        if self._clock is not None:
            self._clock.join(timeout=5)
            self._clock = None

    # ------------------------------------------------------------------ streams
    def rx(self, num_samples: int, *, max_shortfalls: int | None = None) -> np.ndarray:
        """Capture ``num_samples`` of what the flowgraph returns while this radio's
        transmitter runs its clock.

        Returns:
            [1, num_samples] complex64.
        Raises:
            TimedOutError: nothing arrived for ``timeout_s`` (no flowgraph at the
            addresses?), carrying the capture so far.
        """
        zmq = self._zmq
        if self._pull is None:
            raise HilError("receive: this ZMQ radio has no receive endpoint")
        num_samples = int(num_samples)
        out = np.zeros(num_samples, ITEM)
        have = messages = timeouts = 0
        self.late_chunks = 0
        self._start_clock()
        try:
            stale = int(STALE_S * self.sample_rate_hz)
            waited_since = time.monotonic()
            while have < num_samples:
                if not self._pull.poll(100):
                    timeouts += 1
                    if time.monotonic() - waited_since > self.timeout_s:
                        raise TimedOutError(
                            f"receive: nothing from {self.rx_endpoint} for {self.timeout_s:g} s "
                            f"after {have} samples (is the flowgraph running?)",
                            capture=out[None, :have].copy(),
                        )
                    continue
                x = np.frombuffer(self._pull.recv(copy=True), ITEM)
                waited_since = time.monotonic()
                if stale > 0:  # what the flowgraph held from before this capture
                    drop = min(stale, len(x))
                    stale -= drop
                    x = x[drop:]
                    if stale > 0 or not len(x):
                        continue
                self._receiving = True
                n = min(len(x), num_samples - have)
                out[have : have + n] = x[:n]
                have += n
                messages += 1
        except zmq.ZMQError as e:
            raise HilError(f"receive: {e}", capture=out[None, :have].copy()) from e
        finally:
            self._receiving = False
            self._stop_clock()
            self.last_counts = ZmqCounts(have, messages, timeouts, self.late_chunks)
        self.last_stats = StreamStats("rx", num_samples, device_shortfalls=self.late_chunks)
        return out[None, :]

    def tx(self, samples, *, max_shortfalls: int | None = None) -> StreamStats:
        """Queue ``samples`` as one burst on the transmitter's clock and wait until it
        was pushed (the clock runs for this burst alone when no capture does)."""
        if self._push is None:
            raise HilError("transmit: this ZMQ radio has no transmit endpoint")
        x = np.ascontiguousarray(full_scale_samples(samples), ITEM)
        done = threading.Event()
        own_clock = not self._clock_on.is_set()
        self._bursts.put((x, done))
        self._start_clock()
        try:
            if not done.wait(timeout=len(x) / self.sample_rate_hz + self.timeout_s):
                raise TimedOutError(
                    f"transmit: {self.tx_endpoint} took no samples (is the flowgraph running?)"
                )
        finally:
            if own_clock and not self._receiving:
                self._stop_clock()
        self.last_stats = StreamStats("tx", len(x))
        return self.last_stats

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        self._stop_clock()
        for s in (self._push, self._pull):
            if s is not None:
                s.close(linger=0)
        self._ctx.term()

    def __enter__(self) -> ZmqRadio:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __repr__(self) -> str:
        return (
            f"ZmqRadio(tx={self.tx_endpoint!r}, rx={self.rx_endpoint!r}, "
            f"sample_rate_hz={self.sample_rate_hz:g})"
        )

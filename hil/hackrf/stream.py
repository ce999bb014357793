"""Streams of a front end: what one stream did (:class:`StreamStats`) and the HackRF's
receive thread that reads bulk transfers into a bounded queue."""

from __future__ import annotations

import queue
import threading
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class StreamStats:
    """What one receive or transmit stream did.

    Attributes:
        direction: "rx" or "tx".
        num_samples: samples delivered to (rx) or taken from (tx) the host.
        discarded_bytes: the stale first buffer thrown away (rx).
        host_dropped_bytes: transfers dropped because the host did not keep up (rx).
        device_shortfalls: overruns (rx) / underruns (tx) counted by the M0 core; -1 when
            the firmware cannot report them (USB API < 1.06).
        longest_shortfall_bytes: the longest such shortfall, bytes.
    """

    direction: str
    num_samples: int
    discarded_bytes: int = 0
    host_dropped_bytes: int = 0
    device_shortfalls: int = -1
    longest_shortfall_bytes: int = 0

    @property
    def clean(self) -> bool:
        return self.host_dropped_bytes == 0 and self.device_shortfalls <= 0


class RxThread:
    """Reads bulk IN transfers into a bounded queue; the first buffer is discarded."""

    def __init__(self, transport, chunk_bytes: int, max_queued: int, timeout_ms: int):
        self.transport = transport
        self.chunk_bytes = chunk_bytes
        self.timeout_ms = timeout_ms
        self.queue: queue.Queue = queue.Queue(maxsize=max_queued)
        self.stop = threading.Event()
        self.done = threading.Event()
        self.error: BaseException | None = None
        self.discarded_bytes = 0
        self.dropped_bytes = 0
        self.thread = threading.Thread(target=self._run, name="hackrf-rx", daemon=True)
        self.thread.start()

    def _run(self) -> None:
        first = True
        try:
            while not self.stop.is_set():
                try:
                    data = self.transport.read(self.chunk_bytes, self.timeout_ms)
                except Exception as e:  # noqa: BLE001 - handed to the consumer
                    if not self.stop.is_set():
                        self.error = e
                    return
                if first:  # stale samples from before the mode change
                    first = False
                    self.discarded_bytes += len(data)
                    continue
                try:
                    self.queue.put_nowait(data)
                except queue.Full:
                    self.dropped_bytes += len(data)
        finally:
            self.done.set()

    def get(self) -> np.ndarray | None:
        """Next buffer, or None when the thread ended (check ``error``)."""
        while True:
            try:
                return self.queue.get(timeout=0.05)
            except queue.Empty:
                if self.done.is_set() and self.queue.empty():
                    return None

"""Wall-clock pacing of an emulated HackRF's streams, with the board's overrun and underrun
model (:class:`StreamPacer`).

A paced board streams at its sample rate, as a real one does: a receive transfer is
delivered no earlier than its last sample was taken, and a transmit transfer is accepted
only while the board's buffer has room. Receiving, the board holds
:data:`RX_BUFFER_BYTES` (four 256 KiB transfers in flight, as libhackrf keeps, plus the
M0's 32 KiB buffer); a host that reads later than that loses the samples that no longer fit
(an overrun: the oldest ones). Transmitting, a synchronous bulk write completes once its
last bytes are in the M0's :data:`TX_BUFFER_BYTES`, so the writer runs at most that far
ahead of the DAC; a host that writes later than the buffer lasts lets the DAC run dry (an
underrun: silence goes out). Each is counted as one shortfall of the M0 state, with its length in bytes, as
the firmware counts them; the samples lost are counted exactly.
"""

from __future__ import annotations

import time

from hil import protocol as p

TX_BUFFER_BYTES = p.FLUSH_BYTES  # the M0's sample buffer
RX_BUFFER_BYTES = 4 * p.TRANSFER_BYTES + TX_BUFFER_BYTES


class StreamPacer:
    """The clock of one stream of a paced board.

    Args:
        sample_rate_hz: the board's sample rate.
        start_sample: the stream's first sample on the board's timeline.
        buffer_samples: samples the board holds between the converter and the host.
        clock: a monotonic clock in seconds (tests pass a fake one).
    """

    def __init__(
        self,
        sample_rate_hz: float,
        start_sample: int,
        buffer_samples: int = RX_BUFFER_BYTES // p.BYTES_PER_SAMPLE,
        clock=time.monotonic,
    ):
        self.sample_rate_hz = float(sample_rate_hz)
        self.start_sample = int(start_sample)
        self.buffer_samples = int(buffer_samples)
        self.clock = clock
        self.started_at: float | None = None
        self.shortfalls = 0
        self.longest_shortfall_bytes = 0
        self.lost_samples = 0  # overrun: never delivered; underrun: silence sent

    def start(self) -> None:
        """The converter starts now (receive: at the mode change; transmit: at the first
        write, when the M0 has samples to send)."""
        if self.started_at is None:
            self.started_at = self.clock()

    def converted(self) -> int:
        """Samples the converter has taken (or sent) since the stream started."""
        if self.started_at is None:
            return 0
        return int((self.clock() - self.started_at) * self.sample_rate_hz + 1e-6)  # float dust

    def _shortfall(self, samples: int) -> None:
        self.shortfalls += 1
        self.lost_samples += samples
        self.longest_shortfall_bytes = max(
            self.longest_shortfall_bytes, samples * p.BYTES_PER_SAMPLE
        )

    def before_read(self, cursor: int, num_samples: int) -> int:
        """Receive: wait until samples ``cursor .. cursor + num_samples - 1`` were taken and
        return where the read starts: ``cursor``, or later when the host fell more than the
        buffer behind (the samples that did not fit are lost: one overrun)."""
        self.start()
        backlog = self.converted() - (cursor - self.start_sample)
        if backlog > self.buffer_samples:
            lost = backlog - self.buffer_samples
            self._shortfall(lost)
            cursor += lost
        assert self.started_at is not None
        due = self.started_at + (cursor + num_samples - self.start_sample) / self.sample_rate_hz
        wait = due - self.clock()
        if wait > 0:
            time.sleep(wait)
        return cursor

    def before_write(self, written: int, num_samples: int, silent: bool = False) -> int:
        """Transmit: wait until the buffer has room for ``num_samples`` more after
        ``written`` samples of this stream; return the samples of silence the DAC sent
        because the host wrote too late (0 when on time: one underrun otherwise).
        ``silent``: the write holds only zeros (the end-of-burst flush), which go out as
        silence either way: late, they are no underrun."""
        first = self.started_at is None
        self.start()
        gap = 0 if first or silent else self.converted() - written
        if gap > 0:
            self._shortfall(gap)
            written += gap
        assert self.started_at is not None
        ahead = written + num_samples - self.buffer_samples
        due = self.started_at + ahead / self.sample_rate_hz
        wait = due - self.clock()
        if wait > 0:
            time.sleep(wait)
        return max(gap, 0)

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
underrun: silence goes out). Each is counted as one shortfall of the M0 state, with its length in
bytes, as the firmware counts them; the samples lost are counted exactly.

An emulated board delivers a transfer later than a real one would: it renders the air only
once the samples are due, in Python, on a host it may share. That delay is the emulator's,
not the host's, so it is not charged to the host: a read's request is taken to arrive as
much earlier as the previous transfer came out later than a real board's would have
(:attr:`StreamPacer.late_s`; while the host runs behind, the delays add up, as the real
board's transfers would have followed each other that much sooner). Only a host that
turns a transfer around too slowly loses samples; the largest delay the board itself added
is kept (:attr:`StreamPacer.longest_late_s`) and reported with the stream.
"""

from __future__ import annotations

import time

from hil.hackrf import protocol as p

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
        self.late_s = 0.0  # how much later than a real board the last transfer came out
        self.longest_late_s = 0.0
        self._ready: float | None = None  # when a real board's transfer would have been out

    def start(self) -> None:
        """The converter starts now (receive: at the mode change; transmit: at the first
        write, when the M0 has samples to send)."""
        if self.started_at is None:
            self.started_at = self.clock()

    def converted(self, at: float | None = None) -> int:
        """Samples the converter has taken (or sent) since the stream started, by ``at``
        (default: now)."""
        if self.started_at is None:
            return 0
        at = self.clock() if at is None else at
        return max(int((at - self.started_at) * self.sample_rate_hz + 1e-6), 0)  # float dust

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
        now = self.clock()
        asked = now - self.late_s  # when a real board would have had this request
        backlog = self.converted(asked) - (cursor - self.start_sample)
        if backlog > self.buffer_samples:
            lost = backlog - self.buffer_samples
            self._shortfall(lost)
            cursor += lost
        assert self.started_at is not None
        due = self.started_at + (cursor + num_samples - self.start_sample) / self.sample_rate_hz
        wait = due - now
        if wait > 0:
            time.sleep(wait)
        self._ready = max(asked, due)
        return cursor

    def after_read(self) -> None:
        """Receive: the transfer started by :meth:`before_read` is out (rendered and on
        its way to the host); how much later than a real board's it is carries over to the
        next request."""
        if self._ready is not None:
            self.late_s = max(self.clock() - self._ready, 0.0)
            self.longest_late_s = max(self.longest_late_s, self.late_s)
            self._ready = None

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


KERNEL_BUFFERS = 4  # DMA blocks an IIO device keeps by default (libiio 0.x)


class BlockQueue:
    """The DMA blocks of an IIO receive buffer (an emulated Pluto's), and the blocks a late
    reader loses.

    The ADC takes blocks of ``block_samples`` one after another from the moment the buffer
    opened; the device has ``num_blocks`` of them. A block it fills waits for the reader;
    the block the reader took last stays the reader's until it asks for the next one
    (libiio hands the memory back at the next refill). A block of samples the ADC completes
    while every block is full or the reader's has nowhere to go: it is lost whole. Each run
    of lost blocks found at one refill is one overrun; the blocks lost are counted exactly.

    Args:
        sample_rate_hz: the ADC's rate.
        block_samples: samples per block (the host's buffer size).
        num_blocks: blocks of the device (``SET dev BUFFERS_COUNT``).
        clock: a monotonic clock in seconds (tests pass a fake one).
    """

    def __init__(
        self,
        sample_rate_hz: float,
        block_samples: int,
        num_blocks: int = KERNEL_BUFFERS,
        clock=time.monotonic,
    ):
        if block_samples <= 0 or num_blocks <= 0:
            raise ValueError(
                f"need block_samples > 0 and num_blocks > 0, got {block_samples}, {num_blocks}"
            )
        self.sample_rate_hz = float(sample_rate_hz)
        self.block_samples = int(block_samples)
        self.num_blocks = int(num_blocks)
        self.clock = clock
        self.started_at = clock()
        self.next_slot = 0  # the first block of ADC samples not yet kept or lost
        self.ready: list[int] = []  # kept blocks the reader has not taken, oldest first
        self.held = 0  # blocks the reader holds (0 before its first refill)
        self.lost_blocks = 0
        self.overruns = 0

    def filled(self) -> int:
        """Blocks of samples the ADC has taken since the buffer opened."""
        elapsed = (self.clock() - self.started_at) * self.sample_rate_hz
        return int(elapsed / self.block_samples + 1e-9)  # float dust

    def waiting(self) -> int:
        """Complete blocks the reader has not taken (kept or about to be: it is late)."""
        return len(self.ready) + max(self.filled() - self.next_slot, 0)

    def take(self) -> int:
        """A refill: the reader hands back its block and takes the oldest kept one; returns
        that block's index (blocks since the buffer opened; its samples start at
        ``index * block_samples``). A block still being filled is the reader's next one
        (it waits for its samples)."""
        done = self.filled()
        if done > self.next_slot:  # completed while the reader held its block
            room = max(self.num_blocks - self.held - len(self.ready), 0)
            kept = min(room, done - self.next_slot)
            self.ready.extend(range(self.next_slot, self.next_slot + kept))
            lost = done - self.next_slot - kept
            if lost:
                self.lost_blocks += lost
                self.overruns += 1
            self.next_slot = done
        self.held = 1
        if self.ready:
            return self.ready.pop(0)
        self.next_slot += 1
        return self.next_slot - 1

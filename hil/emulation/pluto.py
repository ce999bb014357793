"""An emulated ADALM-Pluto: the AD9361's IIO devices, attributes and buffers, looped to itself.

The board holds what libiio sees of a Pluto (``ad9361-phy``, ``cf-ad9361-lpc``,
``cf-ad9361-dds-core-lpc``): the context XML, attribute reads and writes with the driver's
ranges, quantisation and errno-style refusals (:class:`hil.emulation.pluto_attrs.PlutoAttributes`),
and the sample buffers. Its TX DAC (12 bits in 16-bit containers, full scale
``ad9361.TX_FULL_SCALE``) loops to its RX ADC (12 bits, full scale ``ad9361.RX_FULL_SCALE``)
through a :class:`hil.Medium`: multipath, delay and noise at the channel's SNR. TX and RX
LOs come from one crystal, so TX and RX at the same LO have no carrier offset; a TX LO ``df`` above
the RX LO shifts what is received by ``df``.

The receive clock cannot run ahead of the wall clock (samples are delivered at most at the
sample rate since the buffer was opened), and a buffer opened with its size has the DMA
blocks of an IIO device (:class:`hil.emulation.pacing.BlockQueue`): a reader later than
they last loses whole blocks, counted in the debug attribute
``hil.pluto.context.OVERRUN_ATTR``. Transmit is virtual: the medium places what is
written at the receiver's current position and receivers wait for it while a TX buffer is
open. :class:`hil.IiodServer` serves a board over iiod's network protocol.
"""

from __future__ import annotations

import errno
import threading
import time
from dataclasses import dataclass

import numpy as np

from hil.emulation.air import RESAMPLER_TAPS, AirChannel
from hil.emulation.medium import Medium
from hil.emulation.pacing import KERNEL_BUFFERS, BlockQueue
from hil.emulation.pluto_attrs import (
    DEFAULT_RX_GAIN_DB,
    DEFAULT_TX_GAIN_DB,
    PlutoAttributes,
    iio_errno,
    parse_air_setting,
)
from hil.pluto import ad9361
from hil.pluto.ad9361 import RX_FULL_SCALE, TX_FULL_SCALE
from hil.pluto.context import (
    AIR_ATTR,
    OVERRUN_ATTR,
    PHY,
    RX_DEV,
    air_setting,
    context_xml,
)

NETWORK_FAULTS = ("drop", "slow")
"""Faults of a served board (``osnerf hil emulate pluto --fault``), both ``after_samples``
received samples into its life: ``drop`` (the board dies: every connection closes) and
``slow`` (each later receive reply comes ``SLOW_REPLY_S`` late, past libiio's 5 s timeout)."""
SLOW_REPLY_S = 6.0
TX_UNDERRUN_S = 1.0  # wall time a receive waits for an open TX buffer's data before it underruns


@dataclass
class _Port:
    """One side of the board as the medium sees it (same crystal for both)."""

    board: EmulatedPluto
    direction: str
    index: int

    @property
    def ppm(self) -> float:
        return self.board.ppm

    @property
    def sample_rate_hz(self) -> float:
        return float(self.board.sample_rate_hz)

    @property
    def center_freq_hz(self) -> float:
        return float(self.board.rx_lo_hz if self.direction == "rx" else self.board.tx_lo_hz)

    @property
    def rx_gain_db(self) -> float:
        return float(self.board.rx_gain_db)

    @property
    def tx_gain_db(self) -> float:
        return float(self.board.tx_gain_db)


class EmulatedPluto(PlutoAttributes):
    """One emulated Pluto's state (thread-safe).

    Args:
        channel: the air from its TX port to its RX port.
        seed: noise seed.
        ppm: crystal error, parts per million (LOs and sample clock alike).
        serial: what ``hw_serial`` reports.
        drop_after_samples: the board's connections drop once this many samples were
            received (a killed or unplugged board); None: never.
        slow_after_samples: once this many samples were received, each receive reply is
            ``SLOW_REPLY_S`` late (a server that stalls); None: never.
        air_settable: the host may set the air, crystal and seed through the debug attribute
            ``hil.pluto.context.AIR_ATTR`` (what ``osnerf ota`` does before each burst);
            False: the board behaves as a real one, whose air is not the host's to set.
    """

    def __init__(
        self,
        channel: AirChannel | None = None,
        seed: int = 0,
        ppm: float = 0.0,
        serial: str = "104473dc599300131100210074c83b9f0e",
        drop_after_samples: int | None = None,
        slow_after_samples: int | None = None,
        air_settable: bool = True,
    ):
        super().__init__()  # the AD9361 settings and the lock
        if air_settable:
            self.debug_attrs[PHY] = (*self.debug_attrs[PHY], AIR_ATTR)
        self.debug_attrs[RX_DEV] = (*self.debug_attrs[RX_DEV], OVERRUN_ATTR)
        self.medium = Medium(channel, seed=seed, wait_timeout_s=TX_UNDERRUN_S)
        self.ppm = float(ppm)
        self.serial = serial
        self.drop_after_samples = drop_after_samples
        self.slow_after_samples = slow_after_samples
        self.rx_port = _Port(self, "rx", 0)
        self.tx_port = _Port(self, "tx", 1)
        self.rx_cursor = 0  # samples received since the board was made
        self.rx_open = False
        self.rx_opened_at = (0.0, 0)  # (monotonic s, rx_cursor) when the RX buffer opened
        # end of the samples the receiver is rendering now (rx_cursor once a read returns): a
        # transmission that starts meanwhile starts after them, never inside a read in flight
        self.rx_frontier = 0
        self.tx_open = False
        self.tx_is_cyclic = False
        self.tx_cyclic: np.ndarray | None = None
        self.samples_received = 0
        self.rx_blocks: BlockQueue | None = None  # the open buffer's DMA blocks, if sized
        self.rx_block_left = 0  # samples of the block the reader has not had yet
        self.tx_underruns = 0  # times the open TX buffer ran dry while receiving
        self.tx_starved = False  # the open TX buffer is dry: the DAC sends silence
        self.dropped = threading.Event()  # set when a drop fault closed every connection
        self.stalled = threading.Event()  # set when a slow fault began

    @classmethod
    def for_link(
        cls,
        snr_db: float,
        *,
        seed: int = 0,
        multipath=(),
        delay_s: float = 0.0,
        reference_power_dbfs: float = -9.0,
        fault: str | None = None,
        after_samples: int = 50_000,
        ppm: float = 0.0,
        air_settable: bool = True,
    ) -> EmulatedPluto:
        """A board whose loop has ``snr_db`` for a signal of ``reference_power_dbfs`` (the
        over-the-air frames' mean power) sent and received at the default gains
        (:data:`DEFAULT_TX_GAIN_DB`, :data:`DEFAULT_RX_GAIN_DB`).

        Args:
            fault: one of :data:`NETWORK_FAULTS` or None.
            after_samples: received samples before the fault.
            ppm: the board's crystal error (one crystal: no offset between its TX and RX).
            air_settable: see the class.
        """
        if fault is not None and fault not in NETWORK_FAULTS:
            raise KeyError(f"unknown fault {fault!r}; known: {', '.join(NETWORK_FAULTS)}")
        channel = AirChannel(
            snr_db=float(snr_db),
            reference_power_dbfs=reference_power_dbfs,
            reference_txvga_db=DEFAULT_TX_GAIN_DB,
            reference_rx_gain_db=DEFAULT_RX_GAIN_DB,
            delay_s=delay_s,
            multipath=tuple(multipath),
        )
        return cls(
            channel,
            seed=seed,
            ppm=ppm,
            drop_after_samples=int(after_samples) if fault == "drop" else None,
            slow_after_samples=int(after_samples) if fault == "slow" else None,
            air_settable=air_settable,
        )

    # ------------------------------------------------------------------ the context
    def context_xml(self, description: str = "osnerf emulated ADALM-Pluto") -> str:
        """The context as libiio's XML (what iiod's ``PRINT`` returns)."""
        ctx_attrs = {
            "hw_model": "Analog Devices PlutoSDR Rev.C (Z7010-AD9363A) (emulated)",
            "hw_model_variant": "1",
            "hw_serial": self.serial,
            "fw_version": "v0.38",
            "ad9361-phy,xo_correction": str(ad9361.REFERENCE_HZ),
            "ad9361-phy,model": "ad9363a",
            "local,kernel": "osnerf-emulator",
        }
        return context_xml(ctx_attrs, description, self.debug_attrs)

    def _read(self, dev, chan_id, output, kind, attr) -> str:
        if (dev, kind, attr) == (PHY, "DEBUG", AIR_ATTR):
            return air_setting(self.medium.channel, self.ppm, self.medium.seed)
        if (dev, kind, attr) == (RX_DEV, "DEBUG", OVERRUN_ATTR):
            q = self.rx_blocks
            if q is None:
                return "0 0 0"
            return f"{q.overruns} {q.lost_blocks} {q.lost_blocks * q.block_samples}"
        return super()._read(dev, chan_id, output, kind, attr)

    def _write(self, dev, chan_id, output, kind, attr, value) -> None:
        if (dev, kind, attr) != (PHY, "DEBUG", AIR_ATTR):
            return super()._write(dev, chan_id, output, kind, attr, value)
        try:
            channel, ppm, seed = parse_air_setting(value)
        except ValueError as e:
            raise iio_errno(errno.EINVAL, str(e)) from None
        if self.rx_open or self.tx_open:
            raise iio_errno(
                errno.EBUSY, f"{AIR_ATTR}: a buffer is open; set the air between bursts"
            )
        self.medium.set_channel(channel, seed)
        self.ppm = ppm

    # ------------------------------------------------------------------ buffers
    def open_rx(self, block_samples: int | None = None, num_blocks: int = KERNEL_BUFFERS) -> None:
        """Start receiving "now": the RX clock jumps to the medium's present.

        Args:
            block_samples: the host's buffer size: the device keeps ``num_blocks`` DMA
                blocks of it, and a late reader loses whole blocks (None: no block model;
                samples wait for the reader however late).
        """
        with self.lock:
            if self.rx_open:
                raise iio_errno(errno.EBUSY, "the RX buffer is already open")
            m = self.medium
            if m.transmitter is not None:  # the same clock: TX and RX samples are simultaneous
                self.rx_cursor = max(self.rx_cursor, m.tx_len)
            m.idle_until(self.rx_cursor)
            self.rx_frontier = self.rx_cursor
            self.rx_open = True
            self.rx_opened_at = (time.monotonic(), self.rx_cursor)
            self.rx_block_left = 0
            self.rx_blocks = None
            if block_samples is not None:
                q = BlockQueue(self.sample_rate_hz, block_samples, num_blocks)
                q.started_at = self.rx_opened_at[0]
                self.rx_blocks = q

    def close_rx(self) -> None:
        with self.lock:
            self.rx_open = False
        self.medium.notify()

    def read_rx(self, num_samples: int) -> np.ndarray | None:
        """The next ``num_samples`` received, [2 * num_samples] int16 (I, Q), paced to at most
        the sample rate since the buffer opened; None when the connection is to drop."""
        if self.drop_after_samples is not None:
            left = self.drop_after_samples - self.samples_received
            if left <= 0:
                self.dropped.set()
                return None
            num_samples = min(num_samples, left)
        if self.slow_after_samples is not None:
            left = self.slow_after_samples - self.samples_received
            if left <= 0:  # late; a client that gave up has closed the connection by then
                self.stalled.set()
                self.dropped.wait(SLOW_REPLY_S)
            else:
                num_samples = min(num_samples, left)
        t0, k0 = self.rx_opened_at
        num_samples = self._next_block(num_samples, k0)
        due = t0 + (self.rx_cursor + num_samples - k0) / self.sample_rate_hz
        wait = due - time.monotonic()
        if wait > 0:
            time.sleep(wait)
        with self.lock:
            self.rx_frontier = self.rx_cursor + num_samples
        self._extend_cyclic(num_samples)
        if self.tx_starved and self.medium.tx_streaming:  # still dry: silence, no waiting
            self.medium.idle_until(self.rx_cursor + num_samples + RESAMPLER_TAPS, underrun=True)
        asked = time.monotonic()
        y = self.medium.render_iq(self.rx_port, self.rx_cursor, num_samples, lambda: self.rx_open)
        if y is None and self.rx_open and self.medium.tx_streaming:
            self._pause_clock(time.monotonic() - asked)  # the board's wait, not the host's
            self.tx_starved = True
            # the host did not feed the open TX buffer in time: the DAC underruns (sends
            # silence) and what it writes later goes out later, as on a board
            self.tx_underruns += 1
            self.medium.idle_until(self.rx_cursor + num_samples + RESAMPLER_TAPS, underrun=True)
            y = self.medium.render_iq(
                self.rx_port, self.rx_cursor, num_samples, lambda: self.rx_open
            )
        if y is None:
            raise iio_errno(errno.ETIMEDOUT, "no samples: the receive wait timed out")
        self.rx_cursor += num_samples
        self.rx_block_left -= num_samples
        self.samples_received += num_samples
        keep = int(self.medium.channel.delay_s * self.sample_rate_hz) + 8192  # delay + filters
        self.medium.forget_before(self.rx_cursor - keep)
        inter = y.view(np.float32) * np.float32(RX_FULL_SCALE)
        return np.clip(np.rint(inter), -RX_FULL_SCALE, RX_FULL_SCALE - 1).astype(np.int16)

    def _pause_clock(self, seconds: float) -> None:
        """The receive clock stands still for ``seconds``: the emulation waited for the
        virtual transmitter, which a board's ADC never does, so the reader is no later."""
        t0, k0 = self.rx_opened_at
        self.rx_opened_at = (t0 + seconds, k0)
        if self.rx_blocks is not None:
            self.rx_blocks.started_at += seconds

    def _adc_present(self) -> int:
        """Where a transmission starting now starts on the receive clock: the reader's
        position while it keeps up, else (a whole block of a sized buffer waits for the
        reader) what the ADC has taken by now, after the blocks queued for it."""
        q = self.rx_blocks
        if q is None or not self.rx_open or not q.waiting():
            return self.rx_frontier
        t0, k0 = self.rx_opened_at
        return max(self.rx_frontier, k0 + int((time.monotonic() - t0) * self.sample_rate_hz))

    def _next_block(self, num_samples: int, k0: int) -> int:
        """At a block boundary, the reader's next block (skipping, and counting, the samples
        of blocks lost meanwhile); the samples of this read, within its block."""
        q = self.rx_blocks
        if q is None:
            return num_samples
        if self.rx_block_left <= 0:
            # past whole blocks lost, the reader's clock jumps
            self.rx_cursor = max(self.rx_cursor, k0 + q.take() * q.block_samples)
            self.rx_block_left = q.block_samples
        return min(num_samples, self.rx_block_left)

    def _extend_cyclic(self, num_samples: int) -> None:
        """A cyclic TX buffer repeats: append copies until the receiver's next read is covered."""
        cyc = self.tx_cyclic
        if cyc is None:
            return
        m = self.medium
        fs = self.sample_rate_hz
        need = int((self.rx_cursor + num_samples) + m.channel.delay_s * fs) + 4096 + m.fir(fs).span
        while m.tx_len < need:
            m.append_tx_iq(self.tx_port, cyc)

    def open_tx(self, cyclic: bool) -> None:
        with self.lock:
            if self.tx_open:
                raise iio_errno(errno.EBUSY, "the TX buffer is already open")
            self.tx_open = True
            self.tx_cyclic = None
            self.tx_is_cyclic = bool(cyclic)
            # what is sent starts at the receiver's now: after the read in flight, if any,
            # and after what the ADC has taken and not yet delivered
            self.medium.idle_until(max(self.rx_frontier, self._adc_present()))
            self.medium.start_tx(self.tx_port)

    def write_tx(self, raw: np.ndarray) -> None:
        """[2 * num_samples] int16 I, Q from the host; the DAC keeps the 12 MSBs."""
        if self.tx_starved:  # the DAC ran dry: what comes now goes out now
            self.medium.idle_until(self._adc_present(), underrun=True)
        self.tx_starved = False
        x = ((raw.astype(np.int32) >> 4) << 4).astype(np.float32) / np.float32(TX_FULL_SCALE)
        iq = x.view(np.complex64)
        if self.tx_is_cyclic:
            self.tx_cyclic = iq.copy()
            self.medium.end_tx(self.tx_port)  # repeats on demand, never waited for
        else:
            self.medium.append_tx_iq(self.tx_port, iq)

    def close_tx(self) -> None:
        with self.lock:
            self.tx_open = False
            self.tx_cyclic = None
        self.medium.end_tx(self.tx_port)

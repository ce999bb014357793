"""An emulated HackRF One board: its radio state, its answers to control requests and
bulk transfers, and the faults it can inject.

It stalls on values the firmware refuses (USBError errno 32), times out like libusb
(USBTimeoutError, errno 110), can be unplugged mid-stream (errno 19), and connects one
transmitter to any receivers through a :class:`hil.Medium` on a virtual clock.
:class:`hil.Emulator` serves such boards to pyusb.
"""

from __future__ import annotations

import errno
import struct
import threading
from dataclasses import dataclass, field

import numpy as np
import usb.core

from hil.emulation.medium import AMP_GAIN_DB, Medium
from hil.emulation.pacing import RX_BUFFER_BYTES, TX_BUFFER_BYTES, StreamPacer
from hil.hackrf import protocol as p

_STALE_VALUE = 100  # the stale first buffer holds this int8 value in every byte
_M0_IDLE, _M0_RX, _M0_TX_RUN = 0, 2, 4
RX_SAMPLES, TX_SAMPLES = RX_BUFFER_BYTES // 2, TX_BUFFER_BYTES // 2  # a paced board's buffers
PPM_RANGE = (-200.0, 200.0)  # crystal error of an emulated board, parts per million


def stall_error(what: str) -> usb.core.USBError:
    """The error libusb raises when the device stalls a request (errno 32)."""
    return usb.core.USBError(f"Pipe error ({what})", -9, errno.EPIPE)


def timeout_error() -> usb.core.USBTimeoutError:
    """The error libusb raises when a transfer times out (errno 110)."""
    return usb.core.USBTimeoutError("Operation timed out", -7, errno.ETIMEDOUT)


def gone_error() -> usb.core.USBError:
    """The error libusb raises for an unplugged device (errno 19)."""
    return usb.core.USBError("No such device (it may have been disconnected)", -4, errno.ENODEV)


@dataclass(frozen=True)
class RadioSpec:
    """Identity and crystal of one emulated board.

    Attributes:
        serial: 32 lowercase hex characters.
        ppm: crystal error (sample clock and LO), parts per million.
        board_id: 2 = HackRF One.
        firmware_version: what request 15 returns.
        usb_api_version: bcdDevice (0x0108 for v2024.02.1).
        product_id: 0x6089 (HackRF One).
        part_id: the two part-id words of request 18.
    """

    serial: str
    ppm: float = 0.0
    board_id: int = 2
    firmware_version: str = "2024.02.1"
    usb_api_version: int = 0x0108
    product_id: int = 0x6089
    part_id: tuple[int, int] = (0xA000CB3C, 0x00574F61)

    def __post_init__(self):
        if len(self.serial) != 32 or any(c not in "0123456789abcdef" for c in self.serial):
            raise ValueError(f"serial must be 32 lowercase hex characters, got {self.serial!r}")
        lo, hi = PPM_RANGE
        if not lo <= self.ppm <= hi:
            raise ValueError(f"ppm must be in [{lo:g}, {hi:g}], got {self.ppm!r}")


FAULT_NAMES = ("stall", "rx-timeout", "unplug", "overrun")
"""Named faults of :meth:`Faults.named` (``osnerf ota --fault``)."""


@dataclass
class Faults:
    """Faults to inject (mutable: tests switch them on mid-run).

    Byte and sample counts are per board since it was created; a read that would cross a
    limit stops at it (a short transfer, as libusb returns before a timeout), so the data
    before a fault is exact.

    Attributes:
        stall_requests: vendor request numbers that always stall.
        read_timeout_after_bytes: bulk reads time out once this many bytes were read
            (the stale first buffer included).
        unplug_after_bytes: the device disappears once this many bytes were read.
        read_timeout_after_samples: bulk reads time out once this many samples of the air
            were received (the stale first buffer not counted).
        unplug_after_samples: the device disappears once this many samples of the air
            were received.
        shortfalls: overruns/underruns the M0 state reports for each stream.
        stale_first_buffer: the first read after entering receive returns stale bytes.
    """

    stall_requests: set[int] = field(default_factory=set)
    read_timeout_after_bytes: int | None = None
    unplug_after_bytes: int | None = None
    read_timeout_after_samples: int | None = None
    unplug_after_samples: int | None = None
    shortfalls: int = 0
    stale_first_buffer: bool = True

    @classmethod
    def named(cls, name: str, after_samples: int = 0) -> Faults:
        """A receiver's fault by name, to rehearse how a run reports it.

        Args:
            name: one of :data:`FAULT_NAMES`: ``"stall"`` (the firmware stalls the
                set-frequency request), ``"rx-timeout"`` (bulk reads time out after
                ``after_samples`` samples), ``"unplug"`` (the board vanishes after
                ``after_samples`` samples), ``"overrun"`` (the M0 counts 3 overruns).
            after_samples: samples received before a timeout or unplug (>= 0).
        Raises:
            KeyError: unknown name, listing the known ones.
        """
        if after_samples < 0:
            raise ValueError(f"after_samples must be >= 0, got {after_samples!r}")
        if name == "stall":
            return cls(stall_requests={p.SET_FREQ})
        if name == "rx-timeout":
            return cls(read_timeout_after_samples=int(after_samples))
        if name == "unplug":
            return cls(unplug_after_samples=int(after_samples))
        if name == "overrun":
            return cls(shortfalls=3)
        raise KeyError(f"unknown fault {name!r}; known: {', '.join(FAULT_NAMES)}")


class EmulatedHackRF:
    """One emulated board: the firmware's request handling and its bulk endpoints.

    ``events`` logs what the host did, in order: ``("ctrl", ControlRequest)``,
    ``("write", bytes)`` and ``("read", num_bytes)``.

    ``paced``: stream at the sample rate against the wall clock, with the board's overrun
    and underrun model (:mod:`hil.emulation.pacing`); ``overrun_samples`` and
    ``underrun_samples`` count the samples lost that way over the board's life, and
    ``rx_late_max_s`` is the most a receive transfer came out later than a real board's
    would have (the emulator's own delay, not charged to the host). A paced board logs
    the length of each write, not its bytes: a stream would keep every sample it sent.
    """

    def __init__(
        self, spec: RadioSpec, medium: Medium, index: int = 0, faults: Faults | None = None
    ):
        self.spec = spec
        self.medium = medium
        self.index = index
        self.faults = faults or Faults()
        self.events: list = []
        self.lock = threading.RLock()
        self.unplugged = False
        self.configuration = 1
        self.claimed = False
        self.mode = p.MODE_OFF
        self.sample_rate_hz = 10e6
        self.baseband_filter_hz = p.auto_baseband_filter_hz(10e6)
        self.center_freq_hz = 2.45e9
        self.amp_enabled = False
        self.bias_tee_enabled = False
        self.hw_sync = False
        self.lna_gain_db = 16
        self.vga_gain_db = 16
        self.txvga_gain_db = 0
        self.rx_cursor = 0  # receiver timeline position, samples
        self.paced = False
        self.pacer: StreamPacer | None = None
        self.tx_written = 0  # samples of the current transmit stream, silence included
        self.overrun_samples = 0
        self.underrun_samples = 0
        self.rx_late_max_s = 0.0  # the most a transfer came out later than a real board's
        self.bytes_read = 0
        self._stale_pending = False
        self.m0 = dict(
            requested=0, active=_M0_IDLE, m0_count=0, m4_count=0, shortfalls=0, longest=0
        )

    @property
    def ppm(self) -> float:
        return self.spec.ppm

    @property
    def serial(self) -> str:
        return self.spec.serial

    @property
    def rx_gain_db(self) -> float:
        """LNA + VGA (+ the amp), dB: the receive gain the medium applies."""
        return self.lna_gain_db + self.vga_gain_db + AMP_GAIN_DB * self.amp_enabled

    @property
    def tx_gain_db(self) -> float:
        """TX VGA (+ the amp), dB: the transmit gain the medium applies."""
        return self.txvga_gain_db + AMP_GAIN_DB * self.amp_enabled

    # ------------------------------------------------------------------ control
    def control(self, request_type: int, request: int, value: int, index: int, data_or_length):
        """A vendor request: OUT returns bytes accepted, IN returns the reply bytes."""
        if self.unplugged:
            raise gone_error()
        is_in = bool(request_type & 0x80)
        data = b"" if is_in else bytes(data_or_length or b"")
        length = int(data_or_length) if is_in else 0
        with self.lock:
            self.events.append(
                ("ctrl", p.ControlRequest(request_type, request, value, index, data, length))
            )
            if request in self.faults.stall_requests:
                raise stall_error(f"request {request} set to stall")
            if request_type not in (p.OUT, p.IN):
                raise stall_error("bad request type")
            reply = self._handle(request, value, index, data, is_in)
        if is_in:
            if reply is None:
                raise stall_error(f"request {request} is not an IN request")
            return bytes(reply[:length])
        if reply is not None:
            raise stall_error(f"request {request} is an IN request")
        return len(data)

    def _handle(self, req: int, value: int, index: int, data: bytes, is_in: bool):
        if req == p.SET_TRANSCEIVER_MODE and not is_in:
            if value not in p.TRANSCEIVER_MODES:
                raise stall_error(f"unknown transceiver mode {value}")
            self._set_mode(value)
        elif req == p.SAMPLE_RATE_SET and not is_in:
            if len(data) != 8:
                raise stall_error("sample rate payload must be 8 bytes")
            freq_hz, divider = struct.unpack("<II", data)
            if divider == 0 or not 1e6 <= freq_hz / divider <= 25e6:
                raise stall_error(f"sample rate {freq_hz}/{divider}")
            self.sample_rate_hz = freq_hz / divider
            self.baseband_filter_hz = p.auto_baseband_filter_hz(self.sample_rate_hz)
        elif req == p.BASEBAND_FILTER_BANDWIDTH_SET and not is_in:
            self.baseband_filter_hz = p.baseband_filter_round_down(value | (index << 16))
        elif req == p.SET_FREQ and not is_in:
            if len(data) != 8:
                raise stall_error("frequency payload must be 8 bytes")
            mhz, hz = struct.unpack("<II", data)
            f = mhz * 1_000_000 + hz
            if hz >= 1_000_000 or f > p.FREQ_STALL_ABOVE_HZ:
                raise stall_error(f"frequency {f} Hz")
            self.center_freq_hz = float(f)
        elif req == p.AMP_ENABLE and not is_in:
            self.amp_enabled = bool(value)
        elif req == p.ANTENNA_ENABLE and not is_in:
            self.bias_tee_enabled = bool(value)
        elif req == p.SET_HW_SYNC_MODE and not is_in:
            self.hw_sync = bool(value)
        elif req == p.SET_LNA_GAIN and is_in:
            ok = index <= 40
            if ok:
                self.lna_gain_db = index & ~0x07
            return bytes([int(ok)])
        elif req == p.SET_VGA_GAIN and is_in:
            ok = index <= 62
            if ok:
                self.vga_gain_db = index & ~0x01
            return bytes([int(ok)])
        elif req == p.SET_TXVGA_GAIN and is_in:
            ok = index <= 47
            if ok:
                self.txvga_gain_db = index
            return bytes([int(ok)])
        elif req == p.BOARD_ID_READ and is_in:
            return bytes([self.spec.board_id])
        elif req == p.VERSION_STRING_READ and is_in:
            return self.spec.firmware_version.encode("ascii")
        elif req == p.BOARD_PARTID_SERIALNO_READ and is_in:
            words = [int(self.spec.serial[i : i + 8], 16) for i in range(0, 32, 8)]
            return struct.pack(p.PARTID_SERIAL_FORMAT, *self.spec.part_id, *words)
        elif req == p.GET_M0_STATE and is_in:
            if self.spec.usb_api_version < p.M0_STATE_MIN_API:
                raise stall_error("M0 state needs USB API 1.06")
            m = self.m0
            return p.M0State(
                m["requested"],
                0,
                m["active"],
                m["m0_count"],
                m["m4_count"],
                m["shortfalls"],
                m["longest"],
                0,
                0,
                0,
                0,
            ).pack()
        else:
            raise stall_error(f"unknown request {req} ({'IN' if is_in else 'OUT'})")
        return None

    def _set_mode(self, mode: int) -> None:
        old = self.mode
        self.mode = mode
        if old == p.MODE_TRANSMIT and mode != p.MODE_TRANSMIT:
            self.medium.end_tx(self)
        m0_mode = {p.MODE_OFF: _M0_IDLE, p.MODE_RECEIVE: _M0_RX, p.MODE_TRANSMIT: _M0_TX_RUN}[mode]
        self.m0["requested"] = m0_mode
        self.m0["active"] = m0_mode
        if mode != p.MODE_OFF:  # counters restart with each stream
            self.m0.update(
                m0_count=0,
                m4_count=0,
                shortfalls=self.faults.shortfalls,
                longest=512 * self.faults.shortfalls,
            )
        if mode == p.MODE_RECEIVE:
            self._stale_pending = self.faults.stale_first_buffer
        if mode == p.MODE_TRANSMIT:
            self.medium.start_tx(self)
        self.pacer = None
        if self.paced and mode != p.MODE_OFF:
            self.tx_written = 0
            if mode == p.MODE_RECEIVE:
                self.pacer = StreamPacer(self.sample_rate_hz, self.rx_cursor, RX_SAMPLES)
                self.pacer.start()
            else:
                self.pacer = StreamPacer(self.sample_rate_hz, self.medium.tx_len, TX_SAMPLES)
        self.medium.notify()

    # ------------------------------------------------------------------ bulk
    def bulk_read(self, num_bytes: int) -> bytes:
        """Bulk IN 0x81: ``num_bytes`` (a multiple of 2) of int8 I, Q."""
        if self.unplugged:
            raise gone_error()
        f = self.faults
        if f.unplug_after_bytes is not None and self.bytes_read >= f.unplug_after_bytes:
            self.unplugged = True
            self.medium.notify()
            raise gone_error()
        if f.read_timeout_after_bytes is not None and self.bytes_read >= f.read_timeout_after_bytes:
            raise timeout_error()
        if self.mode != p.MODE_RECEIVE:
            raise timeout_error()
        n = num_bytes // 2
        byte_limits = [
            x for x in (f.unplug_after_bytes, f.read_timeout_after_bytes) if x is not None
        ]
        if byte_limits:  # a short transfer up to the fault
            n = min(n, max(1, (min(byte_limits) - self.bytes_read) // 2))
        if self._stale_pending:
            self._stale_pending = False
            out = bytes([_STALE_VALUE]) * (2 * n)
        else:
            if f.unplug_after_samples is not None and self.rx_cursor >= f.unplug_after_samples:
                self.unplugged = True
                self.medium.notify()
                raise gone_error()
            if (
                f.read_timeout_after_samples is not None
                and self.rx_cursor >= f.read_timeout_after_samples
            ):
                raise timeout_error()
            limits = [
                x for x in (f.unplug_after_samples, f.read_timeout_after_samples) if x is not None
            ]
            if limits:
                n = min(n, min(limits) - self.rx_cursor)
            pacer = self.pacer  # one stream's, even if the host switches modes meanwhile
            if pacer is not None:
                self._pace_read(pacer, n)
            raw = self.medium.render(
                self, self.rx_cursor, n, lambda: self.mode == p.MODE_RECEIVE and not self.unplugged
            )
            if raw is None:
                if self.unplugged:
                    raise gone_error()
                raise timeout_error()
            self.rx_cursor += n
            out = raw.tobytes()
            if pacer is not None:
                pacer.after_read()
                self.rx_late_max_s = max(self.rx_late_max_s, pacer.longest_late_s)
        self.bytes_read += len(out)
        self.m0["m0_count"] += len(out)
        self.m0["m4_count"] += len(out)
        self.events.append(("read", len(out)))
        return out

    def bulk_write(self, data: bytes) -> int:
        """Bulk OUT 0x02: int8 I, Q to transmit."""
        if self.unplugged:
            raise gone_error()
        if self.mode != p.MODE_TRANSMIT:
            raise timeout_error()
        if len(data) % 2:
            raise stall_error("odd number of bytes")
        self.events.append(("write", len(data) if self.paced else bytes(data)))
        pacer = self.pacer
        if pacer is not None:
            n = len(data) // 2
            gap = pacer.before_write(self.tx_written, n, silent=not any(data))
            if gap:  # the DAC ran dry: silence went out
                self.medium.idle_until(self.medium.tx_len + gap, underrun=True)
                self.underrun_samples += gap
                self._count_shortfalls(pacer)
            self.tx_written += gap + n
        self.medium.append_tx(self, np.frombuffer(data, dtype=np.int8))
        self.m0["m0_count"] += len(data)
        self.m0["m4_count"] += len(data)
        return len(data)

    def _pace_read(self, pacer: StreamPacer, num_samples: int) -> None:
        """Wait for the samples of the next read to be taken; skip (and count) those lost
        to an overrun; forget the transmitter's samples no receiver needs any more."""
        start = pacer.before_read(self.rx_cursor, num_samples)
        if start > self.rx_cursor:
            self.overrun_samples += start - self.rx_cursor
            self.rx_cursor = start
            self._count_shortfalls(pacer)
        slack = int(self.medium.channel.delay_s * self.sample_rate_hz) + (1 << 16)
        self.medium.forget_before(int(self.rx_cursor * (1 - 2 * PPM_RANGE[1] * 1e-6)) - slack)

    def _count_shortfalls(self, pacer: StreamPacer) -> None:
        self.m0["shortfalls"] = self.faults.shortfalls + pacer.shortfalls
        self.m0["longest"] = max(self.m0["longest"], pacer.longest_shortfall_bytes)

    def unplug(self) -> None:
        """Pull the cable: every later request raises errno 19."""
        self.unplugged = True
        self.medium.notify()

"""The HackRF One USB protocol as pure functions: every control request as bytes.

Every constant comes from the protocol reference (libhackrf / hackrf_transfer / firmware
v2024.02.1+). Each builder returns a :class:`ControlRequest` whose fields are exactly what
goes on the wire, so tests compare them byte for byte and the emulator parses the same
objects.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass

VENDOR_ID = 0x1D50
PRODUCT_IDS = {0x6089: "HackRF One", 0x604B: "Jawbreaker", 0xCC15: "rad1o"}
BOARD_IDS = {
    0: "Jellybean",
    1: "Jawbreaker",
    2: "HackRF One",
    3: "rad1o",
    4: "HackRF One r9",
    5: "HackRF Pro",
}

CONFIGURATION_VALUE = 1
INTERFACE = 0
ENDPOINT_RX = 0x81
ENDPOINT_TX = 0x02
PACKET_BYTES = 512
TRANSFER_BYTES = 262144  # libhackrf's transfer size: 256 KiB, a multiple of 512
FLUSH_BYTES = 32768  # the firmware's bulk buffer: zeros written after the last TX samples
CONTROL_TIMEOUT_MS = 100
BYTES_PER_SAMPLE = 2  # interleaved int8 I, Q (SigMF ci8)
M0_STATE_MIN_API = 0x0106

OUT = 0x40  # vendor, host to device, device recipient
IN = 0xC0  # vendor, device to host, device recipient

SET_TRANSCEIVER_MODE = 1
SAMPLE_RATE_SET = 6
BASEBAND_FILTER_BANDWIDTH_SET = 7
BOARD_ID_READ = 14
VERSION_STRING_READ = 15
SET_FREQ = 16
AMP_ENABLE = 17
BOARD_PARTID_SERIALNO_READ = 18
SET_LNA_GAIN = 19
SET_VGA_GAIN = 20
SET_TXVGA_GAIN = 21
ANTENNA_ENABLE = 23
SET_HW_SYNC_MODE = 29
GET_M0_STATE = 41

MODE_OFF, MODE_RECEIVE, MODE_TRANSMIT = 0, 1, 2
TRANSCEIVER_MODES = {MODE_OFF: "off", MODE_RECEIVE: "receive", MODE_TRANSMIT: "transmit"}

SAMPLE_RATE_RANGE_HZ = (2e6, 20e6)
MAX_DIVIDER = 31
FREQ_RANGE_HZ = (1e6, 6e9)  # nominal tuning range the driver accepts
FREQ_STALL_ABOVE_HZ = 7250e6  # the firmware stalls above this
BASEBAND_FILTERS_HZ = tuple(
    int(round(m * 1e6)) for m in (1.75, 2.5, 3.5, 5, 5.5, 6, 7, 8, 9, 10, 12, 14, 15, 20, 24, 28)
)
AUTO_FILTER_FRACTION = 0.75
LNA_GAIN_RANGE_DB, LNA_GAIN_STEP_DB = (0, 40), 8
VGA_GAIN_RANGE_DB, VGA_GAIN_STEP_DB = (0, 62), 2
TXVGA_GAIN_RANGE_DB = (0, 47)
M0_STATE_FORMAT = "<HHIIIIIIIII"  # 40 bytes
PARTID_SERIAL_FORMAT = "<2I4I"  # 24 bytes


@dataclass(frozen=True)
class ControlRequest:
    """One vendor control transfer exactly as sent.

    Attributes:
        request_type: bmRequestType (0x40 OUT or 0xC0 IN).
        request: bRequest (the vendor request number).
        value: wValue.
        index: wIndex.
        data: payload bytes for OUT requests (``b""`` when none).
        length: wLength for IN requests (0 for OUT).
    """

    request_type: int
    request: int
    value: int = 0
    index: int = 0
    data: bytes = b""
    length: int = 0

    @property
    def is_in(self) -> bool:
        return bool(self.request_type & 0x80)


def _out(request: int, value: int = 0, index: int = 0, data: bytes = b"") -> ControlRequest:
    return ControlRequest(OUT, request, value, index, bytes(data), 0)


def _in(request: int, value: int = 0, index: int = 0, length: int = 1) -> ControlRequest:
    return ControlRequest(IN, request, value, index, b"", length)


def set_transceiver_mode(mode: int) -> ControlRequest:
    """Request 1: 0 off, 1 receive, 2 transmit."""
    if mode not in TRANSCEIVER_MODES:
        raise ValueError(f"mode must be one of {sorted(TRANSCEIVER_MODES)}, got {mode!r}")
    return _out(SET_TRANSCEIVER_MODE, value=mode)


def sample_rate_params(sample_rate_hz: float) -> tuple[int, int]:
    """``(freq_hz, divider)`` for request 6: the smallest divider 1..31 with fs*divider integer.

    Falls back to divider 1 (fs rounded to 1 Hz) when no divider makes it integral.
    """
    fs = float(sample_rate_hz)
    lo, hi = SAMPLE_RATE_RANGE_HZ
    if not math.isfinite(fs) or not lo <= fs <= hi:
        raise ValueError(f"sample_rate_hz must be in [{lo:g}, {hi:g}] Hz, got {sample_rate_hz!r}")
    for divider in range(1, MAX_DIVIDER + 1):
        scaled = fs * divider
        if abs(scaled - round(scaled)) < 1e-6 * divider:
            return int(round(scaled)), divider
    return int(fs + 0.5), 1


def set_sample_rate(sample_rate_hz: float) -> ControlRequest:
    """Request 6 with payload ``<II`` (freq_hz, divider)."""
    freq_hz, divider = sample_rate_params(sample_rate_hz)
    return _out(SAMPLE_RATE_SET, data=struct.pack("<II", freq_hz, divider))


def baseband_filter_round_down(bandwidth_hz: float) -> int:
    """The largest allowed filter <= ``bandwidth_hz`` (the smallest if none), in Hz."""
    allowed = [b for b in BASEBAND_FILTERS_HZ if b <= bandwidth_hz + 1e-6]
    return allowed[-1] if allowed else BASEBAND_FILTERS_HZ[0]


def auto_baseband_filter_hz(sample_rate_hz: float) -> int:
    """The filter libhackrf sets after a sample rate: largest allowed <= 0.75 * Fs."""
    return baseband_filter_round_down(AUTO_FILTER_FRACTION * float(sample_rate_hz))


def set_baseband_filter(bandwidth_hz: int) -> ControlRequest:
    """Request 7: wValue = bw & 0xffff, wIndex = bw >> 16; only the listed values."""
    bw = int(bandwidth_hz)
    if bw not in BASEBAND_FILTERS_HZ:
        raise ValueError(
            f"baseband_filter_hz must be one of {[b / 1e6 for b in BASEBAND_FILTERS_HZ]} MHz, got "
            f"{bandwidth_hz!r}"
        )
    return _out(BASEBAND_FILTER_BANDWIDTH_SET, value=bw & 0xFFFF, index=bw >> 16)


def set_frequency(center_freq_hz: float) -> ControlRequest:
    """Request 16 with payload ``<II`` (f // 1e6, f % 1e6); f rounded to 1 Hz."""
    f = float(center_freq_hz)
    lo, hi = FREQ_RANGE_HZ
    if not math.isfinite(f) or not lo <= f <= hi:
        raise ValueError(f"center_freq_hz must be in [{lo:g}, {hi:g}] Hz, got {center_freq_hz!r}")
    fi = int(round(f))
    return _out(SET_FREQ, data=struct.pack("<II", fi // 1_000_000, fi % 1_000_000))


def set_amp_enable(enabled: bool) -> ControlRequest:
    """Request 17: RF amplifier on (1) or off (0)."""
    return _out(AMP_ENABLE, value=int(bool(enabled)))


def set_antenna_enable(enabled: bool) -> ControlRequest:
    """Request 23: antenna port power (bias tee) on (1) or off (0)."""
    return _out(ANTENNA_ENABLE, value=int(bool(enabled)))


def set_hw_sync_mode(enabled: bool) -> ControlRequest:
    """Request 29: hardware trigger sync (hackrf_transfer always sends 0)."""
    return _out(SET_HW_SYNC_MODE, value=int(bool(enabled)))


def _check_gain(name: str, gain_db: float, lo: int, hi: int) -> float:
    g = float(gain_db)
    if not math.isfinite(g) or not lo <= g <= hi:
        raise ValueError(f"{name} must be in [{lo}, {hi}] dB, got {gain_db!r}")
    return g


def quantize_lna_gain_db(gain_db: float) -> int:
    """LNA (RX IF) gain rounded down to a multiple of 8 dB in [0, 40]."""
    g = _check_gain("lna_gain_db", gain_db, *LNA_GAIN_RANGE_DB)
    return int(g // LNA_GAIN_STEP_DB) * LNA_GAIN_STEP_DB


def quantize_vga_gain_db(gain_db: float) -> int:
    """VGA (RX baseband) gain rounded down to an even value in [0, 62]."""
    g = _check_gain("vga_gain_db", gain_db, *VGA_GAIN_RANGE_DB)
    return int(g // VGA_GAIN_STEP_DB) * VGA_GAIN_STEP_DB


def quantize_txvga_gain_db(gain_db: float) -> int:
    """TX VGA gain rounded down to 1 dB in [0, 47]."""
    return int(_check_gain("txvga_gain_db", gain_db, *TXVGA_GAIN_RANGE_DB))


def set_lna_gain(gain_db: float) -> ControlRequest:
    """Request 19 (IN, 1 byte): gain in wIndex, rounded down to a multiple of 8."""
    return _in(SET_LNA_GAIN, index=quantize_lna_gain_db(gain_db), length=1)


def set_vga_gain(gain_db: float) -> ControlRequest:
    """Request 20 (IN, 1 byte): gain in wIndex, rounded down to even."""
    return _in(SET_VGA_GAIN, index=quantize_vga_gain_db(gain_db), length=1)


def set_txvga_gain(gain_db: float) -> ControlRequest:
    """Request 21 (IN, 1 byte): gain in wIndex, 0-47 dB."""
    return _in(SET_TXVGA_GAIN, index=quantize_txvga_gain_db(gain_db), length=1)


def read_board_id() -> ControlRequest:
    return _in(BOARD_ID_READ, length=1)


def read_version_string() -> ControlRequest:
    return _in(VERSION_STRING_READ, length=255)


def read_partid_serial() -> ControlRequest:
    return _in(BOARD_PARTID_SERIALNO_READ, length=struct.calcsize(PARTID_SERIAL_FORMAT))


def read_m0_state() -> ControlRequest:
    return _in(GET_M0_STATE, length=struct.calcsize(M0_STATE_FORMAT))


@dataclass(frozen=True)
class M0State:
    """The M0 core's streaming state (request 41): mode, byte counters and shortfalls.

    ``num_shortfalls`` counts receive overruns (RX) or transmit underruns (TX).
    """

    requested_mode: int
    request_flag: int
    active_mode: int
    m0_count: int
    m4_count: int
    num_shortfalls: int
    longest_shortfall: int
    shortfall_limit: int
    threshold: int
    next_mode: int
    error: int

    @classmethod
    def unpack(cls, payload: bytes) -> M0State:
        size = struct.calcsize(M0_STATE_FORMAT)
        if len(payload) != size:
            raise ValueError(f"M0 state must be {size} bytes, got {len(payload)}")
        return cls(*struct.unpack(M0_STATE_FORMAT, bytes(payload)))

    def pack(self) -> bytes:
        return struct.pack(M0_STATE_FORMAT, *(getattr(self, f) for f in self.__dataclass_fields__))


def parse_partid_serial(payload: bytes) -> tuple[tuple[int, int], str]:
    """``((part_id_0, part_id_1), serial)`` from request 18's 24 bytes; serial as 32 hex chars."""
    if len(payload) != struct.calcsize(PARTID_SERIAL_FORMAT):
        raise ValueError(f"part id / serial must be 24 bytes, got {len(payload)}")
    words = struct.unpack(PARTID_SERIAL_FORMAT, bytes(payload))
    return (words[0], words[1]), "".join(f"{w:08x}" for w in words[2:])


def usb_api_version_string(bcd_device: int) -> str:
    """``0x0108`` -> ``"1.08"``, as hackrf_info prints it."""
    return f"{(bcd_device >> 8) & 0xFF:x}.{bcd_device & 0xFF:02x}"

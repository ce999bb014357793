"""SoapyRemote's wire formats, written from its specification (pothosware/SoapyRemote 0.5:
``common/SoapyRemoteDefs.hpp``, ``SoapyRPCPacker.cpp``, ``SoapyRPCUnpacker.cpp``,
``SoapyStreamEndpoint.cpp``).

RPC over TCP: one message is a 12-byte header (``"SRPC"``, protocol version, total length,
big-endian 32-bit words), typed values, and the 4-byte trailer ``"CPRS"``. Each value is a
type byte (:class:`T`) then its body, integers big-endian: a 32-bit int, a 64-bit int, a
double as ``frexp``'s exponent (int) and 53-bit mantissa (int64), a string as its length
(int) and bytes, a range as two or three doubles (minimum, maximum, step), lists as a count
(int) and their items. A call is ``T.CALL`` and its number (:class:`Call`); a reply with no
value is ``T.VOID``, an error ``T.EXCEPTION`` and a message.

Streams over UDP: each datagram starts with :data:`DATAGRAM_HEADER` (bytes, sequence,
elements or a negative error code, flags, time in ns); the receiving side acknowledges with
a bare header whose ``sequence`` is the next one it expects and whose ``elems`` is how many
datagrams may be in flight (flow control).
"""

from __future__ import annotations

import math
import struct
from enum import IntEnum

HEADER_WORD = b"SRPC"
TRAILER_WORD = b"CPRS"
RPC_VERSION = 0x000400  # the version whose ranges carry a step
DEFAULT_PORT = 55132
DATAGRAM_HEADER = struct.Struct(">IIiiq")  # bytes, sequence, elems or error, flags, time_ns
DEFAULT_MTU = 1500
PROTO_HEADER_BYTES = 40 + 8  # IPv6 + UDP: what SoapyRemote subtracts from the MTU
_MANTISSA_BITS = 53


class T(IntEnum):
    """Type bytes of packed values."""

    CHAR = 0
    BOOL = 1
    INT32 = 2
    INT64 = 3
    FLOAT64 = 4
    COMPLEX128 = 5
    STRING = 6
    RANGE = 7
    RANGE_LIST = 8
    STRING_LIST = 9
    FLOAT64_LIST = 10
    KWARGS = 11
    KWARGS_LIST = 12
    EXCEPTION = 13
    VOID = 14
    CALL = 15
    SIZE_LIST = 16
    ARG_INFO = 17
    ARG_INFO_LIST = 18


class Call(IntEnum):
    """The calls an emulated device answers (any other is answered with an exception)."""

    FIND = 0
    MAKE = 1
    UNMAKE = 2
    HANGUP = 3
    GET_SERVER_ID = 20
    START_LOG_FORWARDING = 21
    STOP_LOG_FORWARDING = 22
    GET_DRIVER_KEY = 100
    GET_HARDWARE_KEY = 101
    GET_HARDWARE_INFO = 102
    GET_NUM_CHANNELS = 202
    GET_FULL_DUPLEX = 203
    SETUP_STREAM = 300
    CLOSE_STREAM = 301
    ACTIVATE_STREAM = 302
    DEACTIVATE_STREAM = 303
    GET_STREAM_FORMATS = 304
    GET_NATIVE_STREAM_FORMAT = 305
    GET_STREAM_ARGS_INFO = 306
    LIST_ANTENNAS = 500
    SET_ANTENNA = 501
    GET_ANTENNA = 502
    LIST_GAINS = 700
    SET_GAIN_MODE = 701
    GET_GAIN_MODE = 702
    SET_GAIN = 703
    GET_GAIN = 705
    GET_GAIN_RANGE = 707
    HAS_GAIN_MODE = 709
    SET_FREQUENCY = 800
    GET_FREQUENCY = 802
    LIST_FREQUENCIES = 804
    GET_FREQUENCY_RANGE = 805
    SET_SAMPLE_RATE = 900
    GET_SAMPLE_RATE = 901
    LIST_SAMPLE_RATES = 902
    GET_SAMPLE_RATE_RANGE = 907
    SET_BANDWIDTH = 903
    GET_BANDWIDTH = 904
    GET_BANDWIDTH_RANGE = 906
    WRITE_SETTING = 1400
    READ_SETTING = 1401
    GET_SETTING_INFO = 1402


class Range(tuple):
    """A SoapySDR range: ``(minimum, maximum, step)``."""

    def __new__(cls, minimum: float, maximum: float, step: float = 0.0):
        return super().__new__(cls, (float(minimum), float(maximum), float(step)))


class Packer:
    """Typed values into one message (:meth:`message`)."""

    def __init__(self, version: int = RPC_VERSION):
        self.version = version
        self.body = bytearray()

    def _type(self, t: T) -> None:
        self.body.append(int(t))

    def call(self, call: int) -> Packer:
        self._type(T.CALL)
        return self.int32(int(call))

    def void(self) -> Packer:
        self._type(T.VOID)
        return self

    def char(self, value: int) -> Packer:
        self._type(T.CHAR)
        self.body += struct.pack(">b", value)
        return self

    def bool(self, value: bool) -> Packer:
        self._type(T.BOOL)
        self.body.append(1 if value else 0)
        return self

    def int32(self, value: int) -> Packer:
        self._type(T.INT32)
        self.body += struct.pack(">i", value)
        return self

    def int64(self, value: int) -> Packer:
        self._type(T.INT64)
        self.body += struct.pack(">q", value)
        return self

    def float64(self, value: float) -> Packer:
        self._type(T.FLOAT64)
        mantissa, exponent = math.frexp(float(value))
        self.int32(exponent)
        return self.int64(int(math.ldexp(mantissa, _MANTISSA_BITS)))

    def string(self, value: str) -> Packer:
        raw = value.encode()
        self._type(T.STRING)
        self.int32(len(raw))
        self.body += raw
        return self

    def range(self, value: tuple) -> Packer:
        self._type(T.RANGE)
        self.float64(value[0]).float64(value[1])
        if self.version >= RPC_VERSION:
            self.float64(value[2] if len(value) > 2 else 0.0)
        return self

    def range_list(self, values: list) -> Packer:
        self._type(T.RANGE_LIST)
        self.int32(len(values))
        for v in values:
            self.range(v)
        return self

    def string_list(self, values: list) -> Packer:
        self._type(T.STRING_LIST)
        self.int32(len(values))
        for v in values:
            self.string(v)
        return self

    def float64_list(self, values: list) -> Packer:
        self._type(T.FLOAT64_LIST)
        self.int32(len(values))
        for v in values:
            self.float64(v)
        return self

    def kwargs(self, value: dict) -> Packer:
        self._type(T.KWARGS)
        self.int32(len(value))
        for k, v in sorted(value.items()):
            self.string(k).string(v)
        return self

    def kwargs_list(self, values: list) -> Packer:
        self._type(T.KWARGS_LIST)
        self.int32(len(values))
        for v in values:
            self.kwargs(v)
        return self

    def arg_info_list(self, infos: list[dict]) -> Packer:
        """Each info: key, value, name, description, units, type (int), range, options."""
        self._type(T.ARG_INFO_LIST)
        self.int32(len(infos))
        for a in infos:
            self._type(T.ARG_INFO)
            for k in ("key", "value", "name", "description", "units"):
                self.string(a.get(k, ""))
            self.int32(a.get("type", 3)).range(a.get("range", Range(0, 0)))
            self.string_list(a.get("options", [])).string_list(a.get("option_names", []))
        return self

    def exception(self, message: str) -> Packer:
        self._type(T.EXCEPTION)
        return self.string(message)

    def message(self) -> bytes:
        """Header, values, trailer: the bytes on the wire."""
        n = 12 + len(self.body) + 4
        return HEADER_WORD + struct.pack(">II", RPC_VERSION, n) + bytes(self.body) + TRAILER_WORD


class Unpacker:
    """Typed values out of one message's payload (between header and trailer).

    Raises:
        ValueError: a value of another type than the one asked for, or past the end.
    """

    def __init__(self, payload: bytes, version: int = RPC_VERSION):
        self.data = memoryview(payload)
        self.offset = 0
        self.version = version

    @property
    def done(self) -> bool:
        return self.offset == len(self.data)

    def peek(self) -> T | None:
        return None if self.done else T(self.data[self.offset])

    def _take(self, n: int) -> bytes:
        if self.offset + n > len(self.data):
            raise ValueError("SoapyRemote message: read past its end")
        out = bytes(self.data[self.offset : self.offset + n])
        self.offset += n
        return out

    def _expect(self, t: T) -> None:
        got = self._take(1)[0]
        if got != t:
            raise ValueError(f"SoapyRemote message: expected {t.name}, got type {got}")

    def call(self) -> int:
        self._expect(T.CALL)
        return self.int32()

    def char(self) -> int:
        self._expect(T.CHAR)
        return struct.unpack(">b", self._take(1))[0]

    def bool(self) -> bool:
        self._expect(T.BOOL)
        return self._take(1) != b"\0"

    def int32(self) -> int:
        self._expect(T.INT32)
        return struct.unpack(">i", self._take(4))[0]

    def int64(self) -> int:
        self._expect(T.INT64)
        return struct.unpack(">q", self._take(8))[0]

    def float64(self) -> float:
        self._expect(T.FLOAT64)
        exponent = self.int32()
        return math.ldexp(float(self.int64()), exponent - _MANTISSA_BITS)

    def string(self) -> str:
        self._expect(T.STRING)
        return self._take(self.int32()).decode()

    def range(self) -> Range:
        self._expect(T.RANGE)
        lo, hi = self.float64(), self.float64()
        return Range(lo, hi, self.float64() if self.version >= RPC_VERSION else 0.0)

    def string_list(self) -> list[str]:
        self._expect(T.STRING_LIST)
        return [self.string() for _ in range(self.int32())]

    def size_list(self) -> list[int]:
        self._expect(T.SIZE_LIST)
        return [self.int32() for _ in range(self.int32())]

    def kwargs(self) -> dict[str, str]:
        self._expect(T.KWARGS)
        return {self.string(): self.string() for _ in range(self.int32())}


def split_message(raw: bytes) -> tuple[int, bytes]:
    """``(version, payload)`` of one whole message (header and trailer checked).

    Raises:
        ValueError: not a SoapyRemote message.
    """
    if len(raw) < 16 or raw[:4] != HEADER_WORD:
        raise ValueError("SoapyRemote message: bad header word")
    version, length = struct.unpack(">II", raw[4:12])
    if length != len(raw) or raw[-4:] != TRAILER_WORD:
        raise ValueError("SoapyRemote message: bad length or trailer word")
    return version, raw[12:-4]


def read_message(sock) -> tuple[int, bytes] | None:
    """The next message from a TCP socket as ``(version, payload)``; None when it closed."""
    head = _recv_exactly(sock, 12)
    if head is None:
        return None
    if head[:4] != HEADER_WORD:
        raise ValueError("SoapyRemote message: bad header word")
    length = struct.unpack(">I", head[8:12])[0]
    if length <= 16:
        raise ValueError("SoapyRemote message: bad length")
    rest = _recv_exactly(sock, length - 12)
    if rest is None:
        return None
    return split_message(head + rest)


def _recv_exactly(sock, n: int) -> bytes | None:
    buf = bytearray()
    while len(buf) < n:
        chunk = sock.recv(n - len(buf))
        if not chunk:
            return None
        buf += chunk
    return bytes(buf)


def datagram(sequence: int, elems: int, payload: bytes = b"", flags: int = 0, time_ns: int = 0):
    """One stream datagram: :data:`DATAGRAM_HEADER` then ``payload`` (``elems`` < 0: an
    error code and no payload)."""
    n = DATAGRAM_HEADER.size + len(payload)
    return DATAGRAM_HEADER.pack(n, sequence & 0xFFFFFFFF, elems, flags, time_ns) + payload


def elems_per_datagram(mtu: int, elem_bytes: int, num_channels: int = 1) -> int:
    """Samples one datagram carries at ``mtu`` bytes (what SoapyRemote fills)."""
    return ((mtu - PROTO_HEADER_BYTES - DATAGRAM_HEADER.size) // num_channels) // elem_bytes

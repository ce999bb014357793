"""iiod's network protocol (libiio 0.x, TCP port 30431), served for an emulated Pluto.

A plain-text protocol: one command per line, answered by an integer line (a length, or a
negative errno) and then any payload. The commands libiio 0.24's network backend sends::

    VERSION                         -> "0.24.<7-char tag>"
    PRINT                           -> length, the context XML, "\\n"
    TIMEOUT ms                      -> 0
    READ dev [INPUT|OUTPUT chn] [DEBUG|BUFFER] attr          -> length, value, "\\n"
    WRITE dev [INPUT|OUTPUT chn] [DEBUG|BUFFER] attr len     (then len bytes) -> bytes written
    OPEN dev samples mask [CYCLIC]  -> 0          CLOSE dev -> 0
    READBUF dev bytes               -> length, mask line, data (repeated until bytes sent)
    WRITEBUF dev bytes              -> bytes, (then the data) -> bytes written
    GETTRIG dev                     -> -ENOENT (no trigger)    SETTRIG dev [trig] -> 0
    SET dev BUFFERS_COUNT n         -> 0                        EXIT

Each client connection is served on its own thread (libiio opens a new connection for each
buffer). The server listens on the loopback range only (127.0.0.0/8).
"""

from __future__ import annotations

import errno
import ipaddress
import socket
import socketserver
import threading

import numpy as np

from hil.emulation.air import prepare_resampler
from hil.emulation.pacing import KERNEL_BUFFERS
from hil.emulation.pluto import EmulatedPluto
from hil.pluto.context import RX_DEV, TX_DEV

IIOD_PORT = 30431
VERSION_LINE = b"0.24.osnerf0\n"
READ_CHUNK_SAMPLES = 1 << 13  # rendered (and paced) in pieces of about 2 ms at 4 MS/s


class _Handler(socketserver.StreamRequestHandler):
    server: IiodServer

    def setup(self):
        self.request.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)  # no 40 ms stalls
        super().setup()
        self.opened: dict[str, dict] = {}
        self.buffers_count: dict[str, int] = {}  # SET dev BUFFERS_COUNT n (libiio's default: 4)
        self.server.track(self.connection, True)

    def finish(self):
        for dev in list(self.opened):
            self._close(dev)
        self.server.track(self.connection, False)
        try:
            super().finish()
        except OSError:
            pass

    def _send(self, data: bytes) -> None:
        self.wfile.write(data)
        self.wfile.flush()

    def _int(self, value: int) -> None:
        self._send(f"{int(value)}\n".encode())

    def handle(self):
        while not self.server.stopping.is_set():
            try:
                line = self.rfile.readline()
            except OSError:
                return
            if not line:
                return
            words = line.decode("ascii", "replace").split()
            if not words:
                continue
            cmd, args = words[0].upper(), words[1:]
            if cmd == "EXIT":
                return
            try:
                if not self._dispatch(cmd, args):
                    return
            except OSError as e:
                if isinstance(e, (BrokenPipeError, ConnectionError)):
                    return
                self._int(-(e.errno or errno.EIO))
            except (ValueError, IndexError):
                self._int(-errno.EINVAL)

    # ------------------------------------------------------------------ commands
    def _dispatch(self, cmd: str, args: list[str]) -> bool:
        board = self.server.board
        if cmd == "VERSION":
            self._send(VERSION_LINE)
        elif cmd == "PRINT":
            xml = self.server.xml
            self._send(f"{len(xml)}\n".encode() + xml + b"\n")
        elif cmd == "TIMEOUT":
            int(args[0])
            self._int(0)
        elif cmd in ("READ", "WRITE"):
            dev, chan, output, kind, attr, rest = _attr_address(args, cmd == "WRITE")
            if cmd == "READ":
                value = board.read_attr(dev, chan, output, kind, attr).encode() + b"\0"
                self._send(f"{len(value)}\n".encode() + value + b"\n")
            else:
                n = int(rest[0])
                data = self.rfile.read(n)
                if len(data) < n:
                    return False
                board.write_attr(dev, chan, output, kind, attr, data.rstrip(b"\0").decode())
                self._int(n)
        elif cmd == "OPEN":
            dev, samples, mask = args[0], int(args[1]), args[2]
            cyclic = len(args) > 3 and args[3].upper() == "CYCLIC"
            if dev not in (RX_DEV, TX_DEV) or samples <= 0:
                raise OSError(errno.EINVAL, "no buffer on this device")
            enabled = int(mask, 16) & 0x3
            if enabled == 0:
                raise OSError(errno.EINVAL, "no channel enabled")
            if dev == RX_DEV:  # the DMA blocks of this buffer's size
                board.open_rx(samples, self.buffers_count.get(dev, KERNEL_BUFFERS))
            else:
                board.open_tx(cyclic)
            self.opened[dev] = {"mask": mask, "enabled": enabled}
            self._int(0)
        elif cmd == "CLOSE":
            self._close(args[0])
            self._int(0)
        elif cmd == "READBUF":
            return self._readbuf(args[0], int(args[1]))
        elif cmd == "WRITEBUF":
            return self._writebuf(args[0], int(args[1]))
        elif cmd == "GETTRIG":
            self._int(-errno.ENOENT)
        elif cmd == "SET" and len(args) == 3 and args[1].upper() == "BUFFERS_COUNT":
            count = int(args[2])
            if count <= 0:
                raise OSError(errno.EINVAL, "BUFFERS_COUNT must be > 0")
            self.buffers_count[args[0]] = count
            self._int(0)
        elif cmd in ("SETTRIG", "SET"):
            self._int(0)
        else:
            self._int(-errno.EINVAL)
        return True

    def _close(self, dev: str) -> None:
        if self.opened.pop(dev, None) is None:
            return
        if dev == RX_DEV:
            self.server.board.close_rx()
        elif dev == TX_DEV:
            self.server.board.close_tx()

    def _readbuf(self, dev: str, num_bytes: int) -> bool:
        st = self.opened.get(dev)
        if dev != RX_DEV or st is None:
            self._int(-errno.EBADF)
            return True
        per_sample = 2 * bin(st["enabled"]).count("1")
        mask_line = st["mask"][-8:].encode() + b"\n"
        first = True
        left = num_bytes // per_sample
        while left > 0:
            n = min(left, READ_CHUNK_SAMPLES)
            iq = self.server.board.read_rx(n)
            if iq is None:  # the board drops the connection (killed mid-capture)
                self.server.drop()
                return False
            n = len(iq) // 2
            if st["enabled"] != 0x3:
                iq = iq[0::2] if st["enabled"] == 0x1 else iq[1::2]
            payload = iq.astype("<i2").tobytes()
            self._send(f"{len(payload)}\n".encode() + (mask_line if first else b"") + payload)
            first = False
            left -= n
        return True

    def _writebuf(self, dev: str, num_bytes: int) -> bool:
        st = self.opened.get(dev)
        if dev != TX_DEV or st is None:
            self._int(-errno.EBADF)
            return True
        self._int(num_bytes)
        data = self.rfile.read(num_bytes)
        if len(data) < num_bytes:
            return False
        raw = np.frombuffer(data, "<i2")
        if st["enabled"] != 0x3:  # one channel: the other DAC input is 0
            full = np.zeros(2 * len(raw), np.int16)
            full[0 if st["enabled"] == 0x1 else 1 :: 2] = raw
            raw = full
        self.server.board.write_tx(raw)
        self._int(num_bytes)
        return True


def _attr_address(args: list[str], write: bool):
    """``dev [INPUT|OUTPUT chn] [DEBUG|BUFFER] attr [len]`` -> its parts."""
    dev, rest = args[0], args[1:]
    chan, output, kind = None, False, ""
    if rest and rest[0].upper() in ("INPUT", "OUTPUT"):
        output, chan, rest = rest[0].upper() == "OUTPUT", rest[1], rest[2:]
    if rest and rest[0].upper() in ("DEBUG", "BUFFER") and len(rest) > (2 if write else 1):
        kind, rest = rest[0].upper(), rest[1:]
    return dev, chan, output, kind, rest[0], rest[1:]


class IiodServer(socketserver.ThreadingTCPServer):
    """iiod's network protocol for one :class:`hil.EmulatedPluto`.

    Args:
        board: the emulated board.
        address: a loopback IPv4 address (127.0.0.0/8).
        port: TCP port (0: any free one; see ``port`` after construction).

    Use as a context manager (``serve_in_background()`` starts a thread), or call
    ``serve_forever()`` in the foreground.
    """

    daemon_threads = True
    allow_reuse_address = True

    def __init__(self, board: EmulatedPluto, address: str = "127.0.0.1", port: int = IIOD_PORT):
        try:
            ip = ipaddress.ip_address(address)
        except ValueError:
            raise ValueError(f"address must be an IPv4 loopback address, got {address!r}") from None
        if ip.version != 4 or not ip.is_loopback:
            raise ValueError(f"address must be in 127.0.0.0/8 (loopback), got {address!r}")
        if not 0 <= int(port) <= 65535:
            raise ValueError(f"port must be in [0, 65535], got {port!r}")
        prepare_resampler()  # the board's first receive is as quick as the rest
        self.board = board
        self.xml = board.context_xml().encode()
        self.stopping = threading.Event()
        self._conns: set = set()
        self._conn_lock = threading.Lock()
        self._thread: threading.Thread | None = None
        super().__init__((address, int(port)), _Handler)

    @property
    def address(self) -> str:
        return str(self.server_address[0])

    @property
    def port(self) -> int:
        return self.server_address[1]

    @property
    def uri(self) -> str:
        """libiio's URI of this server, ``ip:ADDRESS:PORT``."""
        return f"ip:{self.address}:{self.port}"

    def track(self, conn, add: bool) -> None:
        with self._conn_lock:
            (self._conns.add if add else self._conns.discard)(conn)

    def drop(self) -> None:
        """Close every connection abruptly, as a board that died would."""
        self.stopping.set()
        with self._conn_lock:
            conns = list(self._conns)
        for c in conns:
            try:
                c.shutdown(socket.SHUT_RDWR)
                c.close()
            except OSError:
                pass

    def serve_in_background(self) -> IiodServer:
        self._thread = threading.Thread(target=self.serve_forever, name="iiod", daemon=True)
        self._thread.start()
        return self

    def close(self) -> None:
        self.drop()
        self.shutdown() if self._thread is not None else None
        self.server_close()

    def __enter__(self) -> IiodServer:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


__all__ = ["IIOD_PORT", "IiodServer"]

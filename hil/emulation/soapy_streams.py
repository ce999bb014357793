"""SoapyRemote's UDP streams of an emulated device: a receive stream sends the board's samples
in datagrams within the window the client acknowledges (an overflow as a datagram carrying
``SOAPY_SDR_OVERFLOW`` instead of elements); a transmit stream acknowledges the client's
datagrams and writes their samples to the board, a datagram flagged ``END_BURST`` ending
the burst, and reports the board's underruns on the status socket as
``SOAPY_SDR_UNDERFLOW``. :class:`hil.emulation.soapy_remote.SoapyRemoteServer` makes them.
"""

from __future__ import annotations

import select
import socket
import threading

import numpy as np

from hil.emulation.soapy_device import RX
from hil.emulation.soapy_rpc import DATAGRAM_HEADER, DEFAULT_MTU, datagram, elems_per_datagram

OVERFLOW, UNDERFLOW = -4, -7  # SOAPY_SDR_OVERFLOW, SOAPY_SDR_UNDERFLOW
END_BURST, HAS_TIME = 1 << 1, 1 << 2
NUM_BUFFS = 8  # SoapyRemote acknowledges every window / NUM_BUFFS datagrams
POLL_S = 0.05


class Stream:
    """One stream's datagram sockets, connected to the ports the client bound."""

    def __init__(self, server, direction: int, host: str, args: dict, ports):
        self.server = server
        self.device = server.device
        self.direction = direction
        self.mtu = int(float(args.get("remote:mtu", DEFAULT_MTU)))
        self.elems = elems_per_datagram(self.mtu, 4)  # CS16: 4 bytes a sample
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind((server.address, 0))
        self.sock.connect((host, int(ports[0])))
        self.status = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.status.connect((host, int(ports[1])))
        self.active = threading.Event()
        self.closed = threading.Event()
        self.thread = threading.Thread(target=self._run, name="soapy-stream", daemon=True)

    @property
    def port(self) -> int:
        return self.sock.getsockname()[1]

    def activate(self) -> None:
        self.active.set()

    def deactivate(self) -> None:
        self.active.clear()

    def close(self) -> None:
        self.active.clear()
        self.closed.set()
        if self.thread.is_alive() and self.thread is not threading.current_thread():
            self.thread.join(timeout=5)
        self.sock.close()
        self.status.close()

    def _run(self) -> None:
        raise NotImplementedError


class RxStream(Stream):
    """Board -> client: samples in datagrams within the client's flow-control window."""

    def __init__(self, *a, **k):
        super().__init__(*a, **k)
        self.sequence = 0
        self.acked = 0  # the next sequence the client expects
        self.window = 0  # datagrams the client lets be in flight (0 until its first ACK)
        self.opened = False
        self.sent_samples = 0

    def activate(self) -> None:
        with self.device.lock:
            if not self.opened:
                self.device.open_rx()
                self.opened = True
        super().activate()

    def deactivate(self) -> None:
        super().deactivate()
        with self.device.lock:
            if self.opened:
                self.device.board.close_rx()
                self.opened = False

    def close(self) -> None:
        self.deactivate()
        super().close()

    def _acks(self, timeout: float) -> None:
        ready, _, _ = select.select([self.sock], [], [], timeout)
        while ready:
            try:
                raw = self.sock.recv(2048)
            except OSError:
                return
            if len(raw) >= DATAGRAM_HEADER.size:
                _, seq, elems, _, _ = DATAGRAM_HEADER.unpack_from(raw)
                self.acked, self.window = seq, elems
            ready, _, _ = select.select([self.sock], [], [], 0)

    def _room(self) -> int:
        return self.window - ((self.sequence - self.acked) & 0xFFFFFFFF)

    def _run(self) -> None:
        while not self.closed.is_set():
            self._acks(0 if self.active.is_set() else POLL_S)
            if not self.active.is_set():
                continue
            room = self._room()
            if room <= 0:
                self._acks(POLL_S)
                continue
            n = self.elems * min(room, 32)
            try:
                raw, overflowed = self.device.read(n)
            except OSError:  # deactivated while the board waited
                continue
            if overflowed:
                self._send(OVERFLOW, b"", 0)
            if raw is None:  # the board died
                self.server.drop()
                return
            flags = HAS_TIME
            t_ns = int(self.sent_samples * 1e9 / self.device.sample_rate(RX))
            payload = raw.astype("<i2").tobytes()
            step = 4 * self.elems
            for start in range(0, len(payload), step):
                part = payload[start : start + step]
                self._send(len(part) // 4, part, flags, t_ns)
            self.sent_samples += len(raw) // 2

    def _send(self, elems: int, payload: bytes, flags: int, time_ns: int = 0) -> None:
        try:
            self.sock.send(datagram(self.sequence, elems, payload, flags, time_ns))
        except OSError:
            return
        self.sequence += 1


class TxStream(Stream):
    """Client -> board: acknowledges the client's datagrams and transmits their samples."""

    def __init__(self, *a, **k):
        super().__init__(*a, **k)
        window = int(float(self.server.window_bytes))
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, window)
        got = self.sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)
        self.window = max(1, got // self.mtu)
        self.trigger = max(1, self.window // NUM_BUFFS)
        self.expected = 0
        self.last_ack = 0
        self.underruns = self.device.board.tx_underruns
        self.pending: list = []
        self.drain_request = threading.Event()  # deactivation asked: take what arrived first
        self.drain = threading.Event()
        self._ack()  # a gratuitous first ACK: the client may send

    def _ack(self) -> None:
        try:
            self.sock.send(datagram(self.expected, self.window))
        except OSError:
            pass
        self.last_ack = self.expected

    def deactivate(self) -> None:
        """Play out what the client sent before the call, then end the burst."""
        self.drain.clear()
        self.drain_request.set()
        if self.thread.is_alive():
            self.drain.wait(timeout=5)
        super().deactivate()

    def close(self) -> None:
        self.deactivate()
        super().close()

    def _flush(self) -> None:
        pending, self.pending = self.pending, []
        if pending:
            with self.device.lock:
                self.device.write(np.concatenate(pending))

    def _end_burst(self) -> None:
        self._flush()
        with self.device.lock:
            self.device.end_burst()
        try:  # the burst's acknowledgement, as a USRP reports it
            self.status.send(datagram(1, 0, flags=END_BURST))
        except OSError:
            pass

    def _run(self) -> None:
        have = 0
        while not self.closed.is_set():
            draining = self.drain_request.is_set()
            wait = 0 if (self.pending or draining) else POLL_S
            ready, _, _ = select.select([self.sock], [], [], wait)
            if not ready:
                if draining:  # every datagram sent before the deactivation is in
                    self.drain_request.clear()
                    if self.pending or self.device.board.tx_open:
                        self._end_burst()
                    self.drain.set()
                self._flush()
                have = 0
                self._report_underruns()
                continue
            try:
                raw = self.sock.recv(65536)
            except OSError:
                return
            if len(raw) < DATAGRAM_HEADER.size:
                continue
            _, seq, elems, flags, _ = DATAGRAM_HEADER.unpack_from(raw)
            self.expected = (seq + 1) & 0xFFFFFFFF
            if ((self.expected - self.last_ack) & 0xFFFFFFFF) >= self.trigger:
                self._ack()
            if elems > 0:
                body = raw[DATAGRAM_HEADER.size : DATAGRAM_HEADER.size + 4 * elems]
                self.pending.append(np.frombuffer(body, "<i2"))
                have += elems
            if flags & END_BURST:
                self._end_burst()
                have = 0
            elif have >= 1 << 15:
                self._flush()
                have = 0

    def _report_underruns(self) -> None:
        n = self.device.board.tx_underruns
        if n > self.underruns:
            self.underruns = n
            status = datagram(1, UNDERFLOW)  # sequence: the channel mask
            try:
                self.status.send(status)
            except OSError:
                pass

"""An emulated device served over SoapyRemote's protocol: :class:`SoapyRemoteServer`.

Real libSoapySDR reaches it through Debian's remote module, as it would reach
``SoapySDRServer`` on another host::

    SoapySDR.Device("driver=remote,remote=tcp://127.0.0.1:55132")

Each TCP connection is served on its own thread: one RPC message in, one reply out
(:mod:`hil.emulation.soapy_rpc`), a ``HANGUP`` ends it. ``SETUP_STREAM`` (UDP only) binds
a datagram socket, connects it to the port the client bound, and starts the stream's
thread (:mod:`hil.emulation.soapy_streams`).
"""

from __future__ import annotations

import ipaddress
import select
import socket
import threading
import uuid

from hil.emulation.air import prepare_resampler
from hil.emulation.soapy_device import NATIVE_FORMAT, RX, TX, EmulatedSoapyDevice
from hil.emulation.soapy_rpc import DEFAULT_PORT, Call, Packer, Unpacker, read_message
from hil.emulation.soapy_streams import (
    POLL_S,
    RxStream,
    Stream,
    TxStream,
)

_POLL_S = POLL_S


class SoapyRemoteServer:
    """SoapyRemote's server protocol for one :class:`EmulatedSoapyDevice`.

    Args:
        device: the emulated device.
        address: a loopback IPv4 address (127.0.0.0/8).
        port: TCP port (0: any free one; see ``port`` after construction).
        window_bytes: the receive socket buffer a transmit stream asks for (its flow
            control window follows from what the kernel grants).

    Use as a context manager (:meth:`serve_in_background` starts a thread).
    """

    def __init__(
        self,
        device: EmulatedSoapyDevice,
        address: str = "127.0.0.1",
        port: int = DEFAULT_PORT,
        window_bytes: int = 4 << 20,
    ):
        try:
            ip = ipaddress.ip_address(address)
        except ValueError:
            raise ValueError(f"address must be an IPv4 loopback address, got {address!r}") from None
        if ip.version != 4 or not ip.is_loopback:
            raise ValueError(f"address must be in 127.0.0.0/8 (loopback), got {address!r}")
        if not 0 <= int(port) <= 65535:
            raise ValueError(f"port must be in [0, 65535], got {port!r}")
        prepare_resampler()
        self.device = device
        self.window_bytes = window_bytes
        self.server_id = str(uuid.uuid4())
        self.listener = socket.create_server((address, int(port)), reuse_port=False)
        self.stopping = threading.Event()
        self.dropped = threading.Event()
        self._conns: set = set()
        self._streams: set = set()
        self._lock = threading.Lock()
        self._thread: threading.Thread | None = None

    @property
    def address(self) -> str:
        return str(self.listener.getsockname()[0])

    @property
    def port(self) -> int:
        return self.listener.getsockname()[1]

    @property
    def url(self) -> str:
        return f"tcp://{self.address}:{self.port}"

    @property
    def args(self) -> str:
        """The Soapy device string that reaches this server through the remote module."""
        return f"driver=remote,remote={self.url}"

    def serve_in_background(self) -> SoapyRemoteServer:
        self._thread = threading.Thread(target=self._accept, name="soapy-remote", daemon=True)
        self._thread.start()
        return self

    def _accept(self) -> None:
        while not self.stopping.is_set():
            ready, _, _ = select.select([self.listener], [], [], _POLL_S)
            if not ready:
                continue
            try:
                conn, _ = self.listener.accept()
            except OSError:
                return
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            with self._lock:
                self._conns.add(conn)
            threading.Thread(target=self._serve, args=(conn,), daemon=True).start()

    def _serve(self, conn: socket.socket) -> None:
        streams: dict[int, Stream] = {}
        try:
            while not self.stopping.is_set():
                try:
                    msg = read_message(conn)
                except (OSError, ValueError):
                    return
                if msg is None:
                    return
                version, payload = msg
                reply = Packer(version)
                again = True
                try:
                    again = self._handle(Unpacker(payload, version), reply, conn, streams)
                except Exception as e:  # noqa: BLE001 - every refusal goes back to the client
                    reply = Packer(version).exception(str(e))
                try:
                    conn.sendall(reply.message())
                except OSError:
                    return
                if not again:
                    return
        finally:
            for s in streams.values():
                s.close()
                with self._lock:
                    self._streams.discard(s)
            with self._lock:
                self._conns.discard(conn)
            conn.close()

    def _handle(self, u: Unpacker, p: Packer, conn, streams: dict) -> bool:
        """Answer one call; False once the client hangs up."""
        call = u.call()
        if call in (Call.MAKE, Call.UNMAKE, Call.HANGUP):
            if call == Call.MAKE:
                u.kwargs()
            p.void()
            return call != Call.HANGUP
        if call in (
            Call.SETUP_STREAM,
            Call.ACTIVATE_STREAM,
            Call.DEACTIVATE_STREAM,
            Call.CLOSE_STREAM,
        ):
            self._handle_stream(call, u, p, conn, streams)
        elif not (self._handle_device(call, u, p) or self._handle_channel(call, u, p)):
            raise NotImplementedError(f"call {call} is not supported by the emulated device")
        return True

    def _handle_device(self, call, u: Unpacker, p: Packer) -> bool:
        """The device's identity, stream formats and settings; False: not such a call."""
        dev = self.device
        if call == Call.FIND:
            u.kwargs()
            p.kwargs_list(dev.enumerate())
        elif call == Call.GET_SERVER_ID:
            p.string(self.server_id)
        elif call in (Call.START_LOG_FORWARDING, Call.STOP_LOG_FORWARDING):
            p.void()
        elif call == Call.GET_DRIVER_KEY:
            p.string("osnerf")
        elif call == Call.GET_HARDWARE_KEY:
            p.string("AD9363 (emulated)")
        elif call == Call.GET_HARDWARE_INFO:
            p.kwargs(dev.hardware_info())
        elif call == Call.GET_NUM_CHANNELS:
            u.char()
            p.int32(1)
        elif call == Call.GET_FULL_DUPLEX:
            u.char(), u.int32()
            p.bool(True)
        elif call in (Call.GET_STREAM_FORMATS, Call.GET_NATIVE_STREAM_FORMAT):
            direction, _ = u.char(), u.int32()
            if call == Call.GET_STREAM_FORMATS:
                p.string_list([NATIVE_FORMAT])
            else:
                p.string(NATIVE_FORMAT).float64(dev.full_scale(direction))
        elif call == Call.GET_STREAM_ARGS_INFO:
            u.char(), u.int32()
            p.arg_info_list([])
        elif call == Call.GET_SETTING_INFO:
            p.arg_info_list(dev.setting_info())
        elif call == Call.WRITE_SETTING:
            dev.write_setting(u.string(), u.string())
            p.void()
        elif call == Call.READ_SETTING:
            p.string(dev.read_setting(u.string()))
        else:
            return False
        return True

    def _handle_channel(self, call, u: Unpacker, p: Packer) -> bool:
        """A channel's antenna, gain, frequency and sample rate; False: not such a call."""
        dev = self.device
        if call == Call.LIST_ANTENNAS:
            direction, _ = u.char(), u.int32()
            p.string_list(["A" if direction == TX else "A_BALANCED"])
        elif call == Call.GET_ANTENNA:
            direction, _ = u.char(), u.int32()
            p.string("A" if direction == TX else "A_BALANCED")
        elif call == Call.LIST_GAINS:
            direction, _ = u.char(), u.int32()
            p.string_list(["PGA"])
        elif call == Call.HAS_GAIN_MODE:
            u.char(), u.int32()
            p.bool(False)
        elif call == Call.GET_GAIN_MODE:
            u.char(), u.int32()
            p.bool(False)
        elif call == Call.GET_GAIN_RANGE:
            direction, _ = u.char(), u.int32()
            p.range(dev.gain_range(direction))
        elif call == Call.SET_GAIN:
            direction, _, value = u.char(), u.int32(), u.float64()
            dev.set_gain(direction, value)
            p.void()
        elif call == Call.GET_GAIN:
            direction, _ = u.char(), u.int32()
            p.float64(dev.gain(direction))
        elif call == Call.GET_FREQUENCY_RANGE:
            direction, _ = u.char(), u.int32()
            p.range_list(dev.frequency_range(direction))
        elif call == Call.SET_FREQUENCY:
            direction, _, value = u.char(), u.int32(), u.float64()
            u.kwargs()
            dev.set_frequency(direction, value)
            p.void()
        elif call == Call.GET_FREQUENCY:
            direction, _ = u.char(), u.int32()
            p.float64(dev.frequency(direction))
        elif call == Call.GET_SAMPLE_RATE_RANGE:
            direction, _ = u.char(), u.int32()
            p.range_list(dev.sample_rate_range(direction))
        elif call == Call.LIST_SAMPLE_RATES:
            direction, _ = u.char(), u.int32()
            p.float64_list([r[0] for r in dev.sample_rate_range(direction)])
        elif call == Call.SET_SAMPLE_RATE:
            direction, _, value = u.char(), u.int32(), u.float64()
            dev.set_sample_rate(direction, value)
            p.void()
        elif call == Call.GET_SAMPLE_RATE:
            direction, _ = u.char(), u.int32()
            p.float64(dev.sample_rate(direction))
        else:
            return False
        return True

    def _handle_stream(self, call, u: Unpacker, p: Packer, conn, streams: dict) -> None:
        if call == Call.SETUP_STREAM:
            self._setup_stream(u, p, conn, streams)
        elif call in (Call.ACTIVATE_STREAM, Call.DEACTIVATE_STREAM, Call.CLOSE_STREAM):
            stream_id = u.int32()
            stream = streams[stream_id]
            if call == Call.CLOSE_STREAM:
                stream.close()
                with self._lock:
                    self._streams.discard(stream)
                del streams[stream_id]
                p.void()
            else:
                (stream.activate if call == Call.ACTIVATE_STREAM else stream.deactivate)()
                p.int32(0)

    def _setup_stream(self, u: Unpacker, p: Packer, conn, streams: dict) -> None:
        direction = u.char()
        fmt = u.string()
        channels = u.size_list()
        args = u.kwargs()
        ports = (u.string(), u.string())
        if fmt != NATIVE_FORMAT:
            raise ValueError(f"stream format {fmt} is not supported; the device streams CS16")
        if channels not in ([], [0]):
            raise ValueError(f"channels {channels}: the device has one channel each way")
        if args.get("remote:prot", "udp") != "udp":
            raise ValueError("only the udp stream protocol is emulated")
        host = conn.getpeername()[0]
        kind = RxStream if direction == RX else TxStream
        stream = kind(self, direction, host, args, ports)
        stream_id = max(streams, default=-1) + 1
        streams[stream_id] = stream
        with self._lock:
            self._streams.add(stream)
        stream.thread.start()
        p.int32(stream_id).string(str(stream.port))

    def drop(self) -> None:
        """Close every connection and stream abruptly, as a device that died would."""
        self.dropped.set()
        self.stopping.set()
        with self._lock:
            conns, streams = list(self._conns), list(self._streams)
        for s in streams:
            s.active.clear()
            s.closed.set()
        for c in conns:
            try:
                c.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass

    def close(self) -> None:
        self.drop()
        if self._thread is not None:
            self._thread.join(timeout=5)
        self.listener.close()

    def __enter__(self) -> SoapyRemoteServer:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


__all__ = ["SoapyRemoteServer"]

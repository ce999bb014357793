"""The HackRF One driver on pure pyusb (no libhackrf): settings, receive and transmit.

``HackRF.open(serial=None, backend=None)`` finds the device with pyusb (any backend: the
system libusb, or :class:`hil.EmulatorBackend` for tests), claims interface 0 and reads
its identity. One property per knob, with units in the name; setters validate, send the
request and keep the value the firmware actually uses (gains are quantised), readable
back. ``rx`` receives on a dedicated thread in 256 KiB transfers and discards the first
(stale) buffer; ``tx`` pads to 512 bytes, writes the 32 KiB end-of-burst flush and waits
for play-out before switching the radio off. Overruns and underruns are read from the M0
state after each stream.
"""

from __future__ import annotations

import array
import queue
import threading
import time
import warnings
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from hil import protocol as p
from hil.errors import (
    DeviceNotFoundError,
    HilError,
    RequestFailedError,
    StreamError,
    usb_error_to_hil,
)


class UsbTransport:
    """Control and bulk transfers on one pyusb device (claimed interface 0)."""

    def __init__(self, device):
        self.device = device

    def control(self, req: p.ControlRequest, timeout_ms: int = p.CONTROL_TIMEOUT_MS):
        if req.is_in:
            return bytes(
                self.device.ctrl_transfer(
                    req.request_type, req.request, req.value, req.index, req.length, timeout_ms
                )
            )
        return self.device.ctrl_transfer(
            req.request_type,
            req.request,
            req.value,
            req.index,
            req.data if req.data else None,
            timeout_ms,
        )

    def read(self, num_bytes: int, timeout_ms: int) -> np.ndarray:
        buf = array.array("b", bytes(num_bytes))
        n = self.device.read(p.ENDPOINT_RX, buf, timeout_ms)
        return np.frombuffer(buf, dtype=np.int8, count=n)

    def write(self, data: bytes, timeout_ms: int) -> int:
        return self.device.write(p.ENDPOINT_TX, data, timeout_ms)

    def close(self) -> None:
        import usb.util

        try:
            usb.util.release_interface(self.device, p.INTERFACE)
        finally:
            usb.util.dispose_resources(self.device)


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


class _RxThread:
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


def _to_complex(raw: np.ndarray) -> np.ndarray:
    """[2 * num_samples] int8 interleaved I, Q -> [num_samples] complex64, full scale 1.0."""
    return (raw.astype(np.float32) / 128.0).view(np.complex64)


def to_int8_iq(samples: np.ndarray) -> np.ndarray:
    """[num_samples] complex in full scale [-1, 1] -> [2 * num_samples] int8 (round, clip at 127)."""
    x = np.asarray(samples, dtype=np.complex64)
    inter = x.view(np.float32).astype(np.float64) * 128.0
    return np.clip(np.round(inter), -128, 127).astype(np.int8)


def full_scale_samples(samples) -> np.ndarray:
    """Check samples to transmit: [num_samples] or [1, num_samples], finite, |I|, |Q| <= 1.

    Returns:
        [num_samples], as given (complex or real).
    Raises:
        ValueError: naming what is wrong.
    """
    x = np.asarray(samples)
    if x.ndim == 2 and x.shape[0] == 1:
        x = x[0]
    if x.ndim != 1 or x.size == 0:
        raise ValueError(
            f"samples must be [num_samples] or [1, num_samples] complex, got shape {x.shape}"
        )
    if not np.all(np.isfinite(x)):
        raise ValueError("samples must be finite")
    peak = (
        max(np.abs(x.real).max(), np.abs(x.imag).max()) if np.iscomplexobj(x) else np.abs(x).max()
    )
    if peak > 1.0 + 1e-6:
        raise ValueError(f"samples must lie within full scale |I|, |Q| <= 1, peak is {peak:.3f}")
    return x


def find_hackrfs(backend=None) -> list:
    """Every HackRF-family board (pyusb ``Device`` objects) on ``backend`` (None: libusb).

    Raises:
        DeviceNotFoundError: no libusb backend could be loaded.
    """
    import usb.core

    try:
        found = usb.core.find(find_all=True, idVendor=p.VENDOR_ID, backend=backend)
        return [d for d in found if d.idProduct in p.PRODUCT_IDS]
    except usb.core.NoBackendError as e:
        raise DeviceNotFoundError(
            "no libusb backend: install libusb-1.0 (Debian libusb-1.0-0, or pip install libusb-package)"
        ) from e


class HackRF:
    """A HackRF One (real or emulated) behind one property per knob.

    Use ``HackRF.open(serial=None, backend=None)`` as a context manager::

        with HackRF.open() as sdr:
            sdr.sample_rate_hz = 4e6          # also sets the 2.5 MHz baseband filter (<= 0.75 Fs)
            sdr.center_freq_hz = 2.45e9
            sdr.lna_gain_db = 17              # reads back 16 (8 dB steps)
            iq = sdr.rx(400_000)              # [1, 400000] complex64, full scale 1.0

    Quantisation: ``lna_gain_db`` rounds down to 8 dB steps (0-40), ``vga_gain_db`` to
    2 dB (0-62), ``txvga_gain_db`` to 1 dB (0-47); ``baseband_filter_hz`` to the largest
    allowed filter <= the value (1.75-28 MHz); ``center_freq_hz`` to 1 Hz.
    """

    def __init__(
        self,
        transport,
        *,
        serial_number: str,
        usb_api_version: int,
        product: str = "HackRF One",
        configure: bool = True,
        rx_chunk_bytes: int = p.TRANSFER_BYTES,
        rx_queue_chunks: int = 64,
        bulk_timeout_ms: int = 1000,
    ):
        self._t = transport
        self.serial_number = serial_number
        self.usb_api_version = int(usb_api_version)
        self.product = product
        if rx_chunk_bytes <= 0 or rx_chunk_bytes % p.PACKET_BYTES:
            raise ValueError(
                f"rx_chunk_bytes must be a positive multiple of 512, got {rx_chunk_bytes}"
            )
        self.rx_chunk_bytes = int(rx_chunk_bytes)
        self.rx_queue_chunks = int(rx_queue_chunks)
        self.bulk_timeout_ms = int(bulk_timeout_ms)
        self._rx: _RxThread | None = None
        self._pending = np.zeros(0, np.int8)
        self._closed = False
        self.last_stats: StreamStats | None = None
        self.board_id = self._read_board_id()
        self.firmware_version = self._read_version()
        self.part_id, serial_from_board = self._read_partid_serial()
        if not self.serial_number:
            self.serial_number = serial_from_board
        self._sample_rate_hz: float | None = None
        self._baseband_filter_hz: int | None = None
        self._center_freq_hz: int | None = None
        self._lna_gain_db = 0
        self._vga_gain_db = 0
        self._txvga_gain_db = 0
        self._amp_enabled = False
        self._bias_tee_enabled = False
        if configure:
            self.configure()

    # ------------------------------------------------------------------ opening
    @classmethod
    def open(cls, serial: str | None = None, backend=None, **kwargs) -> HackRF:
        """Open the first HackRF (or the one whose serial ends with ``serial``).

        Args:
            serial: full 32-hex-digit serial, or its tail (as ``hackrf_info -d``).
            backend: a pyusb backend (``None``: the system libusb; the emulator for tests).
            **kwargs: passed to the constructor (``configure``, ``rx_chunk_bytes``, ...).
        """
        import usb.core
        import usb.util

        found = find_hackrfs(backend)
        chosen = None
        for dev in found:
            try:
                sn = (dev.serial_number or "").lower()
            except (usb.core.USBError, ValueError) as e:
                raise usb_error_to_hil(e, "read serial number") from e
            if serial is None or sn.endswith(str(serial).lower()):
                chosen = dev
                break
        if chosen is None:
            what = f"with serial ending {serial!r}" if serial else "at all"
            raise DeviceNotFoundError(
                f"no HackRF found {what} ({len(found)} HackRF-family device(s) present)"
            )
        try:
            cfg = chosen.get_active_configuration()
            if cfg.bConfigurationValue != p.CONFIGURATION_VALUE:
                chosen.set_configuration(p.CONFIGURATION_VALUE)
        except usb.core.USBError as e:
            if getattr(e, "errno", None) is None:
                chosen.set_configuration(p.CONFIGURATION_VALUE)
            else:
                raise usb_error_to_hil(e, "set configuration 1") from e
        try:
            usb.util.claim_interface(chosen, p.INTERFACE)
        except usb.core.USBError as e:
            raise usb_error_to_hil(
                e, "claim interface 0 (is another program using the HackRF?)"
            ) from e
        return cls(
            UsbTransport(chosen),
            serial_number=sn,
            usb_api_version=chosen.bcdDevice,
            product=p.PRODUCT_IDS[chosen.idProduct],
            **kwargs,
        )

    def configure(
        self,
        sample_rate_hz: float = 10e6,
        center_freq_hz: float = 2.45e9,
        lna_gain_db: float = 16,
        vga_gain_db: float = 24,
        txvga_gain_db: float = 30,
        amp_enabled: bool = False,
        bias_tee_enabled: bool = False,
    ) -> None:
        """Put the radio in a known state, in hackrf_transfer's order (rate, filter, sync, freq, amp, bias)."""
        self._control(p.set_transceiver_mode(p.MODE_OFF), "set mode off")
        self.sample_rate_hz = sample_rate_hz
        self._control(p.set_hw_sync_mode(False), "hardware sync off")
        self.center_freq_hz = center_freq_hz
        self.amp_enabled = amp_enabled
        self.bias_tee_enabled = bias_tee_enabled
        self._lna_gain_db = p.quantize_lna_gain_db(lna_gain_db)
        self._vga_gain_db = p.quantize_vga_gain_db(vga_gain_db)
        self._txvga_gain_db = p.quantize_txvga_gain_db(txvga_gain_db)

    def close(self) -> None:
        """Stop any stream, switch the radio off, release interface 0."""
        if self._closed:
            return
        self._closed = True
        try:
            if self._rx is not None:
                self.stop_rx()
            self._control(p.set_transceiver_mode(p.MODE_OFF), "set mode off")
        except HilError:
            pass
        finally:
            self._t.close()

    def __enter__(self) -> HackRF:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __repr__(self) -> str:
        return (
            f"HackRF(serial={self.serial_number!r}, board={p.BOARD_IDS.get(self.board_id, self.board_id)!r}, "
            f"firmware={self.firmware_version!r}, sample_rate_hz={self._sample_rate_hz}, "
            f"baseband_filter_hz={self._baseband_filter_hz}, center_freq_hz={self._center_freq_hz}, "
            f"lna_gain_db={self._lna_gain_db}, vga_gain_db={self._vga_gain_db}, "
            f"txvga_gain_db={self._txvga_gain_db}, amp_enabled={self._amp_enabled}, "
            f"bias_tee_enabled={self._bias_tee_enabled})"
        )

    # ------------------------------------------------------------------ requests
    def _control(self, req: p.ControlRequest, what: str):
        import usb.core

        if self._closed and not (req.request == p.SET_TRANSCEIVER_MODE and req.value == p.MODE_OFF):
            raise HilError(f"{what}: the device is closed")
        try:
            return self._t.control(req)
        except usb.core.USBError as e:
            raise usb_error_to_hil(e, what) from e

    def _gain_request(self, req: p.ControlRequest, what: str) -> None:
        reply = self._control(req, what)
        if len(reply) != 1 or reply[0] == 0:
            raise RequestFailedError(
                f"{what}: the device refused gain {req.index} dB (reply {bytes(reply).hex()})"
            )

    def _read_board_id(self) -> int:
        return self._control(p.read_board_id(), "read board id")[0]

    def _read_version(self) -> str:
        return bytes(self._control(p.read_version_string(), "read version")).decode(
            "ascii", "replace"
        )

    def _read_partid_serial(self):
        return p.parse_partid_serial(
            self._control(p.read_partid_serial(), "read part id and serial")
        )

    def _rate_hz(self, what: str) -> float:
        """The sample rate set, for a stream that needs it."""
        if self._sample_rate_hz is None:
            raise HilError(f"{what}: no sample rate set (configure() or set sample_rate_hz)")
        return self._sample_rate_hz

    def m0_state(self) -> p.M0State | None:
        """The M0 streaming state (request 41); None on USB API < 1.06."""
        if self.usb_api_version < p.M0_STATE_MIN_API:
            return None
        return p.M0State.unpack(self._control(p.read_m0_state(), "read M0 state"))

    # ------------------------------------------------------------------ properties
    @property
    def sample_rate_hz(self) -> float | None:
        """Sample rate, 2-20 MS/s (None until set); setting it also sets the automatic
        baseband filter (0.75 Fs)."""
        return self._sample_rate_hz

    @sample_rate_hz.setter
    def sample_rate_hz(self, value: float) -> None:
        req = p.set_sample_rate(value)
        self._control(req, "set sample rate")
        freq_hz, divider = p.sample_rate_params(value)
        rate = freq_hz / divider
        self._sample_rate_hz = rate
        bw = p.auto_baseband_filter_hz(rate)
        self._control(p.set_baseband_filter(bw), "set baseband filter")
        self._baseband_filter_hz = bw

    @property
    def baseband_filter_hz(self) -> int | None:
        """Baseband filter, rounded down to one of 1.75 ... 28 MHz (None until set)."""
        return self._baseband_filter_hz

    @baseband_filter_hz.setter
    def baseband_filter_hz(self, value: float) -> None:
        lo, hi = p.BASEBAND_FILTERS_HZ[0], p.BASEBAND_FILTERS_HZ[-1]
        if not lo <= float(value) <= hi:
            raise ValueError(f"baseband_filter_hz must be in [{lo:g}, {hi:g}] Hz, got {value!r}")
        bw = p.baseband_filter_round_down(value)
        self._control(p.set_baseband_filter(bw), "set baseband filter")
        self._baseband_filter_hz = bw

    @property
    def center_freq_hz(self) -> int | None:
        """Centre frequency, 1 MHz - 6 GHz, in 1 Hz steps (None until set)."""
        return self._center_freq_hz

    @center_freq_hz.setter
    def center_freq_hz(self, value: float) -> None:
        self._control(p.set_frequency(value), "set frequency")
        self._center_freq_hz = int(round(float(value)))

    @property
    def amp_enabled(self) -> bool:
        """The RF amplifier (about 11-14 dB, receive and transmit)."""
        return self._amp_enabled

    @amp_enabled.setter
    def amp_enabled(self, value: bool) -> None:
        self._control(p.set_amp_enable(value), "set amp")
        self._amp_enabled = bool(value)

    @property
    def bias_tee_enabled(self) -> bool:
        """Antenna port power (bias tee)."""
        return self._bias_tee_enabled

    @bias_tee_enabled.setter
    def bias_tee_enabled(self, value: bool) -> None:
        self._control(p.set_antenna_enable(value), "set bias tee")
        self._bias_tee_enabled = bool(value)

    @property
    def lna_gain_db(self) -> int:
        """RX LNA (IF) gain, 0-40 dB in 8 dB steps (rounded down)."""
        return self._lna_gain_db

    @lna_gain_db.setter
    def lna_gain_db(self, value: float) -> None:
        req = p.set_lna_gain(value)
        self._gain_request(req, "set LNA gain")
        self._lna_gain_db = req.index

    @property
    def vga_gain_db(self) -> int:
        """RX VGA (baseband) gain, 0-62 dB in 2 dB steps (rounded down)."""
        return self._vga_gain_db

    @vga_gain_db.setter
    def vga_gain_db(self, value: float) -> None:
        req = p.set_vga_gain(value)
        self._gain_request(req, "set VGA gain")
        self._vga_gain_db = req.index

    @property
    def txvga_gain_db(self) -> int:
        """TX VGA gain, 0-47 dB in 1 dB steps (rounded down)."""
        return self._txvga_gain_db

    @txvga_gain_db.setter
    def txvga_gain_db(self, value: float) -> None:
        req = p.set_txvga_gain(value)
        self._gain_request(req, "set TX VGA gain")
        self._txvga_gain_db = req.index

    # ------------------------------------------------------------------ receive
    @property
    def receiving(self) -> bool:
        return self._rx is not None

    def start_rx(self) -> None:
        """VGA gain, LNA gain, mode receive (as hackrf_transfer), then the reader thread."""
        if self._rx is not None:
            return
        self._gain_request(p.set_vga_gain(self._vga_gain_db), "set VGA gain")
        self._gain_request(p.set_lna_gain(self._lna_gain_db), "set LNA gain")
        self._control(p.set_transceiver_mode(p.MODE_RECEIVE), "set mode receive")
        self._pending = np.zeros(0, np.int8)
        self._delivered = 0
        self._rx = _RxThread(
            self._t, self.rx_chunk_bytes, self.rx_queue_chunks, self.bulk_timeout_ms
        )

    def stop_rx(self) -> StreamStats:
        """Mode off, join the reader, read the M0 shortfalls; returns (and keeps) the stats."""
        rx = self._rx
        if rx is None:
            raise HilError("stop_rx: not receiving")
        self._rx = None
        rx.stop.set()
        err = None
        try:
            self._control(p.set_transceiver_mode(p.MODE_OFF), "set mode off")
        except HilError as e:
            err = e
        rx.thread.join(timeout=5.0)
        shortfalls, longest = -1, 0
        if err is None:
            try:
                m0 = self.m0_state()
                if m0 is not None:
                    shortfalls, longest = m0.num_shortfalls, m0.longest_shortfall
            except HilError:
                pass
        self.last_stats = StreamStats(
            "rx", self._delivered, rx.discarded_bytes, rx.dropped_bytes, shortfalls, longest
        )
        if not self.last_stats.clean:
            warnings.warn(
                f"HackRF {self.serial_number}: receive overruns: {self.last_stats}", stacklevel=2
            )
        if err is not None:
            raise err
        return self.last_stats

    def _read_raw(self, num_bytes: int) -> np.ndarray:
        """Exactly ``num_bytes`` int8 from the running stream (raises HilError on faults)."""
        import usb.core

        rx = self._rx
        if rx is None:
            raise HilError("receive: not receiving")
        parts = [self._pending]
        have = len(self._pending)
        while have < num_bytes:
            data = rx.get()
            if data is None:
                e = rx.error
                got = np.concatenate(parts)
                self._pending = np.zeros(0, np.int8)
                if isinstance(e, usb.core.USBError):
                    err = usb_error_to_hil(e, "receive")
                else:
                    err = HilError(f"receive: reader stopped: {e!r}")
                err.partial_raw = got
                raise err from e
            parts.append(data)
            have += len(data)
        raw = np.concatenate(parts)
        self._pending = raw[num_bytes:]
        return raw[:num_bytes]

    def rx(
        self, num_samples: int, *, save_to=None, max_shortfalls: int | None = None
    ) -> np.ndarray:
        """Receive ``num_samples`` samples.

        Starts a stream if none is running (and stops it afterwards), otherwise reads on
        from the running stream.

        Args:
            num_samples: samples to return (> 0).
            save_to: SigMF path stem: the capture (``ci8``) is written there; on a fault
                the capture so far is written and named in the raised error (nothing is
                written when no sample arrived; the error says so).
            max_shortfalls: raise :class:`StreamError` when the stream counted more
                overruns than this (None: warn only).
        Returns:
            [1, num_samples] complex64, full scale 1.0.
        """
        num_samples = int(num_samples)
        if num_samples <= 0:
            raise ValueError(f"num_samples must be > 0, got {num_samples}")
        own = self._rx is None
        if own:
            self.start_rx()
        try:
            raw = self._read_raw(2 * num_samples)
            self._delivered += num_samples
        except HilError as e:
            partial = getattr(e, "partial_raw", np.zeros(0, np.int8))
            try:
                if self._rx is not None:
                    self.stop_rx()
            except HilError:
                pass
            partial = partial[: len(partial) // 2 * 2]
            e.capture = _to_complex(partial)[None, :]
            if save_to is not None and len(partial):
                e.sigmf_path = self._save(partial, save_to, note=f"partial capture: {e}")
            elif save_to is not None:  # SigMF cannot hold an empty recording: write nothing
                e.args = (f"{e}; no sample arrived before it, so no capture was saved",)
            raise
        if own:
            stats = self.stop_rx()
            if max_shortfalls is not None and stats.device_shortfalls > max_shortfalls:
                err = StreamError(
                    f"receive: {stats.device_shortfalls} overruns (allowed {max_shortfalls}); "
                    "samples were lost",
                    capture=_to_complex(raw)[None, :],
                )
                if save_to is not None:
                    err.sigmf_path = self._save(raw, save_to, note=f"capture with overruns: {err}")
                raise err
        if save_to is not None:
            self._save(raw, save_to)
        return _to_complex(raw)[None, :]

    def stream(self, chunk_samples: int = 131072) -> Iterator[np.ndarray]:
        """Yield ``[1, chunk_samples] complex64`` blocks until the generator is closed."""
        self.start_rx()
        try:
            while True:
                raw = self._read_raw(2 * int(chunk_samples))
                self._delivered += int(chunk_samples)
                yield _to_complex(raw)[None, :]
        finally:
            if self._rx is not None:
                self.stop_rx()

    def _save(self, raw: np.ndarray, path, note: str | None = None):
        from hil.sigmf_io import write_sigmf

        return write_sigmf(
            path,
            raw,
            sample_rate_hz=self._rate_hz("save a capture"),
            center_freq_hz=self._center_freq_hz,
            datatype="ci8",
            hw=f"{self.product} {self.serial_number}",
            description=note,
        )

    # ------------------------------------------------------------------ transmit
    def tx(self, samples, *, save_to=None, max_shortfalls: int | None = None) -> StreamStats:
        """Transmit one burst and switch off cleanly.

        TX VGA gain, mode transmit, bulk writes (the last padded with zeros to a multiple of
        512 bytes), 32768 zero bytes (flush), a wait of 32768 / (2 Fs) s for play-out, mode off.

        Args:
            samples: [num_samples] or [1, num_samples] complex, |I|, |Q| <= 1 (full scale).
            save_to: SigMF path stem for the burst as sent (``ci8``).
            max_shortfalls: raise StreamError when the device counted more underruns.
        """
        import usb.core

        if self._rx is not None:
            raise HilError("tx: the device is receiving; stop_rx() first (HackRF is half duplex)")
        x = full_scale_samples(samples)
        raw = to_int8_iq(x)
        payload = raw.tobytes()
        self._gain_request(p.set_txvga_gain(self._txvga_gain_db), "set TX VGA gain")
        self._control(p.set_transceiver_mode(p.MODE_TRANSMIT), "set mode transmit")
        try:
            for start in range(0, len(payload), p.TRANSFER_BYTES):
                chunk = payload[start : start + p.TRANSFER_BYTES]
                if len(chunk) % p.PACKET_BYTES:
                    chunk += bytes(p.PACKET_BYTES - len(chunk) % p.PACKET_BYTES)
                self._t.write(chunk, self.bulk_timeout_ms)
            self._t.write(bytes(p.FLUSH_BYTES), self.bulk_timeout_ms)
            time.sleep(p.FLUSH_BYTES / (p.BYTES_PER_SAMPLE * self._rate_hz("transmit")))
        except usb.core.USBError as e:
            try:
                self._control(p.set_transceiver_mode(p.MODE_OFF), "set mode off")
            except HilError:
                pass
            raise usb_error_to_hil(e, "transmit") from e
        self._control(p.set_transceiver_mode(p.MODE_OFF), "set mode off")
        m0 = self.m0_state()
        self.last_stats = StreamStats(
            "tx",
            len(x),
            device_shortfalls=-1 if m0 is None else m0.num_shortfalls,
            longest_shortfall_bytes=0 if m0 is None else m0.longest_shortfall,
        )
        if save_to is not None:
            self._save(raw, save_to)
        if m0 is not None and m0.num_shortfalls > 0:
            if max_shortfalls is not None and m0.num_shortfalls > max_shortfalls:
                raise StreamError(
                    f"transmit: {m0.num_shortfalls} underruns (allowed {max_shortfalls})"
                )
            warnings.warn(
                f"HackRF {self.serial_number}: transmit underruns: {self.last_stats}", stacklevel=2
            )
        return self.last_stats

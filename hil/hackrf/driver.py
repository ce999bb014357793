"""The HackRF One driver on pure pyusb (no libhackrf): settings, receive and transmit.

``HackRF.open(serial=None, backend=None)`` finds the device with pyusb (any backend: the
system libusb, or :class:`hil.emulation.EmulatorBackend` for tests), claims interface 0 and reads
its identity. Its knobs (one property each) are those of
:class:`hil.hackrf.settings.HackRFSettings`; the transport and discovery are in
:mod:`hil.hackrf.usb_transport`. ``rx`` receives on a dedicated thread in 256 KiB transfers and
discards the first (stale) buffer; ``tx`` pads to 512 bytes, writes the 32 KiB end-of-burst flush
and waits for play-out before switching the radio off. Overruns and underruns are read from the M0
state after each stream.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Generator

import numpy as np

from hil.errors import (
    DeviceNotFoundError,
    HilError,
    StreamError,
    usb_error_to_hil,
)
from hil.hackrf import protocol as p
from hil.hackrf.settings import HackRFSettings
from hil.hackrf.stream import RxThread, StreamStats
from hil.hackrf.usb_transport import UsbTransport, find_hackrfs
from hil.iq import from_int8_iq, full_scale_samples, to_int8_iq
from hil.sigmf_io import write_sigmf


class HackRF(HackRFSettings):
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

    As a :class:`hil.StreamingRadio`: a transfer starts at once (``tx_start_latency_s`` 0);
    the air is never the board's to set (an emulated HackRF's is its :class:`hil.Emulator`'s
    medium: ``air_settable`` False); overruns are the M0's count in ``last_stats``
    (``emulated_rx_loss`` None).
    """

    tx_start_latency_s = 0.0  # USB streams from the first transfer
    emulated_rx_loss: tuple[int, int, int] | None = None  # a HackRF's overruns are the M0's

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
        self._rx: RxThread | None = None
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
        """Put the radio in a known state, in hackrf_transfer's order (rate, filter, sync, freq,
        amp, bias)."""
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
            f"HackRF(serial={self.serial_number!r}, "
            f"board={p.BOARD_IDS.get(self.board_id, self.board_id)!r}, "
            f"firmware={self.firmware_version!r}, sample_rate_hz={self._sample_rate_hz}, "
            f"baseband_filter_hz={self._baseband_filter_hz}, "
            f"center_freq_hz={self._center_freq_hz}, "
            f"lna_gain_db={self._lna_gain_db}, vga_gain_db={self._vga_gain_db}, "
            f"txvga_gain_db={self._txvga_gain_db}, amp_enabled={self._amp_enabled}, "
            f"bias_tee_enabled={self._bias_tee_enabled})"
        )

    @property
    def air_settable(self) -> bool:
        """False: a HackRF's air is not the board's (emulated boards share a
        :class:`hil.Emulator`'s medium, which the host sets)."""
        return False

    def set_air(self, channel, *, ppm: float = 0.0, seed: int = 0) -> None:
        """``HilError``: a HackRF takes no emulated air of its own."""
        raise HilError(
            f"HackRF {self.serial_number}: its air is not the host's to set (emulated "
            "HackRFs take theirs from their hil.Emulator's medium)"
        )

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
        self._rx = RxThread(
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
            e.capture = from_int8_iq(partial)[None, :]
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
                    capture=from_int8_iq(raw)[None, :],
                )
                if save_to is not None:
                    err.sigmf_path = self._save(raw, save_to, note=f"capture with overruns: {err}")
                raise err
        if save_to is not None:
            self._save(raw, save_to)
        return from_int8_iq(raw)[None, :]

    @property
    def rx_transfer_samples(self) -> int:
        """Samples of one USB transfer of a receive stream (what the driver may still hold)."""
        return self.rx_chunk_bytes // 2

    def stream(self, chunk_samples: int = 131072) -> Generator[np.ndarray, None, None]:
        """Yield ``[1, chunk_samples] complex64`` blocks until the generator is closed."""
        self.start_rx()
        try:
            while True:
                raw = self._read_raw(2 * int(chunk_samples))
                self._delivered += int(chunk_samples)
                yield from_int8_iq(raw)[None, :]
        finally:
            if self._rx is not None:
                self.stop_rx()

    def _save(self, raw: np.ndarray, path, note: str | None = None):
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

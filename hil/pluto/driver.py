"""The ADALM-Pluto (AD9361 behind libiio) through pyadi-iio: settings, receive and transmit.

``Pluto.open(uri=None)`` opens libiio's context (``ip:ADDRESS[:PORT]`` or ``usb:...``; None:
the first Pluto found) and drives it with ``adi.Pluto``. The same code runs on a real board
and on :class:`hil.EmulatedPluto` behind :class:`hil.IiodServer`. One property per knob
with units in the name; setters write the attribute and keep what the driver read back
(LOs, sample rate and gains are quantised by the part). The Pluto is full duplex: one
board transmits and receives at once (``tx`` from one thread while ``rx`` runs on another).
"""

from __future__ import annotations

import math
import os
import time
import warnings
from collections.abc import Generator

import numpy as np

from hil.errors import DeviceNotFoundError, HilError, StreamError
from hil.hackrf.stream import StreamStats
from hil.iq import full_scale_samples
from hil.pluto.ad9361 import GAIN_CONTROL_MODES, RX_FULL_SCALE, TX_FULL_SCALE, integer_hz
from hil.pluto.context import air_setting
from hil.pluto.iio_access import (
    air_attribute,
    destroy_buffers,
    find_plutos,
    iio_error_to_hil,
    import_iio,
    receive_error,
    release_frames,
)
from hil.pluto.stream import PLUTO_BUFFER_SAMPLES, rx_stream
from hil.sigmf_io import write_sigmf


class Pluto:
    """An ADALM-Pluto (real or emulated) behind one property per knob.

    Use ``Pluto.open(uri=None)`` as a context manager::

        with Pluto.open("ip:192.168.2.1") as sdr:
            sdr.sample_rate_hz = 4e6            # reads back what the clock chain makes
            sdr.center_freq_hz = 2.45e9         # RX and TX LO
            sdr.rx_gain_db = 40.7               # manual gain: reads back 40
            iq = sdr.rx(400_000)                # [1, 400000] complex64, full scale 1.0

    Quantisation (the AD9361 driver's): LOs on the RF PLL's fractional-N grid (about 1 Hz),
    the sample rate on the baseband PLL's grid and integer dividers, RX gain in whole dB
    (-3..71 dB at 1.3-4 GHz), TX gain (minus the attenuation) in 0.25 dB steps in
    [-89.75, 0] dB, RF bandwidth in Hz.

    Args:
        sdr: an ``adi.Pluto``.
        uri: its libiio URI.
        rx_chunk_samples: samples per receive buffer (refill), > 0.
        tx_start_latency_s: how long after ``tx`` is called the first samples may leave
            (buffer set-up over the network or USB, a busy host's thread scheduling); an
            over-the-air capture runs that much longer (:func:`hil.send_blocks`).
        tx_chunk_samples: samples per transmit buffer of a streamed burst, > 0.
        kernel_buffers: the driver's buffer queue depth (a burst's tail plays out of it).
        timeout_ms: libiio's timeout of each request and buffer, ms.
    """

    def __init__(
        self,
        sdr,
        uri: str,
        *,
        rx_chunk_samples: int = 1 << 14,
        tx_chunk_samples: int = 1 << 16,
        tx_start_latency_s: float = 0.3,
        timeout_ms: int = 5000,
        kernel_buffers: int = 4,
        configure: bool = True,
    ):
        chunks = {"rx_chunk_samples": rx_chunk_samples, "tx_chunk_samples": tx_chunk_samples}
        for name, v in chunks.items():
            if int(v) <= 0:
                raise ValueError(f"{name} must be > 0, got {v!r}")
        self._sdr = sdr
        self.uri = uri
        self.rx_chunk_samples = int(rx_chunk_samples)
        self.rx_transfer_samples = PLUTO_BUFFER_SAMPLES  # a stream's: 4 for a late reader
        self.tx_chunk_samples = int(tx_chunk_samples)
        self.kernel_buffers = int(kernel_buffers)
        self.tx_start_latency_s = float(tx_start_latency_s)
        self.timeout_ms = int(timeout_ms)
        self._closed = False
        self._receiving = False
        self._cyclic = False
        self.last_stats: StreamStats | None = None
        self.emulated_rx_loss: tuple[int, int, int] | None = None  # set by a stream's end
        self.serial_number = self._context_attr("hw_serial")
        self.product = self._context_attr("hw_model") or "ADALM-Pluto"
        self.firmware_version = self._context_attr("fw_version")
        if configure:
            self.configure()

    # ------------------------------------------------------------------ opening
    @classmethod
    def open(cls, uri: str | None = None, timeout_ms: int = 5000, **kwargs) -> Pluto:
        """Open the Pluto at ``uri`` (libiio's ``ip:ADDRESS[:PORT]`` or ``usb:B.D.I``), or
        the first one :func:`find_plutos` lists.

        Raises:
            DeviceNotFoundError: nothing answers at ``uri`` (the message names it) or no
                Pluto was found.
        """
        iio = import_iio()
        if uri is None and os.environ.get("IIOD_REMOTE"):
            uri = f"ip:{os.environ['IIOD_REMOTE']}"  # no scan: libiio's default network host
        if uri is None:
            found = find_plutos()
            if not found:
                raise DeviceNotFoundError(
                    "no Pluto found: libiio's USB scan found none and IIOD_REMOTE is unset; "
                    "connect one by USB, or set IIOD_REMOTE=ADDRESS for one on the network "
                    "(such as 192.168.2.1)"
                )
            uri = found[0][0]
        try:
            ctx = iio.Context(uri)
        except OSError as e:
            raise DeviceNotFoundError(
                f"no Pluto at {uri}: {os.strerror(e.errno) if e.errno else e}"
            ) from e
        try:
            ctx.set_timeout(int(timeout_ms))
            import adi

            sdr = adi.Pluto(ctx)
            sdr.uri = uri
        except OSError as e:
            raise iio_error_to_hil(e, f"open {uri}") from e
        except Exception as e:  # noqa: BLE001 - pyadi-iio raises plain Exception
            raise DeviceNotFoundError(f"{uri} is not a Pluto (AD9361) context: {e}") from e
        return cls(sdr, uri, timeout_ms=timeout_ms, **kwargs)

    def _context_attr(self, name: str) -> str:
        try:
            return str(self._sdr.ctx.attrs.get(name, ""))
        except Exception:  # noqa: BLE001 - an absent attribute is not an error
            return ""

    def configure(
        self,
        sample_rate_hz: float = 4e6,
        center_freq_hz: float = 2.45e9,
        rx_gain_db: float = 30,
        tx_gain_db: float = -10.0,
    ) -> None:
        """A known state: rate, both LOs, RF bandwidth Fs (at most 20 MHz), manual gain, gains."""
        self.sample_rate_hz = sample_rate_hz
        self.center_freq_hz = center_freq_hz
        self.gain_control_mode = "manual"
        self.rx_gain_db = rx_gain_db
        self.tx_gain_db = tx_gain_db

    def apply_ota_config(self, cfg) -> None:
        """Set rate, LOs and gains from a ``hil.OtaConfig`` (its ``ad9361_*`` gains)."""
        self.configure(
            cfg.sample_rate_hz, cfg.center_freq_hz, cfg.ad9361_rx_gain_db, cfg.ad9361_tx_gain_db
        )

    @property
    def air_settable(self) -> bool:
        """True on :class:`hil.EmulatedPluto`, whose air the host sets (:meth:`set_air`);
        False on a real board."""
        return not self._closed and air_attribute(self._sdr) is not None

    def set_air(self, channel, *, ppm: float = 0.0, seed: int = 0) -> None:
        """Set an emulated board's air (``hil.AirChannel`` from its TX to its RX), its
        crystal error (ppm) and noise seed, between bursts; ``HilError`` on a real board."""
        if not self.air_settable:
            raise HilError(f"{self.uri} is a real board: its air is not the host's to set")
        try:
            air_attribute(self._sdr).value = air_setting(channel, float(ppm), int(seed))
        except Exception as e:  # noqa: BLE001 - libiio raises OSError
            raise iio_error_to_hil(e, "set the emulated air") from e

    def close(self) -> None:
        """Stop transmitting and receiving, release the buffers, then the context (libiio
        reports on stderr what fails on the way, so this comes before any error line)."""
        if self._closed:
            return
        self._closed = True
        destroy_buffers(self._sdr.tx_destroy_buffer, self._sdr.rx_destroy_buffer)
        sdr, self._sdr = self._sdr, None
        vars(sdr).clear()  # pyadi-iio's devices hold the context: it is destroyed now

    def __enter__(self) -> Pluto:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __repr__(self) -> str:
        if self._closed:
            return f"Pluto(uri={self.uri!r}, closed)"
        return (
            f"Pluto(uri={self.uri!r}, serial={self.serial_number!r}, "
            f"sample_rate_hz={self.sample_rate_hz}, rx_lo_hz={self.rx_lo_hz}, "
            f"tx_lo_hz={self.tx_lo_hz}, rf_bandwidth_hz={self.rf_bandwidth_hz}, "
            f"gain_control_mode={self.gain_control_mode!r}, rx_gain_db={self.rx_gain_db}, "
            f"tx_gain_db={self.tx_gain_db})"
        )

    # ------------------------------------------------------------------ attributes
    def _get(self, name: str):
        if self._closed:
            raise HilError(f"read {name}: the device is closed")
        try:
            return getattr(self._sdr, name)
        except Exception as e:  # noqa: BLE001 - libiio raises OSError
            raise iio_error_to_hil(e, f"read {name}") from e

    def _set(self, name: str, value, what: str) -> None:
        if self._closed:
            raise HilError(f"{what}: the device is closed")
        try:
            setattr(self._sdr, name, value)
        except Exception as e:  # noqa: BLE001 - libiio raises OSError
            raise iio_error_to_hil(e, what) from e

    @property
    def sample_rate_hz(self) -> int:
        """RX and TX sample rate, 520833-61440000 S/s (read back from the clock chain); setting
        it also sets the RF bandwidth to the rate (at most 20 MHz)."""
        return int(self._get("sample_rate"))

    @sample_rate_hz.setter
    def sample_rate_hz(self, value: float) -> None:
        v = float(value)
        if not math.isfinite(v) or not 520_833 <= v <= 61_440_000:
            raise ValueError(f"sample_rate_hz must be in [520833, 61440000] S/s, got {value!r}")
        self._set("sample_rate", int(round(v)), "set sample rate")
        self.rf_bandwidth_hz = min(max(int(v), 200_000), 20_000_000)  # the whole band passes

    @property
    def rx_lo_hz(self) -> int:
        """RX LO, Hz (325 MHz-3.8 GHz on a stock Pluto), on the PLL's grid."""
        return int(self._get("rx_lo"))

    @rx_lo_hz.setter
    def rx_lo_hz(self, value: float) -> None:
        self._set("rx_lo", integer_hz(value, "rx_lo_hz"), "set RX LO")

    @property
    def tx_lo_hz(self) -> int:
        """TX LO, Hz, on the PLL's grid."""
        return int(self._get("tx_lo"))

    @tx_lo_hz.setter
    def tx_lo_hz(self, value: float) -> None:
        self._set("tx_lo", integer_hz(value, "tx_lo_hz"), "set TX LO")

    @property
    def center_freq_hz(self) -> int:
        """The RX LO; setting it tunes both LOs (one board, one carrier)."""
        return self.rx_lo_hz

    @center_freq_hz.setter
    def center_freq_hz(self, value: float) -> None:
        self.rx_lo_hz = value
        self.tx_lo_hz = value

    @property
    def rf_bandwidth_hz(self) -> int:
        """RX analog filter bandwidth, Hz; setting it sets RX and TX alike."""
        return int(self._get("rx_rf_bandwidth"))

    @rf_bandwidth_hz.setter
    def rf_bandwidth_hz(self, value: float) -> None:
        bw = integer_hz(value, "rf_bandwidth_hz")
        self._set("rx_rf_bandwidth", bw, "set RX RF bandwidth")
        self._set("tx_rf_bandwidth", bw, "set TX RF bandwidth")

    @property
    def gain_control_mode(self) -> str:
        """RX gain control: manual, fast_attack, slow_attack or hybrid (AGC)."""
        return str(self._get("gain_control_mode_chan0"))

    @gain_control_mode.setter
    def gain_control_mode(self, value: str) -> None:
        if value not in GAIN_CONTROL_MODES:
            raise ValueError(
                f"gain_control_mode must be one of {', '.join(GAIN_CONTROL_MODES)}, got {value!r}"
            )
        self._set("gain_control_mode_chan0", value, "set gain control mode")

    @property
    def rx_gain_db(self) -> float:
        """RX gain, dB: written in manual mode (whole dB), read back in any mode."""
        return float(self._get("rx_hardwaregain_chan0"))

    @rx_gain_db.setter
    def rx_gain_db(self, value: float) -> None:
        if not math.isfinite(float(value)):
            raise ValueError(f"rx_gain_db must be a finite number of dB, got {value!r}")
        if self.gain_control_mode != "manual":  # pyadi-iio would ignore it silently
            raise ValueError("rx_gain_db: set gain_control_mode = 'manual' first")
        self._set("rx_hardwaregain_chan0", float(value), "set RX gain")

    @property
    def tx_gain_db(self) -> float:
        """TX gain (minus the attenuation), [-89.75, 0] dB in 0.25 dB steps."""
        return float(self._get("tx_hardwaregain_chan0"))

    @tx_gain_db.setter
    def tx_gain_db(self, value: float) -> None:
        v = float(value)
        if not math.isfinite(v) or not -89.75 <= v <= 0:
            raise ValueError(f"tx_gain_db must be in [-89.75, 0] dB, got {value!r}")
        self._set("tx_hardwaregain_chan0", v, "set TX gain")

    # ------------------------------------------------------------------ receive
    @property
    def receiving(self) -> bool:
        return self._receiving

    def stream(self, chunk_samples: int) -> Generator[np.ndarray, None, None]:
        """``[1, n]`` receive buffers of ``chunk_samples`` at least, until closed."""
        return rx_stream(self, max(int(chunk_samples), self.rx_transfer_samples))

    def rx(
        self, num_samples: int, *, save_to=None, max_shortfalls: int | None = None
    ) -> np.ndarray:
        """Receive ``num_samples`` samples from a fresh stream (closed again afterwards).

        Args:
            num_samples: samples to return (> 0).
            save_to: SigMF path stem: the capture (``cf32_le``) is written there; on a fault
                the capture so far is written and named in the raised error.
            max_shortfalls: accepted for the HackRF's interface; libiio 0.x reports no
                overrun count, so ``last_stats.device_shortfalls`` is -1.
        Returns:
            [1, num_samples] complex64, full scale 1.0.
        """
        num_samples = int(num_samples)
        if num_samples <= 0:
            raise ValueError(f"num_samples must be > 0, got {num_samples}")
        if self._closed:
            raise HilError("receive: the device is closed")
        sdr = self._sdr
        chunk = min(self.rx_chunk_samples, num_samples)
        parts, have, asked = [], 0, time.monotonic()
        tuning = (float(self.sample_rate_hz), float(self.rx_lo_hz))  # for SigMF, read while alive
        try:
            sdr.rx_destroy_buffer()
            sdr.rx_buffer_size = chunk
            while have < num_samples:
                asked = time.monotonic()
                x = np.asarray(sdr.rx())  # [chunk] complex128, ADC counts
                parts.append((x / RX_FULL_SCALE).astype(np.complex64))
                have += len(x)
                self._receiving = True  # the stream is live once a buffer arrived
        except Exception as e:  # noqa: BLE001 - libiio raises OSError, pyadi Exception
            release_frames(e)
            waited_s = time.monotonic() - asked if parts or self._receiving else 0.0
            err = receive_error(e, waited_s, self.timeout_ms)
            got = np.concatenate(parts)[:num_samples] if parts else np.zeros(0, np.complex64)
            err.capture = got[None, :]
            if save_to is not None and len(got):
                err.sigmf_path = self._save(got, save_to, *tuning, note=f"partial capture: {err}")
            elif save_to is not None:
                err.args = (f"{err}; no sample arrived before it, so no capture was saved",)
            raise err from e
        finally:
            self._receiving = False
            destroy_buffers(sdr.rx_destroy_buffer)
        iq = np.concatenate(parts)[:num_samples]
        self.last_stats = StreamStats("rx", num_samples)
        if save_to is not None:
            self._save(iq, save_to, *tuning)
        return iq[None, :]

    def _save(self, iq, path, sample_rate_hz: float, center_freq_hz: float, note=None):
        return write_sigmf(
            path,
            iq,
            sample_rate_hz=sample_rate_hz,
            center_freq_hz=center_freq_hz,
            datatype="cf32_le",
            hw=f"{self.product} {self.uri}",
            description=note,
        )

    # ------------------------------------------------------------------ transmit
    def tx(
        self, samples, *, cyclic: bool = False, save_to=None, max_shortfalls=None
    ) -> StreamStats:
        """Transmit ``samples`` once (streamed in buffers, then played out) or for ever.

        Args:
            samples: [num_samples] or [1, num_samples] complex, |I|, |Q| <= 1 (full scale).
            cyclic: repeat the samples until :meth:`stop_tx` or :meth:`close` (one buffer).
            save_to: SigMF path stem for the samples as sent.
            max_shortfalls: accepted for the HackRF's interface (no underrun count in libiio 0.x).
        """
        x = full_scale_samples(samples)
        if self._closed:
            raise HilError("transmit: the device is closed")
        counts = np.round(x.real * TX_FULL_SCALE) + 1j * np.round(np.imag(x) * TX_FULL_SCALE)
        sdr = self._sdr
        try:
            sdr.tx_destroy_buffer()
            sdr.tx_cyclic_buffer = bool(cyclic)
            self._cyclic = bool(cyclic)
            if cyclic:
                sdr.tx(counts)
            else:
                n = self.tx_chunk_samples
                padded = np.zeros(-(-len(counts) // n) * n, np.complex128)
                padded[: len(counts)] = counts
                for start in range(0, len(padded), n):
                    sdr.tx(padded[start : start + n])
                queued = min(len(padded), self.kernel_buffers * n)
                time.sleep(queued / float(self.sample_rate_hz))  # the queue plays out
                sdr.tx_destroy_buffer()
        except Exception as e:  # noqa: BLE001 - libiio raises OSError, pyadi Exception
            release_frames(e)
            raise iio_error_to_hil(e, "transmit") from e
        self.last_stats = StreamStats("tx", len(x))
        if save_to is not None:
            rate, lo = float(self.sample_rate_hz), float(self.tx_lo_hz)
            self._save(x.astype(np.complex64), save_to, rate, lo)
        if max_shortfalls is not None and self.last_stats.device_shortfalls > max_shortfalls:
            raise StreamError(f"transmit: {self.last_stats.device_shortfalls} underruns")
        return self.last_stats

    def stop_tx(self) -> None:
        """Stop a cyclic transmission (release the TX buffer)."""
        if self._closed:
            return
        try:
            self._sdr.tx_destroy_buffer()
        except Exception as e:  # noqa: BLE001
            warnings.warn(f"Pluto {self.uri}: stop transmit: {e}", stacklevel=2)
        self._cyclic = False

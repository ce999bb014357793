"""Any SDR with a SoapySDR module as a :class:`hil.Radio`: :class:`SoapyRadio`.

``SoapyRadio.open("driver=uhd,type=b200")`` opens the device a Soapy device string names
(None: the first ``SoapySDR.Device.enumerate()`` finds): a USRP through SoapyUHD, a
HackRF through SoapyHackRF, a LimeSDR, an RTL-SDR (receive only), or any of them on
another host through SoapyRemote (``driver=remote,remote=tcp://HOST:PORT``), including
the emulated device of ``osnerf hil emulate soapy``. One property per knob with units,
each checked against the device's own ``get*Range`` and read back as the driver keeps it.

Streams count what SoapySDR reports: ``readStream``'s ``SOAPY_SDR_OVERFLOW`` (samples
lost before the next ones), ``SOAPY_SDR_TIMEOUT`` (nothing within the wait),
``writeStream``'s and ``readStreamStatus``' ``SOAPY_SDR_UNDERFLOW`` (the device ran dry):
:class:`SoapyCounts`, kept per stream in ``last_counts``. More overflows than a receive
allows raise :class:`hil.StreamError` carrying the capture so far.
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass

import numpy as np

from hil.errors import DeviceNotFoundError, HilError, StreamError, TimedOutError
from hil.hackrf.stream import StreamStats
from hil.iq import full_scale_samples
from hil.pluto.context import air_setting
from hil.soapy.binding import args_string, soapysdr

AIR_SETTING = "emulated_air"  # hil.emulation.soapy_device.AIR_SETTING, a device setting
_RMEM_MAX = "/proc/sys/net/core/rmem_max"


@dataclass(frozen=True)
class SoapyCounts:
    """What SoapySDR reported of one stream.

    Attributes:
        direction: "rx" or "tx".
        num_samples: samples delivered (rx) or accepted (tx).
        overflows: ``SOAPY_SDR_OVERFLOW`` returns (rx): each lost samples.
        underflows: ``SOAPY_SDR_UNDERFLOW`` returns and status reports (tx).
        timeouts: ``SOAPY_SDR_TIMEOUT`` returns (waits that ended with nothing).
    """

    direction: str
    num_samples: int
    overflows: int = 0
    underflows: int = 0
    timeouts: int = 0

    @property
    def lost_samples(self) -> bool:
        return self.overflows > 0 or self.underflows > 0

    def line(self) -> str:
        return (
            f"{self.direction}: {self.num_samples} samples, {self.overflows} overflows, "
            f"{self.underflows} underflows, {self.timeouts} timeouts"
        )


def _span(ranges) -> tuple[float, float]:
    """One (low, high) over a list of ``SoapySDR.Range`` s (or one range)."""
    if not isinstance(ranges, (list, tuple)):
        ranges = [ranges]
    if not ranges:
        return (0.0, math.inf)
    return (min(r.minimum() for r in ranges), max(r.maximum() for r in ranges))


def find_soapy_devices(query: str = "") -> list[str]:
    """Device strings of what ``SoapySDR.Device.enumerate(query)`` finds (every installed
    module's devices; ``query`` narrows it, e.g. ``driver=uhd``).

    Raises:
        DeviceNotFoundError: the binding is not installed.
    """
    return [args_string(k) for k in soapysdr().Device.enumerate(query)]


class SoapyRadio:
    """A SoapySDR device behind one property per knob (channel 0 each way).

    Use ``SoapyRadio.open(args)`` as a context manager::

        with SoapyRadio.open("driver=remote,remote=tcp://127.0.0.1:55132") as sdr:
            sdr.sample_rate_hz = 4e6        # both directions, read back
            sdr.center_freq_hz = 2.45e9     # RX and TX
            iq = sdr.rx(400_000)            # [1, 400000] complex64, full scale 1.0

    Args:
        device: a ``SoapySDR.Device``.
        args: its device string.
        rx_chunk_samples: samples asked of each ``readStream``.
        timeout_s: how long a stream may deliver nothing before it fails.
        tx_start_latency_s: how long after ``tx`` is called the first samples may leave
            (stream set-up, over the network for a remote device); an over-the-air
            capture runs that much longer (:func:`hil.send_blocks`).
    """

    def __init__(
        self,
        device,
        args: str,
        *,
        rx_chunk_samples: int = 1 << 14,
        timeout_s: float = 5.0,
        tx_start_latency_s: float = 0.3,
    ):
        self._dev = device
        self.tx_start_latency_s = float(tx_start_latency_s)
        self.args = args
        self.rx_chunk_samples = int(rx_chunk_samples)
        self.timeout_s = float(timeout_s)
        self._receiving = False
        self._closed = False
        self.last_counts: dict[str, SoapyCounts] = {}
        self.last_stats: StreamStats | None = None
        s = soapysdr()
        self.can_transmit = device.getNumChannels(s.SOAPY_SDR_TX) > 0
        self.driver_key = str(device.getDriverKey())
        self.hardware_key = str(device.getHardwareKey())

    @classmethod
    def open(cls, args: str | None = None, **kwargs) -> SoapyRadio:
        """The device ``args`` names (a Soapy device string); None: the first found.

        Raises:
            DeviceNotFoundError: no binding, nothing found, or the device did not open.
        """
        s = soapysdr()
        if args is None:
            found = find_soapy_devices()
            if not found:
                raise DeviceNotFoundError(
                    "no SoapySDR device found (SoapySDRUtil --find lists what the installed "
                    "modules see); name one with --tx-args/--rx-args"
                )
            args = found[0]
        try:
            device = s.Device(args)
        except (RuntimeError, ValueError) as e:
            raise DeviceNotFoundError(f"SoapySDR device {args!r} did not open: {e}") from e
        return cls(device, args, **kwargs)

    # ------------------------------------------------------------------ ranges
    def _range(self, what: str, direction: str) -> tuple[float, float]:
        s = soapysdr()
        d = s.SOAPY_SDR_TX if direction == "tx" else s.SOAPY_SDR_RX
        get = {
            "freq": self._dev.getFrequencyRange,
            "rate": self._dev.getSampleRateRange,
            "gain": self._dev.getGainRange,
        }[what]
        return _span(get(d, 0))

    def ranges(self) -> dict[str, tuple[float, float]]:
        """The device's own ranges: ``center_freq_range_hz`` and ``sample_rate_range_hz``
        (what both directions reach, or receive alone for a receive-only device),
        ``rx_gain_range_db``, ``tx_gain_range_db``."""
        dirs = ("rx", "tx") if self.can_transmit else ("rx",)
        out = {}
        for key, what in (("center_freq_range_hz", "freq"), ("sample_rate_range_hz", "rate")):
            spans = [self._range(what, d) for d in dirs]
            out[key] = (max(lo for lo, _ in spans), min(hi for _, hi in spans))
        out["rx_gain_range_db"] = self._range("gain", "rx")
        if self.can_transmit:
            out["tx_gain_range_db"] = self._range("gain", "tx")
        return out

    # ------------------------------------------------------------------ knobs
    def _dirs(self):
        s = soapysdr()
        return (s.SOAPY_SDR_RX, s.SOAPY_SDR_TX) if self.can_transmit else (s.SOAPY_SDR_RX,)

    def _checked(self, value: float, span: tuple[float, float], name: str, unit: str) -> float:
        v = float(value)
        if not (math.isfinite(v) and span[0] <= v <= span[1]):
            raise ValueError(f"{name} must be in [{span[0]:g}, {span[1]:g}] {unit}, got {value!r}")
        return v

    def _call(self, what: str, fn, *args):
        if self._closed:
            raise HilError(f"{what}: the device is closed")
        try:
            return fn(*args)
        except (RuntimeError, ValueError) as e:
            raise HilError(f"{what}: {e}") from e

    @property
    def sample_rate_hz(self) -> float:
        return float(self._dev.getSampleRate(soapysdr().SOAPY_SDR_RX, 0))

    @sample_rate_hz.setter
    def sample_rate_hz(self, value: float) -> None:
        v = self._checked(value, self.ranges()["sample_rate_range_hz"], "sample_rate_hz", "S/s")
        for d in self._dirs():
            self._call("set the sample rate", self._dev.setSampleRate, d, 0, v)

    @property
    def center_freq_hz(self) -> float:
        return float(self._dev.getFrequency(soapysdr().SOAPY_SDR_RX, 0))

    @center_freq_hz.setter
    def center_freq_hz(self, value: float) -> None:
        v = self._checked(value, self.ranges()["center_freq_range_hz"], "center_freq_hz", "Hz")
        for d in self._dirs():
            self._call("set the frequency", self._dev.setFrequency, d, 0, v)

    @property
    def rx_gain_db(self) -> float:
        return float(self._dev.getGain(soapysdr().SOAPY_SDR_RX, 0))

    @rx_gain_db.setter
    def rx_gain_db(self, value: float) -> None:
        v = self._checked(value, self._range("gain", "rx"), "rx_gain_db", "dB")
        self._call("set the RX gain", self._dev.setGain, soapysdr().SOAPY_SDR_RX, 0, v)

    @property
    def tx_gain_db(self) -> float:
        return float(self._dev.getGain(soapysdr().SOAPY_SDR_TX, 0))

    @tx_gain_db.setter
    def tx_gain_db(self, value: float) -> None:
        v = self._checked(value, self._range("gain", "tx"), "tx_gain_db", "dB")
        self._call("set the TX gain", self._dev.setGain, soapysdr().SOAPY_SDR_TX, 0, v)

    def apply_ota_config(self, cfg) -> None:
        """``cfg``'s (``hil.OtaConfig``) sample rate and frequency, and its Soapy gains
        where given (None leaves the device's)."""
        self.sample_rate_hz = cfg.sample_rate_hz
        self.center_freq_hz = cfg.center_freq_hz
        if cfg.soapy_rx_gain_db is not None:
            self.rx_gain_db = cfg.soapy_rx_gain_db
        if cfg.soapy_tx_gain_db is not None and self.can_transmit:
            self.tx_gain_db = cfg.soapy_tx_gain_db

    # ------------------------------------------------------------------ the emulated air
    @property
    def air_settable(self) -> bool:
        """Whether the device takes an emulated air (``osnerf hil emulate soapy``)."""
        try:
            return AIR_SETTING in [a.key for a in self._dev.getSettingInfo()]
        except RuntimeError:
            return False

    def set_air(self, channel, *, ppm: float = 0.0, seed: int = 0) -> None:
        """The emulated device's air from now on (a ``hil.AirChannel``), its crystal error
        and noise seed. Raises ``HilError`` on a real device."""
        if not self.air_settable:
            raise HilError(f"{self.args}: a real device; its air is not the host's to set")
        text = air_setting(channel, ppm, seed)
        self._call("set the emulated air", self._dev.writeSetting, AIR_SETTING, text)

    # ------------------------------------------------------------------ streams
    def _stream_args(self) -> dict:
        """A remote device's socket window within what the kernel grants (no warning)."""
        if "driver=remote" not in self.args:
            return {}
        try:
            with open(_RMEM_MAX) as f:
                return {"remote:window": str(int(f.read()))}
        except (OSError, ValueError):
            return {}

    @property
    def receiving(self) -> bool:
        return self._receiving

    def rx(self, num_samples: int, *, max_shortfalls: int | None = None) -> np.ndarray:
        """Receive ``num_samples`` from a fresh stream (closed again afterwards).

        Args:
            max_shortfalls: raise :class:`hil.StreamError` once more overflows than this
                were reported (None: warn only).
        Returns:
            [1, num_samples] complex64, full scale 1.0.
        Raises:
            StreamError: too many overflows, or a stream error; TimedOutError: nothing
                arrived for ``timeout_s``. Either carries the capture so far.
        """
        s = soapysdr()
        num_samples = int(num_samples)
        if num_samples <= 0:
            raise ValueError(f"num_samples must be > 0, got {num_samples}")
        out = np.zeros(num_samples, np.complex64)
        have = overflows = timeouts = 0
        stream = self._call(
            "set up the receive stream",
            self._dev.setupStream,
            s.SOAPY_SDR_RX,
            s.SOAPY_SDR_CF32,
            [0],
            self._stream_args(),
        )
        try:
            self._call("start receiving", self._dev.activateStream, stream)
            waited_since = time.monotonic()
            while have < num_samples:
                n = min(self.rx_chunk_samples, num_samples - have)
                r = self._dev.readStream(stream, [out[have:]], n, timeoutUs=100_000)
                if r.ret > 0:
                    have += r.ret
                    self._receiving = True
                    waited_since = time.monotonic()
                    continue
                if r.ret == s.SOAPY_SDR_OVERFLOW:
                    overflows += 1
                    if max_shortfalls is not None and overflows > max_shortfalls:
                        raise StreamError(
                            f"receive: {overflows} overflows (SOAPY_SDR_OVERFLOW: samples "
                            f"lost) after {have} samples, allowed {max_shortfalls}",
                            capture=out[None, :have].copy(),
                        )
                    continue
                if r.ret == s.SOAPY_SDR_TIMEOUT or r.ret == 0:
                    timeouts += r.ret != 0
                    if time.monotonic() - waited_since > self.timeout_s:
                        raise TimedOutError(
                            f"receive: nothing for {self.timeout_s:g} s from {self.args} "
                            f"after {have} samples ({timeouts} timeouts)",
                            capture=out[None, :have].copy(),
                        )
                    continue
                raise StreamError(
                    f"receive: readStream returned {s.SoapySDR_errToStr(r.ret)} ({r.ret})",
                    capture=out[None, :have].copy(),
                )
        finally:
            self._receiving = False
            self.last_counts["rx"] = SoapyCounts("rx", have, overflows, 0, timeouts)
            self._end(stream)
        self.last_stats = StreamStats("rx", num_samples, device_shortfalls=overflows)
        if overflows:
            warnings.warn(f"SoapySDR {self.args}: {self.last_counts['rx'].line()}", stacklevel=2)
        return out[None, :]

    def tx(self, samples, *, max_shortfalls: int | None = None) -> StreamStats:
        """Transmit ``samples`` (|I|, |Q| <= 1) once as one burst, flagged ``END_BURST``,
        and wait until the device has played it out (its end-of-burst status, or the
        burst's duration).

        Raises:
            StreamError: more underflows than ``max_shortfalls``, or a stream error.
        """
        s = soapysdr()
        if not self.can_transmit:
            raise HilError(f"transmit: {self.args} is a receive-only device")
        x = np.ascontiguousarray(full_scale_samples(samples), np.complex64)
        rate = self.sample_rate_hz
        stream = self._call(
            "set up the transmit stream",
            self._dev.setupStream,
            s.SOAPY_SDR_TX,
            s.SOAPY_SDR_CF32,
            [0],
            self._stream_args(),
        )
        sent = underflows = timeouts = 0
        try:
            self._call("start transmitting", self._dev.activateStream, stream)
            waited_since = time.monotonic()
            while sent < len(x):
                r = self._dev.writeStream(
                    stream, [x[sent:]], len(x) - sent, s.SOAPY_SDR_END_BURST, timeoutUs=100_000
                )
                if r.ret > 0:
                    sent += r.ret
                    waited_since = time.monotonic()
                elif r.ret == s.SOAPY_SDR_UNDERFLOW:
                    underflows += 1
                elif r.ret == s.SOAPY_SDR_TIMEOUT or r.ret == 0:
                    timeouts += r.ret != 0
                    if time.monotonic() - waited_since > self.timeout_s:
                        raise TimedOutError(
                            f"transmit: {self.args} took nothing for {self.timeout_s:g} s"
                        )
                else:
                    what = s.SoapySDR_errToStr(r.ret)
                    raise StreamError(f"transmit: writeStream returned {what} ({r.ret})")
            underflows += self._await_end_of_burst(stream, len(x) / rate)
        finally:
            self.last_counts["tx"] = SoapyCounts("tx", sent, 0, underflows, timeouts)
            self._end(stream)
        self.last_stats = StreamStats("tx", len(x), device_shortfalls=underflows)
        if underflows:
            msg = f"SoapySDR {self.args}: {self.last_counts['tx'].line()}"
            if max_shortfalls is not None and underflows > max_shortfalls:
                raise StreamError(f"transmit: {msg} (allowed {max_shortfalls})")
            warnings.warn(msg, stacklevel=2)
        return self.last_stats

    def _await_end_of_burst(self, stream, burst_s: float) -> int:
        """Read the stream's status until its end-of-burst report or the burst's play-out
        time (with a margin) has passed; returns the underflows reported meanwhile."""
        s = soapysdr()
        deadline = time.monotonic() + burst_s + 0.5
        underflows = 0
        while time.monotonic() < deadline:
            r = self._dev.readStreamStatus(stream, timeoutUs=50_000)
            if r.ret == s.SOAPY_SDR_NOT_SUPPORTED:
                time.sleep(max(0.0, deadline - 0.5 - time.monotonic()))
                break
            if r.ret == s.SOAPY_SDR_UNDERFLOW:
                underflows += 1
            elif r.ret == 0 and r.flags & s.SOAPY_SDR_END_BURST:
                break
        return underflows

    def _end(self, stream) -> None:
        try:
            self._dev.deactivateStream(stream)
        finally:
            self._dev.closeStream(stream)

    # ------------------------------------------------------------------ life
    def close(self) -> None:
        """Release the device (best effort; once)."""
        if self._closed:
            return
        self._closed = True
        try:
            self._dev.close()  # the binding's unmake (a remote device hangs up)
        except (RuntimeError, AttributeError):
            pass
        self._dev = None

    def __enter__(self) -> SoapyRadio:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __repr__(self) -> str:
        if self._closed:
            return f"SoapyRadio({self.args!r}, closed)"
        return (
            f"SoapyRadio({self.args!r}, driver={self.driver_key!r}, "
            f"hardware={self.hardware_key!r}, sample_rate_hz={self.sample_rate_hz:g}, "
            f"center_freq_hz={self.center_freq_hz:g}, rx_gain_db={self.rx_gain_db:g})"
        )

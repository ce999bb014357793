"""The HackRF's control requests and knobs: one property per setting, with units in the
name; setters validate, send the request and keep the value the firmware actually uses
(gains are quantised), readable back. :class:`hil.HackRF` adds opening and streaming."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from hil.errors import HilError, RequestFailedError, usb_error_to_hil
from hil.hackrf import protocol as p

if TYPE_CHECKING:
    from hil.ota.config import OtaConfig


class HackRFSettings:
    """Requests and settings of a HackRF on a transport (see :class:`hil.HackRF`)."""

    _t: Any  # the transport: control(req), read, write, close
    _closed: bool
    usb_api_version: int
    _sample_rate_hz: float | None
    _baseband_filter_hz: int | None
    _center_freq_hz: int | None
    _lna_gain_db: int
    _vga_gain_db: int
    _txvga_gain_db: int
    _amp_enabled: bool
    _bias_tee_enabled: bool

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

    def apply_ota_config(self, cfg: OtaConfig) -> None:
        """Set rate, frequency and the three gains from a ``hil.OtaConfig``."""
        self.sample_rate_hz = cfg.sample_rate_hz
        self.center_freq_hz = cfg.center_freq_hz
        self.lna_gain_db = cfg.lna_gain_db
        self.vga_gain_db = cfg.vga_gain_db
        self.txvga_gain_db = cfg.txvga_gain_db

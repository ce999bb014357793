"""The emulated ADALM-Pluto's IIO attributes: the AD9361 settings libiio reads and writes.

:class:`PlutoAttributes` holds the settings (LOs, sample rate and its clock chain, FIR,
bandwidths, gains, loopback) and answers attribute reads and writes with the driver's
ranges and quantisation (:mod:`hil.pluto.ad9361`) and errno-style refusals (``OSError`` with
``EINVAL``, ``ENOENT``, ``EACCES``, ...). :class:`hil.EmulatedPluto` adds the context and
the sample buffers.
"""

from __future__ import annotations

import errno
import json
import math
import threading

from hil.emulation.air import AirChannel
from hil.emulation.hackrf import PPM_RANGE
from hil.pluto import ad9361
from hil.pluto.ad9361 import DEFAULT_RX_GAIN_DB, DEFAULT_TX_GAIN_DB
from hil.pluto.context import (
    AIR_ATTR,
    BUFFER_ATTRS,
    DEBUG_ATTRS,
    DEVICE_ATTRS,
    DEVICE_NAMES,
    PHY,
    RX_DEV,
    TX_DEV,
    find_channel,
)


def iio_errno(code: int, what: str) -> OSError:
    """The ``OSError`` an IIO driver's refusal becomes (``errno`` ``code``)."""
    return OSError(code, f"{errno.errorcode[code]}: {what}")


class PlutoAttributes:
    """An emulated Pluto's AD9361 settings behind IIO attribute reads and writes
    (thread-safe: every read and write holds ``lock``)."""

    def __init__(self) -> None:
        self.lock = threading.RLock()
        self.rx_lo_hz = ad9361.lo_frequency_hz(2_400_000_000)
        self.tx_lo_hz = ad9361.lo_frequency_hz(2_450_000_000)
        self.fir_enabled = False
        self.fir_decimation = 1
        self.fir_config = "FIR Rx: 0,0 Tx: 0,0"
        self.requested_rate_hz = 30_720_000
        self.chain = ad9361.clock_chain(self.requested_rate_hz)
        self.rx_bandwidth_hz = 18_000_000
        self.tx_bandwidth_hz = 18_000_000
        self.gain_control_mode = "slow_attack"
        self.manual_rx_gain_db = DEFAULT_RX_GAIN_DB
        self.tx_gain_db = DEFAULT_TX_GAIN_DB
        self.loopback = 0
        self.store: dict[tuple, str] = {}
        self.debug_attrs = dict(DEBUG_ATTRS)  # a board may add its own (the emulated air)

    # ------------------------------------------------------------------ derived state
    @property
    def sample_rate_hz(self) -> int:
        return self.chain["RXSAMP"]

    @property
    def rx_gain_db(self) -> int:
        """The gain applied to what is received: manual, or what the emulated AGC settled on."""
        if self.gain_control_mode == "manual":
            return self.manual_rx_gain_db
        return DEFAULT_RX_GAIN_DB

    def path_rates(self, direction: str) -> str:
        c = self.chain
        if direction == "rx":
            keys = ("BBPLL", "ADC", "R2", "R1", "RF", "RXSAMP")
            return " ".join(f"{k}:{c[k]}" for k in keys)
        vals = (c["BBPLL"], c["ADC"] // 2, c["R2"], c["R1"], c["RF"], c["RXSAMP"])
        return " ".join(
            f"{k}:{v}" for k, v in zip(("BBPLL", "DAC", "T2", "T1", "TF", "TXSAMP"), vals)
        )

    def _check(self, dev: str, chan_id: str | None, output: bool, kind: str, attr: str) -> None:
        if dev not in DEVICE_NAMES:
            raise iio_errno(errno.ENODEV, f"no device {dev}")
        if chan_id is not None:
            ch = find_channel(dev, chan_id, output)
            if ch is None:
                raise iio_errno(
                    errno.ENXIO, f"{dev} has no {'output' if output else 'input'} {chan_id}"
                )
            names = ch.attrs
        elif kind == "DEBUG":
            names = self.debug_attrs[dev]
        elif kind == "BUFFER":
            names = BUFFER_ATTRS if dev != PHY else ()
        else:
            names = DEVICE_ATTRS[dev]
        if attr not in names:
            raise iio_errno(errno.ENOENT, f"{dev} {chan_id or ''} has no attribute {attr}")

    # ------------------------------------------------------------------ reads
    def read_attr(self, dev: str, chan_id: str | None, output: bool, kind: str, attr: str) -> str:
        """An attribute's value as text; raises ``OSError`` (errno) as the driver would."""
        self._check(dev, chan_id, output, kind, attr)
        with self.lock:
            return self._read(dev, chan_id, output, kind, attr)

    def _read(self, dev, chan_id, output, kind, attr) -> str:
        key = (dev, chan_id, output, kind, attr)
        if dev == PHY and kind == "":
            value = self._read_phy(chan_id, output, attr, key)
            if value is not None:
                return value
        if dev == PHY and kind == "DEBUG" and attr == "loopback":
            return str(self.loopback)
        if dev in (RX_DEV, TX_DEV) and kind == "" and attr == "sampling_frequency":
            return str(self.sample_rate_hz)
        if dev in (RX_DEV, TX_DEV) and attr == "sampling_frequency_available":
            return f"{self.sample_rate_hz} {self.sample_rate_hz // 8}"
        if kind == "BUFFER":
            return {"data_available": "0", "length_align_bytes": "8", "watermark": "2048"}[attr]
        defaults = {
            "ensm_mode": "fdd",
            "calib_mode": "auto",
            "trx_rate_governor": "nominal",
            "scale": "0.000000",
            "calibscale": "1.000000",
            "frequency": "9279985",
            "sampling_frequency": str(self.sample_rate_hz),
        }
        return self.store.get(key, defaults.get(attr, "0"))

    def _read_phy(self, chan_id, output, attr, key) -> str | None:
        """An ``ad9361-phy`` attribute the driver computes; None for a stored or default one."""
        if chan_id in ("altvoltage0", "altvoltage1"):
            if attr == "frequency":
                return str(self.rx_lo_hz if chan_id == "altvoltage0" else self.tx_lo_hz)
            if attr == "frequency_available":
                return "[{} 1 {}]".format(*ad9361.LO_RANGE_HZ)
            if attr == "fastlock_recall":
                raise iio_errno(errno.EINVAL, "no fastlock profile stored")
        if chan_id == "voltage0":
            return self._read_voltage0(output, attr, key)
        if chan_id == "out":
            return str(int(self.fir_enabled))
        if chan_id == "temp0":
            return "38553"
        if chan_id is None:
            return self._read_phy_device(attr)
        return None

    def _read_voltage0(self, output, attr, key) -> str | None:
        """An attribute of the phy's ``voltage0`` (RX input or TX output) channel."""
        if attr == "sampling_frequency":
            return str(self.sample_rate_hz)
        if attr == "sampling_frequency_available":
            lo = (
                ad9361.FIR_SAMPLE_RATE_MIN_HZ
                if self.fir_decimation == 4
                else ad9361.SAMPLE_RATE_RANGE_HZ[0]
            )
            return f"[{lo} 1 {ad9361.SAMPLE_RATE_RANGE_HZ[1]}]"
        if attr == "rf_bandwidth":
            return str(self.tx_bandwidth_hz if output else self.rx_bandwidth_hz)
        if attr == "rf_bandwidth_available":
            return "[{} 1 {}]".format(*ad9361.RF_BANDWIDTH_RANGE_HZ)
        if attr == "filter_fir_en":
            return str(int(self.fir_enabled))
        if attr == "hardwaregain":
            g = self.tx_gain_db if output else float(self.rx_gain_db)
            return f"{g:.6f} dB"
        if attr == "hardwaregain_available":
            if output:
                return f"[{-ad9361.TX_ATTENUATION_RANGE_DB[1]:.6f} 0.250000 0.000000]"
            lo, hi = ad9361.rx_gain_range_db(self.rx_lo_hz)
            return f"[{lo} 1 {hi}]"
        if attr == "gain_control_mode":
            return self.gain_control_mode
        if attr == "gain_control_mode_available":
            return " ".join(ad9361.GAIN_CONTROL_MODES)
        if attr == "rssi":
            return "0.00 dB" if output else f"{100.0 - self.rx_gain_db:.2f} dB"
        if attr == "rf_port_select_available":
            return (
                "A B"
                if output
                else "A_BALANCED B_BALANCED C_BALANCED A_N A_P B_N B_P C_N C_P "
                "TX_MONITOR1 TX_MONITOR2 TX_MONITOR1_2"
            )
        if attr == "rf_port_select":
            return self.store.get(key, "A" if output else "A_BALANCED")
        return None

    def _read_phy_device(self, attr) -> str | None:
        """A device attribute of ``ad9361-phy`` (no channel)."""
        if attr == "rx_path_rates":
            return self.path_rates("rx")
        if attr == "tx_path_rates":
            return self.path_rates("tx")
        if attr == "filter_fir_config":
            return self.fir_config
        if attr == "xo_correction":
            return str(ad9361.REFERENCE_HZ)
        if attr == "xo_correction_available":
            return f"[{ad9361.REFERENCE_HZ - 8000} 1 {ad9361.REFERENCE_HZ + 8000}]"
        if attr == "ensm_mode_available":
            return "sleep wait alert fdd pinctrl pinctrl_fdd_indep"
        if attr == "calib_mode_available":
            return "auto manual manual_tx_quad tx_quad rf_dc_offs rssi_gain_step"
        if attr == "trx_rate_governor_available":
            return "nominal highest_osr"
        return None

    # ------------------------------------------------------------------ writes
    def write_attr(
        self, dev: str, chan_id: str | None, output: bool, kind: str, attr: str, value: str
    ) -> None:
        """Write an attribute; raises ``OSError`` (``EINVAL`` for a bad value, ``EACCES`` for
        a read-only one) as the driver would."""
        self._check(dev, chan_id, output, kind, attr)
        value = value.strip()
        with self.lock:
            self._write(dev, chan_id, output, kind, attr, value)

    def _write(self, dev, chan_id, output, kind, attr, value) -> None:
        if attr.endswith("_available") or attr in (
            "rssi",
            "input",
            "rx_path_rates",
            "tx_path_rates",
            "data_available",
            "length_align_bytes",
        ):
            raise iio_errno(errno.EACCES, f"{attr} is read-only")
        try:
            if dev == PHY and kind == "":
                if attr == "frequency" and chan_id in ("altvoltage0", "altvoltage1"):
                    f = ad9361.lo_frequency_hz(_integer(value))
                    if chan_id == "altvoltage0":
                        self.rx_lo_hz = f
                    else:
                        self.tx_lo_hz = f
                    return
                if chan_id == "voltage0" and attr == "sampling_frequency":
                    rate = _integer(value)
                    self.chain = ad9361.clock_chain(
                        rate, self.fir_decimation if self.fir_enabled else 1
                    )
                    self.requested_rate_hz = rate
                    return
                if chan_id == "voltage0" and attr == "rf_bandwidth":
                    bw = ad9361.rf_bandwidth_hz(_integer(value))
                    if output:
                        self.tx_bandwidth_hz = bw
                    else:
                        self.rx_bandwidth_hz = bw
                    return
                if chan_id == "voltage0" and attr == "hardwaregain":
                    if output:
                        self.tx_gain_db = ad9361.tx_gain_db(_number(value))
                    elif self.gain_control_mode != "manual":
                        raise ValueError(
                            "hardwaregain can be written only in manual gain control mode"
                        )
                    else:
                        self.manual_rx_gain_db = ad9361.rx_gain_db(_number(value), self.rx_lo_hz)
                    return
                if chan_id == "voltage0" and attr == "gain_control_mode":
                    if value not in ad9361.GAIN_CONTROL_MODES:
                        raise ValueError(
                            "gain_control_mode must be one of "
                            f"{', '.join(ad9361.GAIN_CONTROL_MODES)}"
                        )
                    if value == "manual" and self.gain_control_mode != "manual":
                        self.manual_rx_gain_db = self.rx_gain_db  # manual keeps the AGC's gain
                    self.gain_control_mode = value
                    return
                if attr in ("voltage_filter_fir_en", "filter_fir_en"):
                    on = bool(_integer(value))
                    dec = self.fir_decimation if on else 1
                    self.chain = ad9361.clock_chain(self.requested_rate_hz, dec)
                    self.fir_enabled = on
                    return
                if attr == "filter_fir_config":
                    self.fir_config, self.fir_decimation = _parse_fir(value)
                    return
            if dev == PHY and kind == "DEBUG" and attr == "loopback":
                v = _integer(value)
                if v not in (0, 1, 2):
                    raise ValueError("loopback must be 0, 1 or 2")
                self.loopback = v
                return
        except ValueError as e:
            raise iio_errno(errno.EINVAL, str(e)) from None
        self.store[(dev, chan_id, output, kind, attr)] = value


def _integer(value: str) -> int:
    try:
        return int(value, 10)
    except ValueError:
        raise ValueError(f"not an integer: {value!r}") from None


def _number(value: str) -> float:
    try:
        v = float(value.split()[0]) if value else float("nan")
    except ValueError:
        raise ValueError(f"not a number: {value!r}") from None
    return v


def _parse_fir(text: str) -> tuple[str, int]:
    """A ``filter_fir_config`` write -> (its read-back summary, RX decimation)."""
    dec, taps = 1, 0
    for line in text.splitlines():
        words = line.replace(",", " ").split()
        if words[:1] == ["RX"] and "DEC" in words:
            dec = int(words[words.index("DEC") + 1])
        elif words and all(w.lstrip("-").isdigit() for w in words):
            taps += 1
    if dec not in (1, 2, 4) or not 1 <= taps <= 128:
        raise ValueError(f"FIR config: decimation {dec} (1, 2 or 4), {taps} taps (1-128)")
    return f"FIR Rx: {taps},{dec} Tx: {taps},{dec}", dec


def parse_air_setting(text: str):
    """``(hil.AirChannel, ppm, seed)`` of :func:`air_setting` text; ``ValueError`` otherwise."""
    try:
        d = json.loads(text)
        channel = AirChannel.from_json(json.dumps(d["air"]))
        ppm, seed = float(d["ppm"]), int(d["seed"])
    except (TypeError, KeyError, ValueError) as e:
        raise ValueError(f"{AIR_ATTR}: not an air setting ({e})") from None
    if not (math.isfinite(ppm) and PPM_RANGE[0] <= ppm <= PPM_RANGE[1]) or seed < 0:
        raise ValueError(f"{AIR_ATTR}: ppm must be in {list(PPM_RANGE)} and seed >= 0")
    return channel, ppm, seed

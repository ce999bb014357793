"""An emulated ADALM-Pluto: the AD9361's IIO devices, attributes and buffers, looped to itself.

The board holds what libiio sees of a Pluto (``ad9361-phy``, ``cf-ad9361-lpc``,
``cf-ad9361-dds-core-lpc``): the context XML, attribute reads and writes with the driver's
ranges and quantisation (:mod:`hil.ad9361`) and errno-style refusals (``OSError`` with
``EINVAL``, ``ENOENT``, ``EACCES``), and the sample buffers. Its TX DAC (12 bits in 16-bit
containers, full scale 32768) loops to its RX ADC (12 bits, full scale 2048) through a
:class:`hil.Medium`: multipath, delay and noise at the channel's SNR. TX and RX LOs come
from one crystal, so TX and RX at the same LO have no carrier offset; a TX LO ``df`` above
the RX LO shifts what is received by ``df``.

The receive clock cannot run ahead of the wall clock (samples are delivered at most at the
sample rate since the buffer was opened); transmit is virtual: the medium places what is
written at the receiver's current position and receivers wait for it while a TX buffer is
open. :class:`hil.IiodServer` serves a board over iiod's network protocol.
"""

from __future__ import annotations

import errno
import threading
import time
from dataclasses import dataclass

import numpy as np

from hil import ad9361
from hil.air import RESAMPLER_TAPS, AirChannel
from hil.medium import Medium
from hil.pluto_context import (
    BUFFER_ATTRS,
    DEBUG_ATTRS,
    DEVICE_ATTRS,
    DEVICE_NAMES,
    PHY,
    RX_DEV,
    TX_DEV,
    context_xml,
    find_channel,
)

RX_FULL_SCALE = 2048  # 12-bit ADC samples, sign-extended in 16-bit containers
TX_FULL_SCALE = 32768  # 12-bit DAC samples in the 16 bits' most significant bits
DEFAULT_RX_GAIN_DB = 30  # the gain the emulated AGC settles on and manual mode starts at
DEFAULT_TX_GAIN_DB = -10.0


NETWORK_FAULTS = ("drop", "slow")
"""Faults of a served board (``osnerf hil emulate pluto --fault``), both ``after_samples``
received samples into its life: ``drop`` (the board dies: every connection closes) and
``slow`` (each later receive reply comes ``SLOW_REPLY_S`` late, past libiio's 5 s timeout)."""
SLOW_REPLY_S = 6.0
TX_UNDERRUN_S = 1.0  # wall time a receive waits for an open TX buffer's data before it underruns


def _err(code: int, what: str) -> OSError:
    return OSError(code, f"{errno.errorcode[code]}: {what}")


@dataclass
class _Port:
    """One side of the board as the medium sees it (same crystal for both)."""

    board: EmulatedPluto
    direction: str
    index: int

    @property
    def ppm(self) -> float:
        return self.board.ppm

    @property
    def sample_rate_hz(self) -> float:
        return float(self.board.sample_rate_hz)

    @property
    def center_freq_hz(self) -> float:
        return float(self.board.rx_lo_hz if self.direction == "rx" else self.board.tx_lo_hz)

    @property
    def rx_gain_db(self) -> float:
        return float(self.board.rx_gain_db)

    @property
    def tx_gain_db(self) -> float:
        return float(self.board.tx_gain_db)


class EmulatedPluto:
    """One emulated Pluto's state (thread-safe).

    Args:
        channel: the air from its TX port to its RX port.
        seed: noise seed.
        ppm: crystal error, parts per million (LOs and sample clock alike).
        serial: what ``hw_serial`` reports.
        drop_after_samples: the board's connections drop once this many samples were
            received (a killed or unplugged board); None: never.
        slow_after_samples: once this many samples were received, each receive reply is
            ``SLOW_REPLY_S`` late (a server that stalls); None: never.
    """

    def __init__(
        self,
        channel: AirChannel | None = None,
        seed: int = 0,
        ppm: float = 0.0,
        serial: str = "104473dc599300131100210074c83b9f0e",
        drop_after_samples: int | None = None,
        slow_after_samples: int | None = None,
    ):
        self.medium = Medium(channel, seed=seed, wait_timeout_s=TX_UNDERRUN_S)
        self.ppm = float(ppm)
        self.serial = serial
        self.drop_after_samples = drop_after_samples
        self.slow_after_samples = slow_after_samples
        self.lock = threading.RLock()
        self.rx_port = _Port(self, "rx", 0)
        self.tx_port = _Port(self, "tx", 1)
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
        self.rx_cursor = 0  # samples received since the board was made
        self.rx_open = False
        self.rx_opened_at = (0.0, 0)  # (monotonic s, rx_cursor) when the RX buffer opened
        # end of the samples the receiver is rendering now (rx_cursor once a read returns): a
        # transmission that starts meanwhile starts after them, never inside a read in flight
        self.rx_frontier = 0
        self.tx_open = False
        self.tx_is_cyclic = False
        self.tx_cyclic: np.ndarray | None = None
        self.samples_received = 0
        self.tx_underruns = 0  # times the open TX buffer ran dry while receiving
        self.tx_starved = False  # the open TX buffer is dry: the DAC sends silence
        self.dropped = threading.Event()  # set when a drop fault closed every connection
        self.stalled = threading.Event()  # set when a slow fault began

    @classmethod
    def for_link(
        cls,
        snr_db: float,
        *,
        seed: int = 0,
        multipath=(),
        delay_s: float = 0.0,
        reference_power_dbfs: float = -9.0,
        fault: str | None = None,
        after_samples: int = 50_000,
    ) -> EmulatedPluto:
        """A board whose loop has ``snr_db`` for a signal of ``reference_power_dbfs`` (the
        over-the-air frames' mean power) sent and received at the default gains
        (:data:`DEFAULT_TX_GAIN_DB`, :data:`DEFAULT_RX_GAIN_DB`).

        Args:
            fault: one of :data:`NETWORK_FAULTS` or None.
            after_samples: received samples before the fault.
        """
        if fault is not None and fault not in NETWORK_FAULTS:
            raise KeyError(f"unknown fault {fault!r}; known: {', '.join(NETWORK_FAULTS)}")
        channel = AirChannel(
            snr_db=float(snr_db),
            reference_power_dbfs=reference_power_dbfs,
            reference_txvga_db=DEFAULT_TX_GAIN_DB,
            reference_rx_gain_db=DEFAULT_RX_GAIN_DB,
            delay_s=delay_s,
            multipath=tuple(multipath),
        )
        return cls(
            channel,
            seed=seed,
            drop_after_samples=int(after_samples) if fault == "drop" else None,
            slow_after_samples=int(after_samples) if fault == "slow" else None,
        )

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

    # ------------------------------------------------------------------ the context
    def context_xml(self, description: str = "osnerf emulated ADALM-Pluto") -> str:
        """The context as libiio's XML (what iiod's ``PRINT`` returns)."""
        ctx_attrs = {
            "hw_model": "Analog Devices PlutoSDR Rev.C (Z7010-AD9363A) (emulated)",
            "hw_model_variant": "1",
            "hw_serial": self.serial,
            "fw_version": "v0.38",
            "ad9361-phy,xo_correction": str(ad9361.REFERENCE_HZ),
            "ad9361-phy,model": "ad9363a",
            "local,kernel": "osnerf-emulator",
        }
        return context_xml(ctx_attrs, description)

    def _check(self, dev: str, chan_id: str | None, output: bool, kind: str, attr: str) -> None:
        if dev not in DEVICE_NAMES:
            raise _err(errno.ENODEV, f"no device {dev}")
        if chan_id is not None:
            ch = find_channel(dev, chan_id, output)
            if ch is None:
                raise _err(errno.ENXIO, f"{dev} has no {'output' if output else 'input'} {chan_id}")
            names = ch.attrs
        elif kind == "DEBUG":
            names = DEBUG_ATTRS[dev]
        elif kind == "BUFFER":
            names = BUFFER_ATTRS if dev != PHY else ()
        else:
            names = DEVICE_ATTRS[dev]
        if attr not in names:
            raise _err(errno.ENOENT, f"{dev} {chan_id or ''} has no attribute {attr}")

    # ------------------------------------------------------------------ attributes
    def read_attr(self, dev: str, chan_id: str | None, output: bool, kind: str, attr: str) -> str:
        """An attribute's value as text; raises ``OSError`` (errno) as the driver would."""
        self._check(dev, chan_id, output, kind, attr)
        with self.lock:
            return self._read(dev, chan_id, output, kind, attr)

    def _read(self, dev, chan_id, output, kind, attr) -> str:
        key = (dev, chan_id, output, kind, attr)
        if dev == PHY and kind == "":
            if chan_id in ("altvoltage0", "altvoltage1"):
                if attr == "frequency":
                    return str(self.rx_lo_hz if chan_id == "altvoltage0" else self.tx_lo_hz)
                if attr == "frequency_available":
                    return "[{} 1 {}]".format(*ad9361.LO_RANGE_HZ)
                if attr == "fastlock_recall":
                    raise _err(errno.EINVAL, "no fastlock profile stored")
            if chan_id == "voltage0":
                if attr == "sampling_frequency":
                    return str(self.sample_rate_hz)
                if attr == "sampling_frequency_available":
                    lo = ad9361.FIR_SAMPLE_RATE_MIN_HZ if self.fir_decimation == 4 else ad9361.SAMPLE_RATE_RANGE_HZ[0]  # fmt: skip
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
                    return "A B" if output else "A_BALANCED B_BALANCED C_BALANCED A_N A_P B_N B_P C_N C_P TX_MONITOR1 TX_MONITOR2 TX_MONITOR1_2"  # fmt: skip
                if attr == "rf_port_select":
                    return self.store.get(key, "A" if output else "A_BALANCED")
            if chan_id == "out":
                return str(int(self.fir_enabled))
            if chan_id == "temp0":
                return "38553"
            if chan_id is None:
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
        if dev == PHY and kind == "DEBUG" and attr == "loopback":
            return str(self.loopback)
        if dev in (RX_DEV, TX_DEV) and kind == "" and attr == "sampling_frequency":
            return str(self.sample_rate_hz)
        if dev in (RX_DEV, TX_DEV) and attr == "sampling_frequency_available":
            return f"{self.sample_rate_hz} {self.sample_rate_hz // 8}"
        if kind == "BUFFER":
            return {"data_available": "0", "length_align_bytes": "8", "watermark": "2048"}[attr]
        defaults = {"ensm_mode": "fdd", "calib_mode": "auto", "trx_rate_governor": "nominal", "scale": "0.000000", "calibscale": "1.000000", "frequency": "9279985", "sampling_frequency": str(self.sample_rate_hz)}  # fmt: skip
        return self.store.get(key, defaults.get(attr, "0"))

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
        if attr.endswith("_available") or attr in ("rssi", "input", "rx_path_rates", "tx_path_rates", "data_available", "length_align_bytes"):  # fmt: skip
            raise _err(errno.EACCES, f"{attr} is read-only")
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
                    self.chain = ad9361.clock_chain(rate, self.fir_decimation if self.fir_enabled else 1)  # fmt: skip
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
                        raise ValueError("hardwaregain can be written only in manual gain control mode")  # fmt: skip
                    else:
                        self.manual_rx_gain_db = ad9361.rx_gain_db(_number(value), self.rx_lo_hz)
                    return
                if chan_id == "voltage0" and attr == "gain_control_mode":
                    if value not in ad9361.GAIN_CONTROL_MODES:
                        raise ValueError(f"gain_control_mode must be one of {', '.join(ad9361.GAIN_CONTROL_MODES)}")  # fmt: skip
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
            raise _err(errno.EINVAL, str(e)) from None
        self.store[(dev, chan_id, output, kind, attr)] = value

    # ------------------------------------------------------------------ buffers
    def open_rx(self) -> None:
        """Start receiving "now": the RX clock jumps to the medium's present."""
        with self.lock:
            if self.rx_open:
                raise _err(errno.EBUSY, "the RX buffer is already open")
            m = self.medium
            if m.transmitter is not None:  # the same clock: TX and RX samples are simultaneous
                self.rx_cursor = max(self.rx_cursor, m.tx_len)
            m.idle_until(self.rx_cursor)
            self.rx_frontier = self.rx_cursor
            self.rx_open = True
            self.rx_opened_at = (time.monotonic(), self.rx_cursor)

    def close_rx(self) -> None:
        with self.lock:
            self.rx_open = False
        self.medium.notify()

    def read_rx(self, num_samples: int) -> np.ndarray | None:
        """The next ``num_samples`` received, [2 * num_samples] int16 (I, Q), paced to at most
        the sample rate since the buffer opened; None when the connection is to drop."""
        if self.drop_after_samples is not None:
            left = self.drop_after_samples - self.samples_received
            if left <= 0:
                self.dropped.set()
                return None
            num_samples = min(num_samples, left)
        if self.slow_after_samples is not None:
            left = self.slow_after_samples - self.samples_received
            if left <= 0:  # late; a client that gave up has closed the connection by then
                self.stalled.set()
                self.dropped.wait(SLOW_REPLY_S)
            else:
                num_samples = min(num_samples, left)
        t0, k0 = self.rx_opened_at
        due = t0 + (self.rx_cursor + num_samples - k0) / self.sample_rate_hz
        wait = due - time.monotonic()
        if wait > 0:
            time.sleep(wait)
        with self.lock:
            self.rx_frontier = self.rx_cursor + num_samples
        self._extend_cyclic(num_samples)
        if self.tx_starved and self.medium.tx_streaming:  # still dry: silence, no waiting
            self.medium.idle_until(self.rx_cursor + num_samples + RESAMPLER_TAPS, underrun=True)
        y = self.medium.render_iq(self.rx_port, self.rx_cursor, num_samples, lambda: self.rx_open)
        if y is None and self.rx_open and self.medium.tx_streaming:
            self.tx_starved = True
            # the host did not feed the open TX buffer in time: the DAC underruns (sends
            # silence) and what it writes later goes out later, as on a board
            self.tx_underruns += 1
            self.medium.idle_until(self.rx_cursor + num_samples + RESAMPLER_TAPS, underrun=True)
            y = self.medium.render_iq(self.rx_port, self.rx_cursor, num_samples, lambda: self.rx_open)  # fmt: skip
        if y is None:
            raise _err(errno.ETIMEDOUT, "no samples: the receive wait timed out")
        self.rx_cursor += num_samples
        self.samples_received += num_samples
        keep = int(self.medium.channel.delay_s * self.sample_rate_hz) + 8192  # delay + filters
        self.medium.forget_before(self.rx_cursor - keep)
        inter = y.view(np.float32) * np.float32(RX_FULL_SCALE)
        return np.clip(np.rint(inter), -RX_FULL_SCALE, RX_FULL_SCALE - 1).astype(np.int16)

    def _extend_cyclic(self, num_samples: int) -> None:
        """A cyclic TX buffer repeats: append copies until the receiver's next read is covered."""
        cyc = self.tx_cyclic
        if cyc is None:
            return
        m = self.medium
        fs = self.sample_rate_hz
        need = int((self.rx_cursor + num_samples) + m.channel.delay_s * fs) + 4096 + len(m.channel.taps)  # fmt: skip
        while m.tx_len < need:
            m.append_tx_iq(self.tx_port, cyc)

    def open_tx(self, cyclic: bool) -> None:
        with self.lock:
            if self.tx_open:
                raise _err(errno.EBUSY, "the TX buffer is already open")
            self.tx_open = True
            self.tx_cyclic = None
            self.tx_is_cyclic = bool(cyclic)
            # what is sent starts at the receiver's now: after the read in flight, if any
            self.medium.idle_until(self.rx_frontier)
            self.medium.start_tx(self.tx_port)

    def write_tx(self, raw: np.ndarray) -> None:
        """[2 * num_samples] int16 I, Q from the host; the DAC keeps the 12 MSBs."""
        self.tx_starved = False
        x = ((raw.astype(np.int32) >> 4) << 4).astype(np.float32) / np.float32(TX_FULL_SCALE)
        iq = x.view(np.complex64)
        if self.tx_is_cyclic:
            self.tx_cyclic = iq.copy()
            self.medium.end_tx(self.tx_port)  # repeats on demand, never waited for
        else:
            self.medium.append_tx_iq(self.tx_port, iq)

    def close_tx(self) -> None:
        with self.lock:
            self.tx_open = False
            self.tx_cyclic = None
        self.medium.end_tx(self.tx_port)


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

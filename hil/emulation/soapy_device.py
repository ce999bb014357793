"""An emulated SDR as SoapySDR sees it: :class:`EmulatedSoapyDevice`.

What a Soapy driver answers (identification, frequency, sample rate and gain with their
ranges, stream formats, settings) over the board of :class:`hil.EmulatedPluto` (an AD9363
whose TX loops to its RX through a :class:`hil.Medium`): the same LO grid, clock chain,
gain tables and pacing, so a Soapy client sees the ranges and quantisation of a real part.
Samples cross as the board's own: CS16, RX full scale 2048 (12-bit ADC), TX full scale
32767 (the DAC's 12 MSBs of int16). :class:`hil.emulation.soapy_remote.SoapyRemoteServer`
serves one over SoapyRemote's protocol.

The receive side keeps :data:`BUFFER_S` of samples in blocks (the board's DMA blocks,
:class:`hil.emulation.pacing.BlockQueue`): a reader later than that (the host stopped
reading, and the stream's flow-control window filled) loses whole blocks, and the stream
reports ``SOAPY_SDR_OVERFLOW`` before the samples that follow the gap, as a device does.

Faults (``osnerf hil emulate soapy --fault``): ``overflow`` (once, after ``after_samples``
received samples, the board loses :data:`OVERFLOW_LOST_SAMPLES` and the receive stream
reports ``SOAPY_SDR_OVERFLOW``), ``drop`` (the board dies: every connection closes).
"""

from __future__ import annotations

import threading

import numpy as np

from hil.emulation.pluto import EmulatedPluto
from hil.emulation.pluto_attrs import parse_air_setting
from hil.pluto import ad9361
from hil.pluto.ad9361 import RX_FULL_SCALE, TX_FULL_SCALE
from hil.pluto.context import PHY, air_setting

TX, RX = 0, 1  # SOAPY_SDR_TX, SOAPY_SDR_RX
DRIVER_KEY = "osnerf"
AIR_SETTING = "emulated_air"
"""The setting through which a host sets the emulated air (``hil.SoapyRadio.set_air``):
the JSON of ``hil.pluto.context.air_setting``."""
SOAPY_FAULTS = ("overflow", "drop")
OVERFLOW_LOST_SAMPLES = 8192
NATIVE_FORMAT = "CS16"
BUFFER_S = 0.5  # samples the device keeps for a late reader, seconds
BLOCK_SAMPLES = 1 << 15


class EmulatedSoapyDevice:
    """One emulated device (thread-safe): Soapy's calls over an emulated AD9363 board.

    Args:
        board: the board (its air, crystal and settings).
        overflow_after_samples: inject one receive overflow after this many samples
            received in the board's life; None: never.
        air_settable: the host may set the air through :data:`AIR_SETTING`.
        serial: what ``serial`` reports.
    """

    def __init__(
        self,
        board: EmulatedPluto,
        *,
        overflow_after_samples: int | None = None,
        air_settable: bool = True,
        serial: str = "0e5a3f7c",
    ):
        self.board = board
        self.overflow_after_samples = overflow_after_samples
        self.air_settable = air_settable
        self.serial = serial
        self.overflows = 0  # overflows reported to a receive stream
        self._injected = False
        self._lost_runs = 0  # the open buffer's runs of lost blocks, as last reported
        self.lock = threading.RLock()
        board.write_attr(PHY, "voltage0", False, "", "gain_control_mode", "manual")

    @classmethod
    def for_link(
        cls,
        snr_db: float,
        *,
        seed: int = 0,
        multipath=(),
        delay_s: float = 0.0,
        fault: str | None = None,
        after_samples: int = 50_000,
        ppm: float = 0.0,
        air_settable: bool = True,
    ) -> EmulatedSoapyDevice:
        """A device whose TX-to-RX loop has ``snr_db`` for the over-the-air frames at the
        board's default gains (see :meth:`hil.EmulatedPluto.for_link`).

        Args:
            fault: one of :data:`SOAPY_FAULTS` or None.
            after_samples: received samples before the fault.
        """
        if fault is not None and fault not in SOAPY_FAULTS:
            raise KeyError(f"unknown fault {fault!r}; known: {', '.join(SOAPY_FAULTS)}")
        board = EmulatedPluto.for_link(
            snr_db,
            seed=seed,
            multipath=multipath,
            delay_s=delay_s,
            fault="drop" if fault == "drop" else None,
            after_samples=after_samples,
            ppm=ppm,
            air_settable=air_settable,
        )
        over = int(after_samples) if fault == "overflow" else None
        return cls(board, overflow_after_samples=over, air_settable=air_settable)

    # ------------------------------------------------------------------ the board's state
    @property
    def dropped(self):
        return self.board.dropped

    @property
    def stalled(self):
        return self.board.stalled

    @property
    def tx_underruns(self) -> int:
        return self.board.tx_underruns

    @property
    def samples_received(self) -> int:
        return self.board.samples_received

    # ------------------------------------------------------------------ identification
    def enumerate(self) -> list[dict[str, str]]:
        return [{"driver": DRIVER_KEY, "label": self.label, "serial": self.serial}]

    @property
    def label(self) -> str:
        return f"osnerf emulated AD9363 :: {self.serial}"

    def hardware_info(self) -> dict[str, str]:
        return {"part": "AD9363 (emulated)", "serial": self.serial, "emulated": "true"}

    # ------------------------------------------------------------------ tuning
    def frequency_range(self, direction: int) -> list[tuple]:
        return [(*ad9361.LO_RANGE_HZ, 0.0)]

    def sample_rate_range(self, direction: int) -> list[tuple]:
        return [(*ad9361.SAMPLE_RATE_RANGE_HZ, 0.0)]

    def gain_range(self, direction: int) -> tuple:
        if direction == TX:
            return (-ad9361.TX_ATTENUATION_RANGE_DB[1], 0.0, ad9361.TX_ATTENUATION_STEP_DB)
        lo, hi = ad9361.rx_gain_range_db(self.board.rx_lo_hz)
        return (float(lo), float(hi), 1.0)

    def set_frequency(self, direction: int, value_hz: float) -> None:
        chan = "altvoltage1" if direction == TX else "altvoltage0"
        self._write(chan, True, "frequency", str(int(round(value_hz))))

    def frequency(self, direction: int) -> float:
        return float(self.board.tx_lo_hz if direction == TX else self.board.rx_lo_hz)

    def set_sample_rate(self, direction: int, rate_hz: float) -> None:
        self._write("voltage0", False, "sampling_frequency", str(int(round(rate_hz))))

    def sample_rate(self, direction: int) -> float:
        return float(self.board.sample_rate_hz)

    def set_gain(self, direction: int, gain_db: float) -> None:
        self._write("voltage0", direction == TX, "hardwaregain", repr(float(gain_db)))

    def gain(self, direction: int) -> float:
        b = self.board
        return float(b.tx_gain_db if direction == TX else b.rx_gain_db)

    def _write(self, chan: str, output: bool, attr: str, value: str) -> None:
        try:
            self.board.write_attr(PHY, chan, output, "", attr, value)
        except OSError as e:
            raise ValueError(e.strerror or str(e)) from None

    # ------------------------------------------------------------------ settings
    def setting_info(self) -> list[dict]:
        if not self.air_settable:
            return []
        return [
            {
                "key": AIR_SETTING,
                "name": "Emulated air",
                "description": "the emulated TX-to-RX air, crystal and noise seed (JSON)",
                "type": 3,  # SoapySDR::ArgInfo::STRING
            }
        ]

    def write_setting(self, key: str, value: str) -> None:
        if key != AIR_SETTING or not self.air_settable:
            raise ValueError(f"no setting {key!r}")
        channel, ppm, seed = parse_air_setting(value)
        b = self.board
        if b.rx_open or b.tx_open:
            raise ValueError(f"{AIR_SETTING}: a stream is active; set the air between bursts")
        b.medium.set_channel(channel, seed)
        b.ppm = ppm

    def read_setting(self, key: str) -> str:
        if key != AIR_SETTING or not self.air_settable:
            raise ValueError(f"no setting {key!r}")
        b = self.board
        return air_setting(b.medium.channel, b.ppm, b.medium.seed)

    # ------------------------------------------------------------------ samples
    @staticmethod
    def full_scale(direction: int) -> float:
        return float(TX_FULL_SCALE if direction == TX else RX_FULL_SCALE)

    def open_rx(self) -> None:
        """Start receiving "now", with :data:`BUFFER_S` of blocks for a late reader."""
        b = self.board
        blocks = max(2, round(BUFFER_S * b.sample_rate_hz / BLOCK_SAMPLES))
        b.open_rx(block_samples=BLOCK_SAMPLES, num_blocks=blocks)
        self._lost_runs = 0

    def read(self, num_samples: int) -> tuple[np.ndarray | None, bool]:
        """``([2 * n] int16 I, Q or None when the board dropped, overflowed)``: the next
        samples of the open receive stream; ``overflowed``: samples were lost before them
        (the reader was late, or the injected fault)."""
        b = self.board
        limit = self.overflow_after_samples
        if limit is not None and b.samples_received < limit:
            num_samples = min(num_samples, limit - b.samples_received)
        overflowed = False
        if limit is not None and b.samples_received >= limit and not self._injected:
            self._injected = overflowed = True
            if b.read_rx(OVERFLOW_LOST_SAMPLES) is None:  # the lost samples, never delivered
                self.overflows += 1
                return None, True
        raw = b.read_rx(num_samples)
        q = b.rx_blocks
        if q is not None and q.overruns > self._lost_runs:  # blocks lost before these
            self._lost_runs = q.overruns
            overflowed = True
        self.overflows += overflowed
        return raw, overflowed

    def write(self, raw: np.ndarray) -> None:
        """[2 * n] int16 I, Q to transmit; opens a burst if none is open."""
        b = self.board
        if not b.tx_open:
            b.open_tx(cyclic=False)
        b.write_tx(raw)

    def end_burst(self) -> None:
        if self.board.tx_open:
            self.board.close_tx()

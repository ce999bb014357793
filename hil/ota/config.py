"""Radio settings and framing of an over-the-air run (:class:`OtaConfig`)."""

from __future__ import annotations

from dataclasses import dataclass

from hil.hackrf.protocol import FREQ_RANGE_HZ
from hil.ota.header import HEADER_BITS
from hil.pluto.ad9361 import DEFAULT_RX_GAIN_DB, DEFAULT_TX_GAIN_DB


@dataclass(frozen=True)
class OtaConfig:
    """Radio settings and framing of an over-the-air run.

    Attributes:
        sample_rate_hz: both radios, 2-20 MS/s.
        center_freq_hz: both radios, Hz.
        symbols_per_frame: data symbols per frame (after the header), >= 64.
        header_repeat: repetitions of each header bit, >= 1.
        max_papr_db: PAPR limit of each frame's waveform, dB; the burst's mean power is
            ``-max_papr_db`` dBFS so the clipped peak is full scale.
        gap_samples: silence before, between and after frames, samples.
        rx_margin_samples: extra samples captured after the burst.
        rx_lead_s: the transmitter starts this long after the receiver streams, s (the
            capture is longer by as many samples).
        detection_threshold: the receiver's normalised coherent preamble metric that counts
            as a frame, in (0, 1) (``phy.FrameConfig.detection_threshold``: in noise alone it
            is Beta(1, N - 1) distributed, so 0.015 with the 2048-sample preamble
            has a false-alarm probability of 4e-14 per lag and CFO hypothesis); a
            detection where no frame of the burst starts is dropped.
        lna_gain_db, vga_gain_db, txvga_gain_db: HackRF gains (quantised by the driver).
        ad9361_rx_gain_db, ad9361_tx_gain_db: Pluto (AD9361) gains: manual RX gain, and TX
            gain (minus the attenuation, <= 0), dB.
        max_rx_overruns: receive overruns (lost samples) tolerated before the capture
            fails with :class:`hil.StreamError` (None: warn only).
        soapy_rx_gain_db, soapy_tx_gain_db: a SoapySDR device's overall RX and TX gains, dB,
            checked against its ``getGainRange``; None leaves the device's own.
    """

    sample_rate_hz: float = 4e6
    center_freq_hz: float = 2.45e9
    symbols_per_frame: int = 2048
    header_repeat: int = 8
    max_papr_db: float = 9.0
    gap_samples: int = 2000
    rx_margin_samples: int = 20000
    rx_lead_s: float = 0.02
    detection_threshold: float = 0.015
    lna_gain_db: float = 16
    vga_gain_db: float = 24
    txvga_gain_db: float = 30
    ad9361_rx_gain_db: float = DEFAULT_RX_GAIN_DB
    ad9361_tx_gain_db: float = DEFAULT_TX_GAIN_DB
    max_rx_overruns: int | None = None
    soapy_rx_gain_db: float | None = None
    soapy_tx_gain_db: float | None = None

    def __post_init__(self):
        if not 2e6 <= self.sample_rate_hz <= 20e6:
            raise ValueError(f"sample_rate_hz must be in [2e6, 20e6], got {self.sample_rate_hz!r}")
        lo, hi = FREQ_RANGE_HZ
        if not lo <= self.center_freq_hz <= hi:
            raise ValueError(
                f"center_freq_hz must be in [{lo:g}, {hi:g}] Hz, got {self.center_freq_hz!r}"
            )
        if self.max_rx_overruns is not None and self.max_rx_overruns < 0:
            raise ValueError(f"max_rx_overruns must be >= 0 or None, got {self.max_rx_overruns!r}")
        if not isinstance(self.symbols_per_frame, int) or self.symbols_per_frame < 64:
            raise ValueError(
                f"symbols_per_frame must be an integer >= 64, got {self.symbols_per_frame!r}"
            )
        if not isinstance(self.header_repeat, int) or not 1 <= self.header_repeat <= 64:
            raise ValueError(
                f"header_repeat must be an integer in [1, 64], got {self.header_repeat!r}"
            )
        if not 3.0 <= self.max_papr_db <= 20.0:
            raise ValueError(f"max_papr_db must be in [3, 20] dB, got {self.max_papr_db!r}")
        if not 0 < self.detection_threshold < 1:
            raise ValueError(
                f"detection_threshold must be in (0, 1), got {self.detection_threshold!r}"
            )
        if not 0 <= self.rx_lead_s <= 1:
            raise ValueError(f"rx_lead_s must be in [0, 1] s, got {self.rx_lead_s!r}")
        if self.gap_samples < 0 or self.rx_margin_samples < 0:
            raise ValueError("gap_samples and rx_margin_samples must be >= 0")

    @property
    def tx_power_dbfs(self) -> float:
        """Mean power of the transmitted frames, dB re full scale."""
        return -self.max_papr_db

    @property
    def header_symbols(self) -> int:
        return HEADER_BITS * self.header_repeat

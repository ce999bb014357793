"""`osnerf ota`'s configuration: :class:`OtaRunConfig`, every flag of one run as it applies.

:func:`osnerf.commands.ota.run` checks the parsed flags (:mod:`osnerf.commands.ota_radios`,
:mod:`osnerf.commands.ota_stream`), decides what each left-out flag takes (its default where
it is used, null where it is not) and builds one ``OtaRunConfig``; everything after reads
that, never the argparse namespace. Its fields are the flags in ``--help`` order and then
``air``; :meth:`OtaRunConfig.as_record` is the result file's ``config``.
"""

from __future__ import annotations

import argparse
import dataclasses
from dataclasses import dataclass


@dataclass(frozen=True)
class OtaRunConfig:
    """One `osnerf ota` run, checked, with every default applied.

    Attributes:
        uri: pluto: the board's libiio URI (the one found when ``--uri`` was left out);
            None for the other radios.
        tx, rx: ``--tx``/``--rx`` as given ("emulated", "loopback", "hackrf:SERIAL", ...).
        tx_args, rx_args: soapy: the transmitter's and receiver's SoapySDR device strings.
        schemes: the link schemes sent, each in its own burst (one with ``stream``).
        snr_db: the emulated air's SNR, dB; None for a real air (measured instead).
        images: the image file or folder.
        out: the result JSON path, as given.
        sigmf_dir: the SigMF folder as given; None: ``<out>_sigmf`` beside ``out``.
        overwrite: an existing result and its captures may be replaced.
        seed: the emulated air's seed; None for a real air.
        ppm: the emulated crystal errors as ``"TX,RX"`` ppm; None for a real air.
        multipath: the emulated echoes, ``"delay_samples:gain,..."`` or ``"none"``; None for
            a real air.
        delay_us: the emulated propagation delay, microseconds; None for a real air.
        size: images are centre-cropped and resized to ``size x size`` px.
        max_images: at most this many images are sent.
        mcs, image_codec, quality, scale: the digital schemes' settings (None when no
            digital scheme is sent).
        cbr, codec: the jscc schemes' channel symbols per source value (text, ``"1/16"``)
            and semantic codec (None: jscc with the shipped checkpoint, or no jscc scheme).
        allow_untrained: a codec without trained weights may run (labelled so).
        sample_rate_hz, center_freq_hz, max_papr_db: the radio configuration
            (:class:`hil.OtaConfig`'s fields, as are the next four).
        symbols_per_frame, detection_threshold: symbols per frame, the detector's threshold.
        max_rx_overruns: receive overruns tolerated (None with a Pluto, which counts none).
        soapy_rx_gain_db, soapy_tx_gain_db: a SoapySDR device's gains, dB (None: its own).
        fault: the emulated USB fault injected into the receiver, or None.
        stream: views go out one after another to a receiver that streams without pause.
        views, view_interval_s, ring_s, emulator_cpus: the stream's views (None: one per
            image), their interval, s, the receiver's ring buffer, s, and the CPUs of the
            emulated boards' process (None: those of this process); all None without
            ``stream``.
        air: "emulated" (the run sets the air from the air flags) or "real".
    """

    uri: str | None
    tx: str
    rx: str
    tx_args: str | None
    rx_args: str | None
    schemes: tuple[str, ...]
    snr_db: float | None
    images: str
    out: str
    sigmf_dir: str | None
    overwrite: bool
    seed: int | None
    ppm: str | None
    multipath: str | None
    delay_us: float | None
    size: int
    max_images: int
    mcs: str | None
    image_codec: str | None
    quality: int | None
    scale: int | None
    cbr: str | None
    codec: str | None
    allow_untrained: bool
    sample_rate_hz: float
    center_freq_hz: float
    max_papr_db: float
    symbols_per_frame: int
    detection_threshold: float
    max_rx_overruns: int | None
    soapy_rx_gain_db: float | None
    soapy_tx_gain_db: float | None
    fault: str | None
    stream: bool
    views: int | None
    view_interval_s: float | None
    ring_s: float | None
    emulator_cpus: tuple[int, ...] | None
    air: str

    @classmethod
    def from_args(cls, args: argparse.Namespace, **resolved) -> OtaRunConfig:
        """The flags as parsed, each one the checks decided (a default, the board found,
        ``air``) taken from ``resolved`` instead."""
        given = vars(args)
        names = [f.name for f in dataclasses.fields(cls)]
        return cls(**{n: given[n] for n in names if n not in resolved}, **resolved)

    def as_record(self) -> dict:
        """The result file's ``config``: every field, in order."""
        return dataclasses.asdict(self)

"""`osnerf ota`: send images over the air (HackRF One or ADALM-Pluto; real, emulated or loopback).

    osnerf ota --tx emulated --rx emulated --schemes digital,jscc --snr-db 15 \\
        --images DIR --out ota.json

Schemes: the link schemes of ``semcodec.LINK_SCHEMES`` with a framed transmitter and
receiver (``LinkScheme.framed``, :mod:`semcodec.links.framed`): ``digital`` (image codec bytes ->
per-frame CRC + 5G LDPC + QAM from ``phy.digital``) and ``jscc`` (the semantic codec's
symbols). Either way the symbols cross an :class:`osnerf.ota_link.OtaLink`: ``phy``'s OFDM
frames (preamble, pilots), ``hil``'s PAPR control and int8 scaling, out of the TX HackRF
and into the RX HackRF. Emulated boards sit ``--ppm`` apart with
``--multipath`` and ``--delay-us`` at ``--snr-db``. The result file reports per image the
PSNR, the SNR measured from the pilots, frames sent and lost, and lists the SigMF files.
Each scheme of ``--schemes`` goes in its own burst, one after another, with its own capture
(``ota`` for one scheme, ``ota_<scheme>`` for several).
A digital image whose frames do not all pass their CRC is shown as mid-grey (PSNR of that).

``--tx pluto --rx pluto [--uri URI]`` uses one ADALM-Pluto (full duplex) as both ends, real or
emulated (``osnerf hil emulate pluto``), whose air the run sets from the same flags. Between
real radios the air flags are refused (:mod:`osnerf.commands.ota_radios`); results carry the
measured SNR beside the requested one.

``--stream`` keeps the receiver streaming while views go out one after another, decoded
as they arrive (:mod:`osnerf.commands.ota_stream`).

``--fault`` switches on an emulated USB fault of the receiving board (stall, rx-timeout,
unplug, overrun) to rehearse how a run reports it: exit 1 with a one-line message, and the
capture so far saved as SigMF (``<sigmf-dir>/ota_rx_partial``).
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path

from common import load_square_images
from hil import OtaConfig, save_sigmf
from hil.emulation import AIR_SNR_DB_RANGE, FAULT_NAMES, MAX_DELAY_S
from hil.hackrf import FREQ_RANGE_HZ, SAMPLE_RATE_RANGE_HZ
from osnerf.cli import inputs_checked
from osnerf.commands import args as checks
from osnerf.commands.config_cli import add_config_arguments, config_from_args, finite
from osnerf.commands.ota_args import (
    DEVICE_KINDS,
    URI_FORMATS,
    parse_multipath,
    parse_ppm,
    parse_uri,
    usage_error,
)
from osnerf.commands.ota_config import OtaRunConfig
from osnerf.commands.ota_radios import (
    DEFAULT_MULTIPATH,
    air_is_emulated,
    check_overruns,
    check_radio_ranges,
    check_scheme_flags,
    device_kinds,
    measured_snr_db,
    resolve_air,
    send_over_the_air,
)
from osnerf.commands.ota_record import ota_record, remove_old_captures
from osnerf.commands.ota_stream import add_stream_arguments, check_stream_flags, run_stream
from osnerf.ota_link import received_blocks
from osnerf.provenance import open_codec, write_json_atomic
from phy import parse_cbr
from phy.digital import MCS_TABLE
from semcodec import LINK_SCHEMES, codec_names, require_capabilities
from semcodec.digital import IMAGE_CODECS, SCALES
from semcodec.links import ANALOG, DIGITAL, FramedSettings, frame_payload_bytes

MAX_IMAGES = 10_000
OTA_CONFIG_FIELDS = (
    "sample_rate_hz",
    "center_freq_hz",
    "max_papr_db",
    "symbols_per_frame",
    "detection_threshold",
    "max_rx_overruns",
    "soapy_rx_gain_db",
    "soapy_tx_gain_db",
)
OTA_FLAGS = {
    "max_rx_overruns": "--max-overruns",
    "soapy_rx_gain_db": "--rx-gain-db",
    "soapy_tx_gain_db": "--tx-gain-db",
}


def check_codec_snr(codec, snr_db: float) -> None:
    """Refuse an ``--snr-db`` outside the SNR range the codec (``semcodec.open_codec``)
    declares."""
    lo, hi = codec.snr_range_db
    if not lo <= snr_db <= hi:
        raise usage_error(
            f"--snr-db {snr_db:g} dB is not covered by checkpoint {codec.name!r}, trained for "
            f"SNR [{lo:g}, {hi:g}] dB"
        )


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options, in ``--help`` order: the radios, what is sent, the emulated air, the
    images, each scheme's settings, the radio configuration, the stream."""
    _add_radio_arguments(p)
    framed = [k for k, v in LINK_SCHEMES.items() if v.over_the_air]
    p.add_argument(
        "--schemes",
        required=True,
        type=checks.names_from(framed, "--schemes"),
        help=f"comma-separated, each sent in its own burst: {', '.join(framed)} (digital: "
        "image codec + LDPC + QAM at --mcs; jscc: the semantic codec at --cbr; softcast: "
        "DCT chunks at --cbr)",
    )
    p.add_argument(
        "--snr-db",
        type=checks.number(*AIR_SNR_DB_RANGE, "dB"),
        default=None,
        help="air SNR of emulated boards (two emulated HackRFs, or an emulated Pluto), dB "
        "(default 15); refused with real radios",
    )
    p.add_argument(
        "--images", required=True, help="an image file, or a folder of images (png, jpg, ...)"
    )
    p.add_argument("--out", required=True, help="result JSON path")
    p.add_argument(
        "--sigmf-dir", default=None, help="SigMF folder (default: <out>_sigmf beside --out)"
    )
    checks.add_overwrite(p, "--out and the SigMF files in --sigmf-dir")
    _add_air_arguments(p)
    p.add_argument(
        "--size",
        type=checks.count(8, 1024),
        default=64,
        help="images are centre-cropped and resized to SIZE x SIZE, 8..1024 px; never "
        "upscaled (default 64)",
    )
    p.add_argument(
        "--max-images",
        type=checks.count(1, MAX_IMAGES),
        default=4,
        help=f"send at most this many images, 1..{MAX_IMAGES} (default 4)",
    )
    _add_scheme_arguments(p)
    _add_ota_config_arguments(p)
    add_stream_arguments(p)


def _add_radio_arguments(p: argparse.ArgumentParser) -> None:
    """Which radios are the two ends of the link."""
    dev = f"one of {', '.join(DEVICE_KINDS)}; 'hackrf:SERIAL' picks a board by serial (tail)"
    p.add_argument(
        "--uri",
        default=None,
        type=parse_uri,
        help=f"pluto: libiio URI of the board, {URI_FORMATS} (default: the first found; one "
        "Pluto is both ends of the link)",
    )
    p.add_argument("--tx", default="emulated", help=f"transmitter: {dev} (default emulated)")
    p.add_argument("--rx", default="emulated", help=f"receiver: {dev} (default emulated)")
    p.add_argument(
        "--tx-args",
        default=None,
        help="soapy: the transmitter's SoapySDR device string, e.g. 'driver=uhd,type=b200' or "
        "'driver=remote,remote=tcp://127.0.0.1:55132' (default: the first device found)",
    )
    p.add_argument(
        "--rx-args",
        default=None,
        help="soapy: the receiver's device string (default --tx-args: one full-duplex device "
        "is both ends)",
    )


def _add_ota_config_arguments(p: argparse.ArgumentParser) -> None:
    """The radio configuration (:class:`hil.OtaConfig`'s fields) and an emulated fault."""
    add_config_arguments(
        p,
        OtaConfig,
        OTA_CONFIG_FIELDS,
        flags=OTA_FLAGS,
        types={
            "sample_rate_hz": checks.number(*SAMPLE_RATE_RANGE_HZ, "Hz"),  # then each radio's
            "center_freq_hz": checks.number(*FREQ_RANGE_HZ, "Hz"),
            "max_papr_db": finite,  # OtaConfig's own check names its range
            "symbols_per_frame": checks.count(64, 1 << 20),
            "detection_threshold": checks.number(0.0, 1.0),
            "max_rx_overruns": checks.count(0, 1_000_000),
            "soapy_rx_gain_db": finite,  # then the device's getGainRange (ota_radios)
            "soapy_tx_gain_db": finite,
        },
        defaults={"max_rx_overruns": 0},  # a lost sample fails a run from the command line
    )
    p.set_defaults(max_rx_overruns=None)  # 0 where the radio counts overruns (ota_radios)
    p.add_argument(
        "--fault",
        default=None,
        choices=FAULT_NAMES,
        help="emulated boards: inject this USB fault into the receiver, to see how a run "
        "reports it (exit 1; the capture so far is saved as SigMF)",
    )


def _add_air_arguments(p: argparse.ArgumentParser) -> None:
    """The emulated air between the boards: seed, crystal errors, echoes, delay (refused
    with real radios, :mod:`osnerf.commands.ota_radios`)."""
    p.add_argument(
        "--seed", type=checks.seed, default=None, help="seed of the emulated air (default 0)"
    )
    p.add_argument(
        "--ppm",
        default=None,
        help="crystal errors of emulated TX,RX in ppm (default 0,20; one Pluto is one "
        "crystal: TX equal to RX, default 0,0)",
    )
    p.add_argument(
        "--multipath",
        default=None,
        help=f"echoes 'delay_samples:gain,...' or 'none' (default {DEFAULT_MULTIPATH})",
    )
    p.add_argument(
        "--delay-us",
        type=checks.number(0.0, MAX_DELAY_S * 1e6, "us"),
        default=None,
        help="propagation delay, microseconds (default 5)",
    )


def _add_scheme_arguments(p: argparse.ArgumentParser) -> None:
    """The options of the digital scheme (MCS, image codec, quality) and of jscc (CBR, codec)."""
    p.add_argument(
        "--mcs",
        default=None,
        choices=tuple(MCS_TABLE),
        metavar="MCS",
        help=f"digital: modulation and coding, one of {', '.join(MCS_TABLE)} (default qpsk-1/2)",
    )
    p.add_argument(
        "--image-codec",
        default=None,
        choices=list(IMAGE_CODECS),
        help="digital: image codec (default avif)",
    )
    p.add_argument(
        "--quality",
        type=int,
        default=None,
        help="digital: codec quality, 1-100 (JPEG 1-95; default 50)",
    )
    p.add_argument(
        "--scale",
        type=int,
        default=None,
        choices=SCALES,
        help="digital: send the image downscaled by this factor, upscaled (Lanczos) at the "
        "receiver; for low rates at low SNR (default 1: whole)",
    )
    p.add_argument(
        "--cbr", default=None, help="jscc: channel symbols per source value (default 1/16)"
    )

    p.add_argument(
        "--codec",
        default=None,
        metavar="NAME[:CHECKPOINT]",
        help=f"jscc: the semantic codec, one of {', '.join(codec_names())} (plugins through "
        "the semcodec.codecs entry points), optionally with a checkpoint, or a checkpoint path "
        "(default: jscc with the shipped checkpoint)",
    )
    checks.add_allow_untrained(p)


# ----------------------------------------------------------------------------- run
def framed_settings(opts: OtaRunConfig, symbols_per_frame: int):
    """The scheme's ``semcodec.links.FramedSettings`` from the flags, checked: ``--quality`` in the
    image codec's range; jscc: ``--cbr`` and the codec (``--snr-db`` within its range);
    digital: a frame holds payload at ``--mcs``."""
    qlo, qhi = IMAGE_CODECS[opts.image_codec or "avif"].quality_range
    if opts.quality is not None and not max(qlo, 1) <= opts.quality <= qhi:
        raise usage_error(
            f"--quality of {opts.image_codec} must be in [{max(qlo, 1)}, {qhi}], got {opts.quality}"
        )
    cbr, codec = FramedSettings.cbr, None
    analog = any(LINK_SCHEMES[name].kind == ANALOG for name in opts.schemes)
    if analog and opts.cbr is not None:  # an analog scheme sends at --cbr too
        try:
            cbr = parse_cbr(opts.cbr)
        except ValueError as e:
            raise usage_error(f"--{e}") from None
    if any(LINK_SCHEMES[name].needs_codec for name in opts.schemes):
        try:
            cbr = parse_cbr(opts.cbr)
        except ValueError as e:
            raise usage_error(f"--{e}") from None
        codec = open_codec(opts.codec, opts.allow_untrained)
        if opts.snr_db is not None:  # a real air: the encoder's SNR is measured first
            check_codec_snr(codec, opts.snr_db)
        limits = require_capabilities(codec)  # ota does not refine: nothing is refused
        if limits.line():
            print(f"ota: {limits.line()}", file=sys.stderr)
    digital = any(LINK_SCHEMES[name].kind == DIGITAL for name in opts.schemes)
    if digital and frame_payload_bytes(symbols_per_frame, opts.mcs) < 1:
        raise usage_error(
            f"--symbols-per-frame {symbols_per_frame} holds no payload at --mcs {opts.mcs}"
        )
    used = {
        "mcs": opts.mcs,
        "image_codec": opts.image_codec,
        "quality": opts.quality,
        "scale": opts.scale,
    }
    return FramedSettings(
        snr_db=opts.snr_db,
        symbols_per_frame=symbols_per_frame,
        **{k: v for k, v in used.items() if v is not None},
        cbr=cbr,
        codec=codec,
    )


def run(args: argparse.Namespace) -> int:
    """Check the flags into an :class:`OtaRunConfig` (exit 2 on a refusal), then send."""
    kind, tx_id, rx_id = device_kinds(args)
    scheme_flags = check_scheme_flags(args)
    check_radio_ranges(args, kind, (tx_id, rx_id))
    max_rx_overruns = check_overruns(args, kind)
    stream_flags = check_stream_flags(args, kind)
    parse_ppm(args.ppm or "0,0")
    parse_multipath(args.multipath or "none")
    cfg = config_from_args(
        OtaConfig, args, OTA_CONFIG_FIELDS, flags=OTA_FLAGS, max_rx_overruns=max_rx_overruns
    )
    inputs = {"--images": args.images}
    out = checks.output_file(args.out, "--out", overwrite=args.overwrite, inputs=inputs)
    sigmf_dir = Path(args.sigmf_dir) if args.sigmf_dir else out.with_name(out.stem + "_sigmf")
    checks.output_dir(sigmf_dir, "--sigmf-dir", overwrite=args.overwrite, inputs=inputs)
    names, images = load_square_images(
        args.images, args.size, args.max_images, "--images", "--size"
    )
    emulated, found_uri = air_is_emulated(kind, tx_id, rx_id)  # asks the board
    opts = OtaRunConfig.from_args(
        args,
        **scheme_flags,
        max_rx_overruns=max_rx_overruns,
        **stream_flags,
        **resolve_air(args, kind, emulated),
        uri=args.uri if found_uri is None else found_uri,
    )
    settings = framed_settings(opts, cfg.symbols_per_frame)
    inputs_checked()  # from here on a failure is a runtime failure (exit 1)
    return send(opts, cfg, settings, names, images, out, sigmf_dir)


def send(opts: OtaRunConfig, cfg, settings, names, images, out: Path, sigmf_dir: Path) -> int:
    """Send ``images`` as ``opts`` says (a burst per scheme, or a stream) and write the result
    to ``out``, the captures to ``sigmf_dir``."""
    if opts.overwrite:  # the whole output set is replaced, captures included
        remove_old_captures(sigmf_dir)
    t0 = time.perf_counter()
    probe: list = []  # a real air: the jscc encoder's SNR is measured first
    if settings.codec is not None and settings.snr_db is None:
        snr, probe = measured_snr_db(opts, cfg, settings, sigmf_dir)
        settings = replace(settings, snr_db=snr)
    if opts.stream:  # views one after another to a receiver that never stops
        return run_stream(opts, cfg, settings, names, images, out, t0, probe)
    bursts = []
    for name in opts.schemes:
        scheme = LINK_SCHEMES[name].framed
        blocks, state = scheme.transmit(images, settings)
        print(
            f"ota: {len(names)} image(s), {sum(len(b) for b in blocks)} symbols, scheme {name}",
            file=sys.stderr,
        )
        base = "ota" if len(opts.schemes) == 1 else f"ota_{name}"
        result, hw = send_over_the_air(opts, cfg, blocks, sigmf_dir, base)
        per_image = scheme.receive(received_blocks(result), state, images, settings)
        for b, rec in enumerate(per_image):  # the receiver's CRC verdicts go with the frames
            for frame, crc_ok in zip(result.block_frames(b), rec.frames_crc_ok):
                frame.crc_ok = crc_ok
        paths = save_sigmf(result, sigmf_dir / base, cfg, hw=hw)
        bursts.append((name, per_image, result, paths))
        print(
            f"ota: {name}: {result.frames_lost}/{result.frames_sent} frames lost", file=sys.stderr
        )
    record = ota_record(opts, cfg, settings, names, bursts, t0)
    record["sigmf"][:0] = [str(p) for p in probe]
    write_json_atomic(out, record)
    print(f"ota: wrote {out}", file=sys.stderr)
    return 0

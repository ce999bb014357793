"""Which of `osnerf ota`'s flags a run applies, decided before any work.

* Scheme flags go to one kind of scheme (``semcodec.links.SCHEME_KINDS``): ``--cbr`` and
  ``--codec`` to jscc, ``--mcs``, ``--image-codec``, ``--quality`` and ``--scale`` to
  digital. One given for a kind that ``--schemes`` does not send is refused; one left out
  takes its default where it is used and is recorded as null where it is not.
* Air flags (``--snr-db``, ``--ppm``, ``--multipath``, ``--delay-us``, ``--seed``) set the
  emulated air: between two emulated HackRFs, or inside an emulated Pluto, whose air the run
  sets through the board (``hil.Pluto.set_air``). Between real radios the air is not ours:
  a given air flag is refused, and each is recorded as null; the result carries the SNR the
  receiver measured.
* Radio ranges: ``--center-freq-hz`` and ``--sample-rate-hz`` within the chosen radio's own
  (``hil.DEVICES``: a Pluto's AD9363 tunes 325 MHz to 3.8 GHz).

The checks read the parsed flags and return the values they decide; the run's
:class:`osnerf.commands.ota_config.OtaRunConfig` is built from them, and the functions after
the checks (opening the radios, sending) read that.
"""

from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

from common import Registry
from hil import DEVICES as HARDWARE
from hil import HilError, Pluto, SoapyRadio, save_partial_capture, save_sigmf
from hil.emulation import Faults
from osnerf.commands.ota_args import parse_device, parse_multipath, parse_ppm, usage_error
from osnerf.commands.ota_config import OtaRunConfig
from osnerf.ota_link import OtaLink, open_radios
from semcodec import LINK_SCHEMES

SIMULATED = ("emulated", "loopback")  # two emulated HackRFs, with or without USB
DEFAULT_MULTIPATH = "2:0.4,5:0.2j"

# dest -> (flag, the scheme kind it applies to, its default there)
SCHEME_FLAGS = Registry[tuple[str, str, object]](
    "ota scheme flag",
    {
        "cbr": ("--cbr", "jscc", "1/16"),
        "codec": ("--codec", "jscc", None),  # None: jscc with the shipped checkpoint
        "mcs": ("--mcs", "digital", "qpsk-1/2"),
        "image_codec": ("--image-codec", "digital", "avif"),
        "quality": ("--quality", "digital", 50),
        "scale": ("--scale", "digital", 1),
    },
)

# dest -> (flag, its default on an emulated air; ppm's depends on the radios)
AIR_FLAGS = Registry[tuple[str, object]](
    "ota air flag",
    {
        "snr_db": ("--snr-db", 15.0),
        "ppm": ("--ppm", None),
        "multipath": ("--multipath", DEFAULT_MULTIPATH),
        "delay_us": ("--delay-us", 5.0),
        "seed": ("--seed", 0),
    },
)
PPM_DEFAULTS = {"two boards": "0,20", "one board": "0,0"}


def radio_of(kind: str):
    """The ``hil.DeviceKind`` of an ``--tx``/``--rx`` kind (the simulated ones are HackRFs)."""
    return HARDWARE["hackrf" if kind in SIMULATED else kind]


def check_scheme_flags(args: argparse.Namespace) -> dict[str, object]:
    """Refuse a scheme flag for a kind of scheme ``--schemes`` does not send. Returns each
    scheme flag's value: as given, its default where it is left out and used, else None."""
    kinds = {LINK_SCHEMES[name].kind for name in args.schemes}
    given, values = vars(args), {}
    for dest, (flag, kind, default) in SCHEME_FLAGS.items():
        value = given[dest]
        if value is not None and kind not in kinds:
            raise usage_error(
                f"{flag} applies to {kind} schemes only; --schemes {','.join(args.schemes)} "
                f"sends none, so it would be recorded and never used: leave it out"
            )
        values[dest] = default if value is None and kind in kinds else value
    return values


def check_radio_ranges(args: argparse.Namespace, kind: str, ids=(None,)) -> None:
    """``--center-freq-hz`` and ``--sample-rate-hz`` within the radio's own ranges (a
    SoapySDR device's from its ``get*Range``: each of ``ids`` is opened and asked), and a
    SoapySDR device's ``--rx-gain-db``/``--tx-gain-db`` within its ``getGainRange``."""
    hw = radio_of(kind)
    _check_gains(args, kind, ids)
    freq_range, rate_range, part = hw.ranges_of(ids)
    for value, flag, (lo, hi), unit in (
        (args.center_freq_hz, "--center-freq-hz", freq_range, "Hz"),
        (args.sample_rate_hz, "--sample-rate-hz", rate_range, "S/s"),
    ):
        if not lo <= value <= hi:
            raise usage_error(
                f"{flag} {value:g} {unit} is outside the {hw.label}'s range [{lo:g}, {hi:g}] "
                f"{unit} ({part})"
            )


def _check_gains(args: argparse.Namespace, kind: str, ids) -> None:
    given = {"soapy_rx_gain_db": args.soapy_rx_gain_db, "soapy_tx_gain_db": args.soapy_tx_gain_db}
    if all(v is None for v in given.values()):
        return
    if kind != "soapy":
        raise usage_error(
            "--rx-gain-db/--tx-gain-db set a SoapySDR device's gains: they need --tx soapy "
            "--rx soapy (the other radios take theirs from their own settings)"
        )
    tx_id, rx_id = (tuple(ids) + (None,))[:2]
    for dest, flag, which, device in (
        ("soapy_rx_gain_db", "--rx-gain-db", "rx_gain_range_db", rx_id),
        ("soapy_tx_gain_db", "--tx-gain-db", "tx_gain_range_db", tx_id),
    ):
        if given[dest] is None:
            continue
        r = radio_of(kind).device_ranges(device)
        if which not in r:
            raise usage_error(f"{flag}: {r['part']} has no transmit channel")
        lo, hi = r[which]
        if not lo <= given[dest] <= hi:
            raise usage_error(
                f"{flag} {given[dest]:g} dB is outside the device's range [{lo:g}, {hi:g}] dB "
                f"({r['part']})"
            )


def check_overruns(args: argparse.Namespace, kind: str) -> int | None:
    """``--max-overruns`` (default 0) where the receiver counts its overruns; a Pluto on
    libiio 0.x counts none, so there it is refused and recorded as null (None)."""
    if kind != "pluto":
        return 0 if args.max_rx_overruns is None else args.max_rx_overruns
    if args.max_rx_overruns is not None:
        raise usage_error(
            "--max-overruns: libiio 0.x reports no receive overruns of a Pluto, so it would "
            "be recorded and never applied: leave it out"
        )
    return None


def air_is_emulated(kind: str, uri: str | None, rx_id=None) -> tuple[bool, str | None]:
    """Whether the run sets the air: simulated radios, a Pluto that answers as
    ``hil.EmulatedPluto`` (asked once, over libiio; ``hil.HilError`` when none answers), or
    one SoapySDR device that takes an emulated air (``osnerf hil emulate soapy``); and,
    when no Pluto was named (``uri`` None), the URI of the one found, which the run uses
    (None otherwise)."""
    if kind in SIMULATED:
        return True, None
    if kind == "soapy":
        if rx_id != uri:  # two devices: the air between them is not one board's
            return False, None

        with SoapyRadio.open(uri) as radio:
            return radio.air_settable, None
    if kind != "pluto":
        return False, None

    with Pluto.open(uri, configure=False) as board:
        found = board.uri if uri is None else None  # the first found: this run's board
        return board.air_settable, found


def resolve_air(args: argparse.Namespace, kind: str, emulated: bool) -> dict[str, object]:
    """Refuse air flags a real air cannot take; fill the emulated air's defaults.

    Returns ``air`` ("emulated" or "real") and each air flag's value as applied (None for
    a real air)."""
    hw = radio_of(kind)
    given = vars(args)
    if not emulated:
        refused = [flag for dest, (flag, _) in AIR_FLAGS.items() if given[dest] is not None]
        if refused:
            raise usage_error(
                f"{refused[0]} sets the emulated air, and the air between real {hw.label} "
                f"boards is not ours to set: leave it out (results carry the SNR the "
                f"receiver measured)"
            )
        return {"air": "real", **{dest: given[dest] for dest in AIR_FLAGS}}
    one_board = hw.full_duplex and kind not in SIMULATED
    values = {
        dest: default if given[dest] is None else given[dest]
        for dest, (_, default) in AIR_FLAGS.items()
    }
    if values["ppm"] is None:
        values["ppm"] = PPM_DEFAULTS["one board" if one_board else "two boards"]
    tx_ppm, rx_ppm = parse_ppm(values["ppm"])
    if one_board and tx_ppm != rx_ppm:
        raise usage_error(
            f"--ppm: one {hw.label} is both ends of the link, on one crystal, so TX and RX "
            f"are equal (e.g. 20,20), got {values['ppm']!r}"
        )
    return {"air": "emulated", **values}


def measured_snr_db(opts: OtaRunConfig, cfg, settings, sigmf_dir) -> tuple[float, list]:
    """Between real radios, the jscc encoder's SNR: what the receiver measures on one frame
    of QPSK sent first, within the codec's SNR range (a real transmitter knows no more of
    its air than that), and that burst's SigMF paths (``<sigmf-dir>/ota_probe_*``)."""
    import sys

    import numpy as np

    bits = np.random.default_rng(0).integers(0, 4, settings.symbols_per_frame)
    block = np.exp(1j * (np.pi / 4 + np.pi / 2 * bits)).astype(np.complex64)
    result, hw = send_over_the_air(opts, cfg, [block], sigmf_dir, "ota_probe")
    paths = save_sigmf(result, sigmf_dir / "ota_probe", cfg, hw=hw)
    snr = result.snr_db_measured()
    if snr is None:
        raise HilError("the SNR probe frame was lost: no SNR to encode jscc at")
    lo, hi = settings.codec.snr_range_db
    used = float(min(max(snr, lo), hi))
    print(f"ota: measured {snr:.1f} dB; jscc encodes at {used:.1f} dB", file=sys.stderr)
    return used, paths


def device_kinds(args: argparse.Namespace | OtaRunConfig) -> tuple[str, str | None, str | None]:
    """``(kind, tx_serial, rx_serial)`` of --tx/--rx: "emulated", "loopback" or "hackrf"
    (the flags as parsed, or the run's config: the same fields)."""
    tx_kind, tx_serial = parse_device(args.tx, "--tx")
    rx_kind, rx_serial = parse_device(args.rx, "--rx")
    simulated = {"emulated", "loopback"}
    if (tx_kind in simulated) != (rx_kind in simulated) or (
        tx_kind != rx_kind and tx_kind not in simulated
    ):
        raise usage_error(
            "--tx and --rx must both be simulated (emulated/loopback) or both the same hardware "
            f"({', '.join(HARDWARE)})"
        )
    uri = args.uri
    if uri is not None and tx_kind != "pluto":
        raise usage_error("--uri needs --tx pluto --rx pluto")
    if tx_kind == "pluto":
        tx_serial, rx_serial = tx_serial or uri, rx_serial or uri
    soapy_args = args.tx_args, args.rx_args
    if any(a is not None for a in soapy_args) and tx_kind != "soapy":
        raise usage_error("--tx-args/--rx-args need --tx soapy --rx soapy")
    if tx_kind == "soapy":
        if tx_serial or rx_serial:
            raise usage_error("soapy: name the devices with --tx-args/--rx-args, not soapy:ARGS")
        tx_serial = soapy_args[0]
        rx_serial = soapy_args[1] if soapy_args[1] is not None else tx_serial
    if tx_kind != rx_kind and tx_kind in simulated:
        raise usage_error(
            "--tx and --rx must be the same kind when simulated (both emulated or both loopback)"
        )
    if args.fault and tx_kind not in simulated:
        raise usage_error(
            "--fault needs emulated boards (--tx emulated --rx emulated, or loopback)"
        )
    return tx_kind, tx_serial, rx_serial


def open_pair(opts: OtaRunConfig, ota_cfg):
    """(tx, rx, emulator or None) for the --tx/--rx kinds, the air from the air flags where
    it is emulated (``opts.air``, :func:`resolve_air`); --fault is set on the receiver."""
    kind, tx_serial, rx_serial = device_kinds(opts)
    air = {}
    if opts.air == "emulated":
        air = {
            "seed": opts.seed,
            "ppm": parse_ppm(opts.ppm),
            "multipath": parse_multipath(opts.multipath),
            "delay_s": opts.delay_us * 1e-6,
        }
    if kind in HARDWARE:
        ids = {"tx_serial": tx_serial, "rx_serial": rx_serial}
        return open_radios(kind, opts.snr_db, ota_cfg, **air, **ids)
    tx, rx, emu = open_radios("emulated", opts.snr_db, ota_cfg, **air, loopback=kind == "loopback")
    if opts.fault:  # after the lead-in and half the margin: some capture
        lead = int(ota_cfg.rx_lead_s * ota_cfg.sample_rate_hz)
        emu.radios[1].faults = Faults.named(opts.fault, lead + ota_cfg.rx_margin_samples // 2)
    return tx, rx, emu


def send_over_the_air(opts: OtaRunConfig, cfg, blocks: list, sigmf_dir: Path, base: str = "ota"):
    """One burst of ``blocks`` over an :class:`osnerf.ota_link.OtaLink` between the --tx/--rx
    radios: (``hil.ota.BurstResult``, the hardware in words). A ``hil.HilError`` is raised again
    in one line, with what the receiver got so far saved as SigMF; warnings are printed one
    line each."""
    kind = device_kinds(opts)[0]
    tx, rx, emu = open_pair(opts, cfg)
    hw = radio_of(kind).label + (" (emulated)" if opts.air == "emulated" else "")
    link = OtaLink(tx, rx, opts.snr_db, cfg, emu)
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            result = link.send_blocks(blocks)
    except HilError as e:  # keep what arrived, then report the fault in one line (exit 1)
        saved = save_partial_capture(e, sigmf_dir / base, cfg, hw=hw)
        kept = f"; capture so far saved to {saved}" if saved else "; nothing was received"
        raise type(e)(f"{e}{kept}", capture=e.capture, sigmf_path=saved) from e
    finally:
        link.close()
    for w in caught:  # one line each, not a Python warning with its source line
        print(f"ota: warning: {w.message}", file=sys.stderr)
    return result, hw

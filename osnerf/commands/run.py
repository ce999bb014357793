"""`osnerf run`: the end-to-end pipeline: scene -> collector -> link -> NeRF -> report.

    osnerf run --scene NAME --demand OBJECT[,OBJECT...] --channel {awgn,rayleigh,raytraced,ota}
               --snr-db 0 --schemes jscc,digital,full,gt --seed 0 --out RUN_DIR [--max-seconds N]

Writes RUN_DIR/report.json, report.html, grid.png, received.png and plots. Without --scene
and --demand the default scene and its default demand are used. Re-running the same command
resumes from the stages cached in RUN_DIR/cache/.
"""

from __future__ import annotations

import argparse
import os
import sys
from dataclasses import asdict
from pathlib import Path

import phy
from osnerf.cli import UsageError, inputs_checked
from osnerf.commands import args as checks
from osnerf.commands.config_cli import add_config_arguments, config_from_args
from osnerf.report import write_report
from osnerf.scenes.dataset import default_cache_dir
from osnerf.schemes import SCHEMES, parse_schemes
from osnerf.scu import VIEW_SELECTIONS
from phy.digital import MCS_TABLE
from semcodec.digital import IMAGE_CODECS

# RunConfig fields that are options, in --help order, and the options named otherwise.
CONFIG_FIELDS = (
    "scene",
    "demand",
    "channel",
    "snr_db",
    "schemes",
    "seed",
    "max_seconds",
    "resolution_px",
    "num_train_views",
    "num_test_views",
    "symbol_rate_hz",
    "codec",
    "receiver_codec",
    "mcs",
    "image_codec",
    "nerf_steps",
    "ota_device",
    "nerf_clock",
    "renderer_steps",
    "refine_steps",
    "layer_fusion",
    "drone_speed_m_s",
    "ground_station_m",
    "ring_scale",
    "view_selection",
    "max_views",
    "csi",
    "ota_air",
    "ota_tx_args",
    "ota_rx_args",
    "plan_snr_db",
    "snr_error_db",
    "digital_box",
)
FLAGS = {
    "drone_speed_m_s": "--drone-speed",
    "ground_station_m": "--ground-station",
    "resolution_px": "--resolution",
    "num_train_views": "--views",
    "num_test_views": "--test-views",
    "ota_tx_args": "--tx-args",
    "ota_rx_args": "--rx-args",
}


def _demand(text: str) -> str:
    """``--demand``: OBJECT[:WEIGHT][,OBJECT...], not empty (leave the flag out for the
    scene's default demand)."""
    if not str(text).strip():
        raise argparse.ArgumentTypeError(
            "must name at least one object (OBJECT[:WEIGHT][,...]); leave --demand out for "
            "the scene's default demand"
        )
    return text


def _schemes(text: str, parse) -> tuple[str, ...]:
    """``--schemes``: known names, each once, no empty item (``jscc,`` is a typo, not jscc)."""
    items = [s.strip() for s in str(text).split(",")]
    if not all(items) or len(set(items)) != len(items):
        raise argparse.ArgumentTypeError(
            f"must name each scheme once, comma-separated, with no empty item, got {text!r}"
        )
    return tuple(parse(text))


def add_arguments(p: argparse.ArgumentParser) -> None:
    from osnerf.ota_link import DEVICES as OTA_DEVICES
    from osnerf.ota_link import OTA_AIRS
    from osnerf.run.config import (
        RUN_CHANNELS,
        RunConfig,
    )

    add_config_arguments(
        p,
        RunConfig,
        CONFIG_FIELDS,
        flags=FLAGS,
        types={
            "demand": _demand,
            "schemes": lambda text: _schemes(text, parse_schemes),
            "ground_station_m": checks.ground_station,
            "digital_box": checks.boolean,
        },
        choices={
            "channel": RUN_CHANNELS,
            "mcs": ("auto", *MCS_TABLE),
            "image_codec": tuple(IMAGE_CODECS),
            "ota_device": OTA_DEVICES,
            "ota_air": OTA_AIRS,
            "nerf_clock": ("wall", "cpu"),
            "view_selection": tuple(VIEW_SELECTIONS),
            "csi": phy.CSI_OFDM,
        },
    )
    for a in p._actions:  # given or not: digital's flags are refused without a digital scheme
        if a.dest in DIGITAL_FLAGS:
            a.default = None
    schemes = next(a for a in p._actions if a.dest == "schemes")
    schemes.help += "; known: " + "; ".join(f"{n}: {c.help}" for n, c in SCHEMES.items()).replace(
        "%", "%%"
    )
    p.add_argument(
        "--out",
        required=True,
        help="RUN_DIR: report and stage cache; a run of the same config there is continued "
        "from its cache (the same numbers); a folder holding anything else is refused "
        "without --overwrite",
    )
    checks.add_overwrite(p, "what a --out folder holds (another config's run, other files)")
    checks.add_allow_untrained(p)
    p.add_argument(
        "--cache-dir",
        default=None,
        help="rendered-scene cache (default $OSNERF_CACHE or ~/.cache/osnerf)",
    )


DIGITAL_FLAGS = {"mcs": "--mcs", "image_codec": "--image-codec"}
"""Options that only the digital schemes read (those with an MCS)."""


def run_config(args: argparse.Namespace):
    """The ``osnerf.run.RunConfig`` of parsed arguments (validates them); ``--mcs`` or
    ``--image-codec`` without a digital scheme is refused, not recorded unused."""
    import dataclasses

    from osnerf.run import RunConfig

    digital = [n for n in args.schemes if n in SCHEMES and hasattr(SCHEMES[n], "mcs")]
    filled = argparse.Namespace(**vars(args))
    defaults = {f.name: f.default for f in dataclasses.fields(RunConfig)}
    for dest, flag in DIGITAL_FLAGS.items():
        if getattr(args, dest, None) is None:
            setattr(filled, dest, defaults[dest])
        elif not digital:
            known = ", ".join(n for n in SCHEMES if hasattr(SCHEMES[n], "mcs"))
            raise UsageError(
                f"{flag} applies to the digital schemes ({known}), not to --schemes "
                f"{','.join(args.schemes)}: add one or leave {flag} out"
            )
    return config_from_args(
        RunConfig, filled, CONFIG_FIELDS, flags=FLAGS, allow_untrained=args.allow_untrained
    )


def check_args(args: argparse.Namespace) -> None:
    """What a sweep asks of each point before any runs: the config of parsed arguments is
    valid (combinations included: ``--drone-speed`` with a channel other than raytraced is
    refused here, not when its point comes)."""
    run_config(args)


def run(args: argparse.Namespace) -> int:
    from osnerf.run import run_pipeline
    from osnerf.run.cache import check_stage_files
    from osnerf.run.pipeline import prepare

    cfg = run_config(args)
    out = checks.output_dir(
        args.out,
        "--out",
        overwrite=args.overwrite,
        resumable=lambda d: (d / "cache" / cfg.key()).is_dir(),  # this config's own run
    )

    cache_flag = "--cache-dir" if args.cache_dir else "$OSNERF_CACHE"
    cache = args.cache_dir or (os.environ.get("OSNERF_CACHE") and default_cache_dir())
    if cache:
        checks.output_dir(cache, cache_flag, resumable=lambda _: True)
    check_stage_files(out / "cache" / cfg.key())
    prep = prepare(cfg)  # names, demand, the codecs' SNR range and knowledge base: exit 2
    inputs_checked()  # from here on a failure is a runtime failure (exit 1)
    report, pictures = run_pipeline(
        cfg, out, cache_dir=Path(args.cache_dir) if args.cache_dir else None, prepared=prep
    )
    config = {**asdict(cfg), "schemes": list(cfg.schemes), "cache_key": cfg.key()}
    write_report(out, config, cfg.seed, report, pictures)
    for name, s in report.schemes.items():
        po = "n/a" if s.psnr_object is None else f"{s.psnr_object:.2f}"
        lp = "n/a" if s.lpips is None else f"{s.lpips:.3f}"
        tag = " (bound)" if s.bound else ""
        print(
            f"{name:8s} psnr_object {po} dB  psnr {s.psnr:.2f} dB  lpips {lp}  "
            f"symbols {s.symbols_sent}{tag}",
            file=sys.stderr,
        )
        for rname, r in (s.renderers or {}).items():
            speed = f"  {r['speedup_vs_full']:.1f}x full" if "speedup_vs_full" in r else ""
            setup = f", set up in {r['setup_cpu_seconds']:.0f} CPU-s" if r["setup_stats"] else ""
            rpo = "n/a" if r.get("psnr_object") is None else f"{r['psnr_object']:.2f}"
            print(
                f"{'':8s}  {rname} render: {1e3 * r['seconds_per_view']:.0f} ms/view  "
                f"psnr_object {rpo} dB{speed}{setup}",
                file=sys.stderr,
            )
    print(f"report: {out / 'report.json'} and {out / 'report.html'}", file=sys.stderr)
    return 0

"""`osnerf run`: the end-to-end pipeline: scene -> collector -> link -> NeRF -> report.

    osnerf run --scene NAME --demand OBJECT[,OBJECT...] --channel {awgn,rayleigh,raytraced,ota}
               --snr-db 0 --schemes jscc,digital,full,gt --seed 0 --out RUN_DIR [--max-seconds N]

Writes RUN_DIR/report.json, report.html, grid.png, received.png and plots. Without --scene
and --demand the default scene and its default demand are used. Re-running the same command
resumes from the stages cached in RUN_DIR/cache/.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import asdict
from pathlib import Path

from osnerf.commands import args as checks


def add_arguments(p: argparse.ArgumentParser) -> None:
    from osnerf.ota_link import DEVICES as OTA_DEVICES
    from osnerf.run.config import RUN_CHANNELS, RunConfig
    from osnerf.scenes import DEFAULT_SCENE
    from osnerf.schemes import DEFAULT_SCHEMES, load_entry_points, parse_schemes
    from phy.digital import MCS_TABLE
    from semcodec import IMAGE_CODECS

    schemes = load_entry_points()

    p.add_argument(
        "--scene",
        default=DEFAULT_SCENE,
        help=f"built-in scene (default {DEFAULT_SCENE}; see `osnerf scenes`)",
    )
    p.add_argument(
        "--demand",
        default=None,
        help="OBJECT[:WEIGHT][,OBJECT...] (default: the scene's default demand)",
    )
    p.add_argument(
        "--channel",
        default="rayleigh",
        choices=RUN_CHANNELS,
        help="phy's channels (flat ones with perfect CSI; tdl/cdl over OFDM with LS "
        "estimates; raytraced per drone position) or ota (default rayleigh: block fading)",
    )
    p.add_argument("--snr-db", type=checks.snr_db, default=0.0, help="Es/N0 in dB (default 0)")
    p.add_argument(
        "--schemes",
        type=parse_schemes,
        default=DEFAULT_SCHEMES,
        help="comma-separated schemes: "
        + "; ".join(f"{n}: {c.help}" for n, c in schemes.items())
        + f" (default {','.join(DEFAULT_SCHEMES)})",
    )
    p.add_argument("--seed", type=checks.seed, default=0)
    p.add_argument("--out", required=True, help="RUN_DIR: report and stage cache")
    p.add_argument(
        "--max-seconds",
        type=float,
        default=600.0,
        help="cap on NeRF training seconds per scheme (the budget itself with --nerf-steps 0; default 600)",
    )
    p.add_argument(
        "--resolution",
        type=checks.resolution,
        default=80,
        help="drone image size in pixels, 16..512 (default 80)",
    )
    p.add_argument("--views", type=int, default=24, help="drone views captured (default 24)")
    p.add_argument(
        "--test-views", type=int, default=8, help="held-out views for scoring (default 8)"
    )
    p.add_argument(
        "--symbol-rate-hz", type=float, default=1e6, help="for air time (default 1e6 symbols/s)"
    )
    p.add_argument(
        "--codec", default=None, help="codec checkpoint (default: semcodec's shipped one)"
    )
    p.add_argument(
        "--receiver-codec", default=None, help="receiver's checkpoint (default: the same)"
    )
    p.add_argument(
        "--mcs",
        default="auto",
        choices=("auto", *MCS_TABLE),
        metavar="MCS",
        help="the digital scheme's MCS: auto (from the average SNR alone, no CSI at the "
        f"transmitter; default) or a fixed one of {', '.join(MCS_TABLE)}; digital_genie is the "
        "bound that knows each draw",
    )
    p.add_argument(
        "--image-codec",
        default="avif",
        choices=tuple(IMAGE_CODECS),
        help=f"digital baseline image codec: {', '.join(IMAGE_CODECS)} (default avif)",
    )
    p.add_argument(
        "--nerf-steps",
        type=int,
        default=6000,
        help="NeRF steps per scheme, equal for all (default 6000; 0: the same --max-seconds instead)",
    )
    p.add_argument(
        "--ota-device",
        default="emulated",
        choices=OTA_DEVICES,
        help="--channel ota: two emulated HackRFs (default), two real ones on USB (hackrf) or "
        "one Pluto (pluto: the first libiio finds, or ip:$IIOD_REMOTE)",
    )
    p.add_argument(
        "--nerf-clock",
        default="cpu",
        help="what --max-seconds counts: wall, or cpu (CPU s / threads; for shared machines)",
    )
    p.add_argument(
        "--lightweight-seconds",
        type=float,
        default=RunConfig.lightweight_seconds,
        help="the learned renderers of renderer.RENDERERS (lightweight: keyframes + U-Net; "
        "features: a feature field + decoder, paper 3.3) render the held-out views beside the "
        "full render of each scheme's field after this many seconds of training each; the "
        f"report gives each one's time per view and PSNR (default {RunConfig.lightweight_seconds:g}; "
        "0: skip)",
    )
    p.add_argument(
        "--refine-steps",
        type=checks.refine_steps,
        default=RunConfig.refine_steps,
        help="the jscc transmitter refines each view's symbols with this many Adam steps on "
        "the expected distortion over its own model of the channel (knows the decoder, the "
        "channel kind and the view's SNR, not the draw; default "
        f"{RunConfig.refine_steps}; 0: the encoder's symbols)",
    )
    p.add_argument(
        "--cache-dir",
        default=None,
        help="rendered-scene cache (default $OSNERF_CACHE or ~/.cache/osnerf)",
    )


def run_config(args: argparse.Namespace):
    """The ``osnerf.run.RunConfig`` of parsed arguments (validates them)."""
    from osnerf.run import RunConfig

    return RunConfig(
        scene=args.scene,
        demand=args.demand,
        channel=args.channel,
        snr_db=args.snr_db,
        schemes=tuple(args.schemes),
        seed=args.seed,
        max_seconds=args.max_seconds,
        resolution_px=args.resolution,
        num_train_views=args.views,
        num_test_views=args.test_views,
        symbol_rate_hz=args.symbol_rate_hz,
        codec=args.codec,
        receiver_codec=args.receiver_codec,
        mcs=args.mcs,
        image_codec=args.image_codec,
        nerf_clock=args.nerf_clock,
        ota_device=args.ota_device,
        nerf_steps=args.nerf_steps or None,
        lightweight_seconds=args.lightweight_seconds,
        refine_steps=args.refine_steps,
    )


def run(args: argparse.Namespace) -> int:
    from osnerf.report import write_report
    from osnerf.run import run_pipeline
    from osnerf.run.cache import check_stage_files

    cfg = run_config(args)
    out = checks.output_dir(args.out, "--out")
    if args.cache_dir:
        checks.output_dir(args.cache_dir, "--cache-dir")
    check_stage_files(out / "cache" / cfg.key())
    report, pictures = run_pipeline(
        cfg, out, cache_dir=Path(args.cache_dir) if args.cache_dir else None
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
            rpo = "n/a" if r.get("psnr_object") is None else f"{r['psnr_object']:.2f}"
            print(
                f"{'':8s}  {rname} render: {1e3 * r['seconds_per_view']:.0f} ms/view  "
                f"psnr_object {rpo} dB{speed}",
                file=sys.stderr,
            )
    print(f"report: {out / 'report.json'} and {out / 'report.html'}", file=sys.stderr)
    return 0

"""`osnerf eval-codec`: image transmission quality, JSCC vs digital vs ideal (vs analog).

Reads every PNG/JPEG of ``--images``, sends each image (one at a time, its own size)
through every scheme at every SNR, and writes
``{"config", "seed", "git_commit", "versions", "checkpoint": {"name", "sha256"},
"results": [{"scheme", "snr_db", "cbr", "psnr", "ssim", "lpips", "num_images", ...}]}`` where
psnr/ssim/lpips are the mean of per-image values (PSNR peak 1.0; LPIPS-AlexNet v0.1 from
:func:`renderer.lpips`, null with ``--no-lpips`` or when an image is smaller than 31x31 px).
All input is checked before any work; the result file is written once, atomically, at the end.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from osnerf.commands import args as checks


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--images", required=True, help="folder of PNG/JPEG images")
    from semcodec.evaluation import EVAL_CHANNELS

    p.add_argument(
        "--channel",
        default="awgn",
        choices=EVAL_CHANNELS,
        help="awgn or rayleigh (block fading, perfect CSI)",
    )
    p.add_argument(
        "--snr-db",
        default="1,4,7,10,13",
        type=checks.snr_db_list,
        help="comma-separated Es/N0 values in dB",
    )
    p.add_argument(
        "--cbr", default="1/16", help="channel bandwidth ratio, e.g. 1/16 (JSCC: 1/48..1/6)"
    )
    p.add_argument(
        "--schemes",
        default="jscc,digital,ideal",
        help="comma-separated: jscc, digital, digital_fixed, ideal, analog, digital_webp, digital_jpeg, ideal_webp, ideal_jpeg",
    )
    p.add_argument("--mcs", default=None, help="MCS of digital_fixed (default 16qam-1/2)")
    p.add_argument("--seed", type=checks.seed, default=0, help="seed of channel noise and fading")
    p.add_argument("--out", required=True, help="result JSON path")
    p.add_argument("--plot", default=None, help="optional PNG plot of PSNR vs SNR")
    p.add_argument("--checkpoint", default=None, help="codec checkpoint (default: the shipped one)")
    p.add_argument(
        "--max-images", type=int, default=None, help="use only the first N images (sorted by name)"
    )
    p.add_argument(
        "--no-lpips",
        action="store_true",
        help="skip LPIPS (it needs the weights that `make lpips` converts at setup)",
    )
    p.add_argument(
        "--threads",
        type=checks.threads,
        default=1,
        help="torch CPU threads (default 1: the machine is shared)",
    )


def run(args: argparse.Namespace) -> int:
    import torch

    from osnerf.provenance import result_header, write_json_atomic
    from phy import parse_cbr
    from renderer import LPIPS_MIN_SIDE_PX, lpips, lpips_weights
    from semcodec.codec import load_codec
    from semcodec.evaluation import (
        DEFAULT_FIXED_MCS,
        EVAL_CHANNELS,
        SCHEMES,
        EvalContext,
        load_image_folder,
        parse_schemes,
        psnr,
        ssim,
    )

    out = checks.output_file(args.out, "--out")
    if args.plot:
        checks.output_file(args.plot, "--plot")
    checks.distinct_outputs(out=args.out, plot=args.plot)
    torch.set_num_threads(args.threads)
    if args.channel not in EVAL_CHANNELS:
        raise ValueError(f"--channel must be one of {list(EVAL_CHANNELS)}, got {args.channel!r}")
    schemes = parse_schemes(args.schemes)
    snrs = list(args.snr_db)
    try:
        cbr = parse_cbr(args.cbr)
    except ValueError as e:
        raise ValueError(f"--{e}") from None
    mcs = args.mcs or DEFAULT_FIXED_MCS
    if "digital_fixed" in schemes or args.mcs:
        from phy.digital import MCS_TABLE

        if mcs not in MCS_TABLE:
            raise KeyError(f"--mcs must be one of {list(MCS_TABLE)}, got {mcs!r}")
    codec = None
    if "jscc" in schemes:
        codec = load_codec(args.checkpoint)
        lo, hi = codec.cbr_range
        try:
            codec.channels_for_cbr(cbr)
        except ValueError:
            raise ValueError(
                f"--cbr {args.cbr} is outside the codec's range [1/48, {round(hi * 48)}/48]"
            ) from None
        slo, shi = codec.snr_range_db
        bad = [s for s in snrs if not slo <= s <= shi]
        if bad:
            raise ValueError(
                f"--snr-db {bad[0]:g} is outside the codec's range [{slo:g}, {shi:g}] dB"
            )
    names, images = load_image_folder(args.images)
    if args.max_images is not None:
        if args.max_images < 1:
            raise ValueError(f"--max-images must be >= 1, got {args.max_images}")
        names, images = names[: args.max_images], images[: args.max_images]
    score_lpips = not args.no_lpips and all(
        min(img.shape[-2:]) >= LPIPS_MIN_SIDE_PX for img in images
    )
    if score_lpips:
        try:
            lpips_weights()  # checked before any work
        except FileNotFoundError as e:
            raise FileNotFoundError(f"{e}, or pass --no-lpips") from None

    ctx = EvalContext(channel=args.channel, codec=codec, fixed_mcs=mcs)
    config = {
        "images": str(args.images),
        "image_names": names,
        "channel": args.channel,
        "snr_db": snrs,
        "cbr": cbr,
        "schemes": schemes,
        "fixed_mcs": mcs,
        "checkpoint": args.checkpoint,
        "metric": "mean of per-image PSNR (peak 1.0), SSIM and LPIPS (AlexNet, v0.1)",
        "lpips": score_lpips,
        "lost_image": "mid-grey 0.5",
    }
    results = []
    from tqdm import tqdm

    bar = tqdm(total=len(schemes) * len(snrs) * len(images), desc="eval-codec", file=sys.stderr)
    for si, scheme in enumerate(schemes):
        for ki, snr in enumerate(snrs):
            gen = torch.Generator().manual_seed(args.seed * 1_000_003 + si * 1000 + ki)
            ps, ss, ls, t0 = [], [], [], time.perf_counter()
            extra = {"failed_codewords": 0, "lost_images": 0, "num_symbols": 0}
            for img in images:
                res = SCHEMES[scheme](ctx, img, snr, cbr, gen)
                ps.append(psnr(res.images, img))
                ss.append(ssim(res.images, img))
                if score_lpips:
                    ls.append(float(lpips(res.images.clamp(0, 1), img)[0]))
                for k in extra:
                    extra[k] += int(res.stats.get(k, 0) or 0)
                bar.update(1)
            results.append(
                {
                    "scheme": scheme,
                    "snr_db": snr,
                    "cbr": cbr,
                    "psnr": float(np.mean(ps)),
                    "ssim": float(np.mean(ss)),
                    "lpips": float(np.mean(ls)) if ls else None,
                    "num_images": len(images),
                    "psnr_per_image": ps,
                    **extra,
                    "seconds": round(time.perf_counter() - t0, 2),
                }
            )
            lp = f", LPIPS {np.mean(ls):.4f}" if ls else ""
            print(
                f"eval-codec: {scheme} {snr:g} dB: PSNR {np.mean(ps):.2f} dB, SSIM {np.mean(ss):.4f}{lp}",
                file=sys.stderr,
            )
    bar.close()
    doc = {
        **result_header(config, args.seed),
        "checkpoint": {"name": codec.name, "sha256": codec.sha256} if codec else None,
        "results": results,
    }
    if args.plot:
        _plot(results, Path(args.plot), f"{args.channel}, CBR {args.cbr}")
    write_json_atomic(out, doc)
    print(f"eval-codec: {len(results)} points -> {out}", file=sys.stderr)
    return 0


def _plot(results: list[dict], path: Path, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5, 3.5))
    for s in dict.fromkeys(r["scheme"] for r in results):
        pts = [(r["snr_db"], r["psnr"]) for r in results if r["scheme"] == s]
        ax.plot(*zip(*pts), marker="o", label=s)
    ax.set_xlabel("SNR (Es/N0) [dB]")
    ax.set_ylabel("PSNR [dB] (mean per image)")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)

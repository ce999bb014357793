"""`osnerf eval-codec`: image transmission quality, JSCC vs digital vs ideal (vs analog).

Reads every PNG/JPEG of ``--images`` (each at least 11x11 px: SSIM's Gaussian window, see
``semcodec.links.schemes.EVAL_MIN_SIDE_PX``), sends each image (one at a time, its own size)
through every scheme at every SNR, ``--draws`` times over independent noise and fading
draws, and writes ``{"config", "seed", "git_commit", "versions", "checkpoint": {"name",
"sha256"}, "results": [{"scheme", "snr_db", "cbr", "psnr", "psnr_ci95", "ssim", "ms_ssim",
"lpips", "psnr_p5", "psnr_p10", "lost_fraction", "num_images", "draws", ...}], "codec":
{...}}`` (the codec's record,
:func:`osnerf.provenance.codec_record`: sha256, trained or not, a plugin's distribution)
where psnr/ssim/lpips are the mean over images x draws of per-image values (PSNR peak
1.0; LPIPS-AlexNet v0.1 from :func:`renderer.lpips`, null with ``--no-lpips`` or when an
image is smaller than 31x31 px) and ``psnr_ci95`` the 95 % percentile bootstrap interval
of that mean over the images x draws values (``[null, null]`` with fewer than
:data:`~osnerf.commands.eval_stats.CI_MIN_VALUES` of them: too few for an interval).
MS-SSIM (pytorch-msssim) is null for images under 161 px a side.

What the transmitter knows is apart from the channel: ``--plan-snr-db`` and
``--snr-error-db`` set its belief (rows then record ``snr_believed_db`` per image and draw,
as each scheme's transmitter used it: jscc's clipped to its codec's SNR range); without
them the transmitter knows the true average SNR, as before.

Channels: every name of ``phy.CHANNELS``; flat ones with a one-tap perfect-CSI ZF receiver,
``tdl``/``cdl`` over OFDM with pilot LS estimates; the decoder gets the per-symbol noise
variance. Draw ``d`` of image ``i`` at SNR ``k`` uses the same seed in every scheme (common
random numbers: ``digital`` and ``digital_genie`` see the same fades). All input is checked
before any work; the result file is written once, atomically, at the end. Until then every
finished (scheme, SNR) point is kept in ``OUT.partial``: the same command run again after an
interruption resumes from it. A partial file of another evaluation (another ``--seed``,
``--images``, ``--codec``, ``--cbr``, ...) is refused with the changed fields named, and
replaced only with ``--overwrite`` (:mod:`osnerf.commands.eval_partial`).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from common import write_figure
from osnerf.cli import inputs_checked
from osnerf.commands import args as checks
from osnerf.commands.eval_inputs import checked_inputs
from osnerf.commands.eval_partial import partial_path, resumable
from osnerf.commands.eval_stats import (
    INTERVAL_TEXT,
    DrawTally,
    draw_seed,
    mean_ci95,
    outage_stats,
    snr_belief,
)
from osnerf.provenance import codec_record, result_header, write_json_atomic
from phy import channel_record
from semcodec import LINK_SCHEMES, EvalContext, capability_record, codec_names
from semcodec.jscc import REFINE_STEPS
from semcodec.links import EVAL_MIN_SIDE_PX, eval_channels, schemes_help

MAX_DRAWS = 10_000
MAX_IMAGES = 100_000
MAX_SNR_ERROR_DB = 20.0


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options, in ``--help`` order: what is sent over which link, then where the results
    go and how the work runs."""
    _add_link_arguments(p)
    _add_output_arguments(p)


def _add_link_arguments(p: argparse.ArgumentParser) -> None:
    """--images, --channel, --draws, --snr-db, --cbr, --schemes, --mcs, --refine-steps, --seed."""
    side = f"{EVAL_MIN_SIDE_PX}x{EVAL_MIN_SIDE_PX} px"
    p.add_argument(
        "--images",
        required=True,
        help=f"an image file, or a folder of images (png, jpg, ...), each at least {side} "
        "(SSIM's Gaussian window); a smaller one is refused",
    )

    p.add_argument(
        "--channel",
        default="awgn",
        help=f"one of phy.CHANNELS: {', '.join(eval_channels())} (rayleigh = block fading, "
        "one fade per image; rayleigh_fast = one per symbol, the setting of the published "
        "Rayleigh anchors)",
    )
    p.add_argument(
        "--draws",
        type=checks.count(1, MAX_DRAWS),
        default=1,
        help=f"independent noise and fading draws per image, 1..{MAX_DRAWS} (default 1); "
        "results give the "
        "mean and a 95%% interval over images x draws",
    )
    p.add_argument(
        "--snr-db",
        default="1,4,7,10,13",
        type=checks.snr_db_list,
        help="comma-separated Es/N0 values in dB",
    )
    p.add_argument(
        "--cbr",
        default="1/16",
        help="channel bandwidth ratio, e.g. 1/16, within the codec's cbr_range (its model card)",
    )
    p.add_argument(
        "--schemes",
        default="jscc,digital,ideal",
        help=f"comma-separated: {schemes_help()}",
    )
    p.add_argument("--mcs", default=None, help="MCS of digital_fixed (default 16qam-1/2)")

    p.add_argument(
        "--refine-steps",
        type=checks.refine_steps,
        default=REFINE_STEPS,
        help=f"Adam steps of jscc_refined per image and SNR (default {REFINE_STEPS}; about one "
        "CPU second each for a Kodak image)",
    )
    p.add_argument(
        "--plan-snr-db",
        type=checks.snr_db,
        default=None,
        help="what every transmitter believes the average SNR is (jscc's encoder SNR, the "
        "digital MCS); the channel applies --snr-db and the receiver measures its noise "
        "(default: the true --snr-db, exact knowledge)",
    )
    p.add_argument(
        "--snr-error-db",
        type=checks.number(0.0, MAX_SNR_ERROR_DB, "dB"),
        default=0.0,
        help="each image's SNR estimate is its true SNR (or --plan-snr-db) plus a zero-mean "
        "Gaussian error of this many dB, drawn per image and draw from --seed, the same for "
        "every scheme; digital plans over the error, digital_naive as if it were exact "
        f"(default 0, at most {MAX_SNR_ERROR_DB:g})",
    )
    p.add_argument("--seed", type=checks.seed, default=0, help="seed of channel noise and fading")


def _add_output_arguments(p: argparse.ArgumentParser) -> None:
    """--out, --plot, --overwrite, --codec, --max-images, --no-lpips, --threads."""
    p.add_argument(
        "--out",
        required=True,
        help="result JSON path (finished points wait in OUT.partial; rerun the same command "
        "to resume; one of another evaluation is refused unless --overwrite)",
    )
    p.add_argument("--plot", default=None, help="optional PNG plot of PSNR vs SNR")
    checks.add_overwrite(p, "--out and --plot (and an OUT.partial of another evaluation)")

    p.add_argument(
        "--codec",
        default=None,
        metavar="NAME[:CHECKPOINT]",
        help=f"the semantic codec: one of {', '.join(codec_names())} (plugins through the "
        "semcodec.codecs entry points), optionally with a checkpoint, or a checkpoint path "
        "(default: jscc with the shipped checkpoint)",
    )
    checks.add_allow_untrained(p)
    p.add_argument(
        "--max-images",
        type=checks.count(1, MAX_IMAGES),
        default=None,
        help=f"use only the first N images (sorted by name), 1..{MAX_IMAGES}",
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
    out, schemes, snrs, cbr, mcs, codec, names, images, score_lpips = checked_inputs(args)
    ctx = EvalContext(
        channel=args.channel,
        codec=codec,
        fixed_mcs=mcs,
        refine_steps=args.refine_steps,
        refine_seed=args.seed + 1_000_000_007,  # its own stream, never an evaluation draw's
        snr_error_db=args.snr_error_db,
    )

    link = ctx.link()  # builds the channel (bad channel settings fail before any work)
    config = {
        "images": str(args.images),
        "image_names": names,
        "channel": args.channel,
        "channel_params": channel_record(link),
        "receiver": ctx.receiver,
        "draws": args.draws,
        "interval": INTERVAL_TEXT,
        "bounds": {s: LINK_SCHEMES[s].bound for s in schemes if LINK_SCHEMES[s].bound},
        "snr_db": snrs,
        "plan_snr_db": args.plan_snr_db,
        "snr_error_db": args.snr_error_db,
        "transmitter_knows": _knowledge(args.plan_snr_db, args.snr_error_db),
        "cbr": cbr,
        "schemes": schemes,
        "fixed_mcs": mcs,
        "refine_steps": args.refine_steps
        if any(LINK_SCHEMES[s].refines for s in schemes)
        else None,
        "codec": args.codec,
        "metric": "mean of per-image PSNR (peak 1.0), SSIM, MS-SSIM (pytorch-msssim, 5 scales) "
        "and LPIPS (AlexNet, v0.1)",
        "lpips": score_lpips,
        "lost_image": "mid-grey 0.5",
    }
    from tqdm import tqdm

    refines = any(LINK_SCHEMES[s].refines for s in schemes)
    checkpoint = None  # the codec, what it declares and whether jscc_refined refined
    if codec is not None:
        steps = args.refine_steps if refines else None
        checkpoint = {"name": codec.name, "sha256": codec.sha256}
        checkpoint.update(capability_record(codec, steps))
    partial = partial_path(out)
    identity = {"config": config, "seed": args.seed, "checkpoint": checkpoint}
    done = resumable(out, identity, args.overwrite)
    if done:
        print(f"eval-codec: resuming {len(done)} finished points from {partial}", file=sys.stderr)
    inputs_checked()  # from here on a failure is a runtime failure (exit 1)
    doc = {**result_header(config, args.seed), "checkpoint": checkpoint, "results": []}
    doc["codec"] = codec_record(codec, args.codec) if codec else None
    total = len(schemes) * len(snrs) * len(images) * args.draws
    # the bar is closed on the way out, by an error too: it never redraws after the message
    with tqdm(total=total, desc="eval-codec", file=sys.stderr) as bar:
        for scheme in schemes:
            for ki, snr in enumerate(snrs):
                r = done.get((scheme, snr))
                if r is None:
                    r = _point(ctx, scheme, ki, snr, cbr, images, args, score_lpips, bar)
                    doc["results"].append(r)
                    # each finished point is kept: an interrupted run resumes from here
                    write_json_atomic(partial, {**doc, "partial": True})
                else:
                    doc["results"].append(r)
                    bar.update(len(images) * args.draws)
    results = doc["results"]
    if args.plot:
        title = f"{args.channel}, CBR {args.cbr}, {args.draws} draw(s) per image"
        _plot(results, Path(args.plot), title)
    write_json_atomic(out, doc)
    partial.unlink(missing_ok=True)
    print(f"eval-codec: {len(results)} points -> {out}", file=sys.stderr)
    return 0


def _knowledge(plan_snr_db, snr_error_db) -> str:
    """What the transmitters know of the SNR, in words (for result files)."""
    base = "the true average SNR" if plan_snr_db is None else f"{plan_snr_db:g} dB, fixed"
    if not snr_error_db:
        return base + (" (exact)" if plan_snr_db is None else "")
    return f"{base} plus a Gaussian error of {snr_error_db:g} dB per image and draw"


def _point(
    ctx, scheme: str, ki: int, snr: float, cbr: float, images, args, score_lpips, bar
) -> dict:
    """One (scheme, SNR) row of the result: every image over ``args.draws`` draws."""
    import torch

    tally, t0 = DrawTally(score_lpips), time.perf_counter()
    for ii, img in enumerate(images):
        row, believed = [], []
        for d in range(args.draws):
            gen = torch.Generator().manual_seed(draw_seed(args.seed, ki, ii, d))
            plan = snr_belief(snr, args.plan_snr_db, args.snr_error_db, args.seed, ki, ii, d)
            plan = _within_codec(ctx, scheme, plan)
            res = LINK_SCHEMES[scheme](ctx, img, snr, cbr, gen, plan)
            believed.append(snr if plan is None else plan)
            row.append(tally.add(res, img))
            bar.update(1)
        tally.psnr.append(row)
        tally.beliefs.append(believed)
    return _result_row(tally, scheme, snr, cbr, len(images), args, t0)


def _result_row(
    tally: DrawTally, scheme: str, snr: float, cbr: float, num_images: int, args, t0: float
) -> dict:
    """The result row of a tallied point, and its line on stderr."""
    ps, ss, ms, ls, extra = tally.psnr, tally.ssim, tally.ms_ssim, tally.lpips, tally.extra
    flat = [v for row in ps for v in row]
    mean, lo, hi = mean_ci95(flat)
    r = {
        "scheme": scheme,
        "snr_db": snr,
        "cbr": cbr,
        "psnr": mean,
        "psnr_ci95": [lo, hi],
        "ssim": float(np.mean(ss)),
        "ms_ssim": None if any(v is None for v in ms) else float(np.mean(ms)),
        "lpips": float(np.mean(ls)) if ls else None,
        "num_images": num_images,
        "draws": args.draws,
        "psnr_per_image": [float(np.mean(row)) for row in ps],
        "psnr_per_draw": ps,
        **extra,
        **outage_stats(flat, extra["lost_images"], len(flat)),
        "seconds": round(time.perf_counter() - t0, 2),
    }
    if args.plan_snr_db is not None or args.snr_error_db:  # what it believed, by the truth
        r["plan_snr_db"] = args.plan_snr_db
        r["snr_error_db"] = args.snr_error_db
        r["snr_believed_db"] = tally.beliefs
    if tally.forecast is not None:  # the planner's forecast of lost images, beside the count
        r["forecast_lost_images"] = tally.forecast
    if tally.budget is not None:
        r["symbol_budget"] = tally.budget
        r["symbols_unused"] = tally.budget - extra["num_symbols"]
    if tally.separate:
        r["views_lost"] = tally.lost
        r["mcs_used"] = tally.mcs_used
    if tally.scales_used:
        r["scales_used"] = tally.scales_used
    r.update(tally.stats_keys)
    if LINK_SCHEMES[scheme].bound:
        r["bound"] = LINK_SCHEMES[scheme].bound
    lp = f", LPIPS {np.mean(ls):.4f}" if ls else ""
    ci = (
        f"[{lo:.2f}, {hi:.2f}]" if lo is not None else f"(n = {len(flat)}: too few for an interval)"
    )
    msl = f", MS-SSIM {r['ms_ssim']:.4f}" if r["ms_ssim"] is not None else ""
    print(
        f"eval-codec: {scheme} {snr:g} dB: PSNR {mean:.2f} dB {ci}, SSIM "
        f"{np.mean(ss):.4f}{msl}{lp}",
        file=sys.stderr,
    )
    return r


def _within_codec(ctx, scheme: str, plan: float | None) -> float | None:
    """A belief outside the semantic codec's SNR range is clipped to it (an encoder is told
    only SNRs it was trained for); other schemes take it as it is."""
    if plan is None or not LINK_SCHEMES[scheme].needs_codec:
        return plan
    lo, hi = ctx.codec.snr_range_db
    return min(max(plan, lo), hi)


def _plot(results: list[dict], path: Path, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.5, 3.8))
    for s in dict.fromkeys(r["scheme"] for r in results):
        rows = [r for r in results if r["scheme"] == s]
        x = [r["snr_db"] for r in rows]
        y = [r["psnr"] for r in rows]
        err = [  # no bar where the values were too few for an interval
            [
                r["psnr"] - (r["psnr_ci95"][0] if r["psnr_ci95"][0] is not None else r["psnr"])
                for r in rows
            ],
            [
                (r["psnr_ci95"][1] if r["psnr_ci95"][1] is not None else r["psnr"]) - r["psnr"]
                for r in rows
            ],
        ]
        bound = rows[0].get("bound")
        ax.errorbar(
            x,
            y,
            yerr=err,
            marker="o",
            capsize=3,
            linestyle="--" if bound else "-",
            label=f"{s} (bound)" if bound else s,
        )
    ax.set_xlabel("SNR (Es/N0) [dB]")
    ax.set_ylabel("PSNR [dB] (mean per image)")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    write_figure(path, fig, dpi=120)
    plt.close(fig)

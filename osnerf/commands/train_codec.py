"""`osnerf train-codec`: train the semantic codec (JSCC) through a channel on CPU.

Resumable: run the same command again and it continues from ``OUT/last_state.pt``.
Writes ``OUT/best.safetensors`` and ``last.safetensors`` (weights + model card),
``OUT/log.jsonl`` (loss, PSNR, learning rate) and ``OUT/summary.json``.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

from osnerf.cli import UsageError
from osnerf.commands import args as checks
from osnerf.paths import shared_data_dir


def add_arguments(p: argparse.ArgumentParser) -> None:
    from semcodec.training import TrainConfig

    d = TrainConfig()
    p.add_argument(
        "--data",
        action="append",
        default=None,
        help="training image folder (repeatable; default: BSDS500 train and val)",
    )
    p.add_argument("--val", default=None, help="validation image folder (default: BSDS500 test)")
    p.add_argument(
        "--out", required=True, help="output folder (checkpoints, log.jsonl, summary.json)"
    )
    p.add_argument("--model", default=d.model, help=f"architecture (default: {d.model})")
    from semcodec.channel_layers import TRAIN_CHANNELS

    p.add_argument(
        "--channel",
        default=d.channel,
        help=f"training channel, or a comma-separated mixture drawn per step: {', '.join(TRAIN_CHANNELS)} (default: {d.channel})",
    )
    for name in (
        "snr_min_db",
        "snr_max_db",
        "focus_snr_min_db",
        "focus_snr_max_db",
        "p_wide_snr",
        "p_focus_m",
        "decay_fraction",
    ):
        p.add_argument(
            "--" + name.replace("_", "-"),
            type=float,
            default=getattr(d, name),
            help=f"TrainConfig.{name} (default: {getattr(d, name)})",
        )
    p.add_argument(
        "--max-minutes", type=float, default=d.max_minutes, help="training time budget in minutes"
    )
    p.add_argument(
        "--crop-px", type=int, default=d.crop_px, help=f"crop size (default: {d.crop_px})"
    )
    p.add_argument(
        "--batch-size",
        type=int,
        default=d.batch_size,
        help=f"crops per step (default: {d.batch_size})",
    )
    p.add_argument("--lr", type=float, default=d.lr, help=f"peak learning rate (default: {d.lr})")
    p.add_argument(
        "--save-every-s", type=float, default=d.save_every_s, help="seconds between checkpoints"
    )
    p.add_argument(
        "--eval-every-s", type=float, default=d.eval_every_s, help="seconds between validations"
    )
    p.add_argument(
        "--threads",
        type=checks.threads,
        default=d.num_threads,
        help="torch CPU threads (default: 2)",
    )
    p.add_argument(
        "--init", default=None, help="start from this checkpoint (fine-tuning, e.g. on rayleigh)"
    )
    p.add_argument("--no-resume", action="store_true", help="start over even if OUT holds a run")
    p.add_argument(
        "--seed", type=checks.seed, default=0, help="seed of crops, SNRs, rates and noise"
    )


def run(args: argparse.Namespace) -> int:
    from osnerf.provenance import result_header, write_json_atomic
    from semcodec.model import MODELS
    from semcodec.training import TrainConfig, load_train_state, train

    if args.model not in MODELS:
        raise KeyError(f"--model must be one of {sorted(MODELS)}, got {args.model!r}")
    cfg = TrainConfig(
        model=args.model,
        channel=args.channel,
        crop_px=args.crop_px,
        batch_size=args.batch_size,
        lr=args.lr,
        max_minutes=args.max_minutes,
        save_every_s=args.save_every_s,
        eval_every_s=args.eval_every_s,
        seed=args.seed,
        num_threads=args.threads,
        snr_min_db=args.snr_min_db,
        snr_max_db=args.snr_max_db,
        focus_snr_min_db=args.focus_snr_min_db,
        focus_snr_max_db=args.focus_snr_max_db,
        p_wide_snr=args.p_wide_snr,
        p_focus_m=args.p_focus_m,
        decay_fraction=args.decay_fraction,
    )
    bsds = shared_data_dir() / "bsds500"
    data = [Path(d) for d in (args.data or [bsds / "train", bsds / "val"])]
    for d in data:
        if not d.is_dir():
            raise FileNotFoundError(f"--data folder not found: {d}")
    val = Path(args.val) if args.val else bsds / "test"
    if not val.is_dir():
        raise FileNotFoundError(f"--val folder not found: {val}")
    init = Path(args.init) if args.init else None
    out = checks.output_dir(args.out, "--out")
    state = out / "last_state.pt"
    if not args.no_resume and state.exists():
        try:
            load_train_state(state)
        except ValueError as e:
            raise UsageError(f"{e}; start over with --no-resume (or delete it)") from None
    summary = train(
        cfg,
        data,
        out,
        val_dir=val,
        resume=not args.no_resume,
        init=init,
        card_extra={"name": f"{cfg.model}-{cfg.channel}"},
    )
    write_json_atomic(
        out / "summary.json", {**result_header(dataclasses.asdict(cfg), args.seed), **summary}
    )
    print(
        f"train-codec: {summary['steps']} steps, validation {summary['validation']}; {out}",
        file=sys.stderr,
    )
    return 0

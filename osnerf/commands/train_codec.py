"""`osnerf train-codec`: train any registered semantic codec through a channel.

``--codec NAME[:CHECKPOINT]`` picks the codec (``semcodec.CODECS``, plugins included; a
checkpoint starts from its weights). On one process it runs as is; under ``torchrun
--nproc-per-node N -m osnerf.cli train-codec ...`` it trains with DDP (gloo on CPU, nccl on
``--device cuda``), each rank taking its share of ``--batch-size``, rank 0 writing.
Resumable at any world size: run the same command again and it continues from
``OUT/last_state.pt``. A resume may change only what ``semcodec.training.RESUMABLE_FIELDS`` lists
(more ``--max-steps``, a later ``--max-minutes``, save and validation intervals, threads,
device); each such change is recorded in the model card's ``resumes``. Any other change
(``--lr``, ``--seed``, ``--data``, ...) is refused with the changed fields named, unless
``--overwrite`` (which starts over). A training that dies before its first checkpoint
leaves nothing behind.
Writes ``OUT/best.safetensors`` and ``last.safetensors`` (weights + model card),
``OUT/log.jsonl`` (loss, PSNR, learning rate; written as training goes) and
``OUT/summary.json`` (with the record of ``best.safetensors``: its codec, sha256 and, for a
plugin, its distribution). ``--model`` left out trains the codec's first architecture.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
from pathlib import Path

from osnerf.cli import UsageError, inputs_checked
from osnerf.commands import args as checks
from osnerf.commands.config_cli import add_config_arguments, config_from_args, flag_of
from osnerf.paths import shared_data_dir
from osnerf.provenance import codec_record, result_header, write_json_atomic
from semcodec import TrainConfig, open_codec, parse_codec_spec, train
from semcodec.training import (
    ResumeRefused,
    build_codec,
    check_resume,
    describe_changes,
    load_train_state,
    train_inputs,
    with_architecture,
)

# TrainConfig fields that are options, in --help order; all but num_threads keep their name.
CONFIG_FIELDS = (
    "codec",
    "model",
    "channel",
    "snr_min_db",
    "snr_max_db",
    "focus_snr_min_db",
    "focus_snr_max_db",
    "p_wide_snr",
    "p_focus_m",
    "warmup_steps",
    "decay_fraction",
    "max_minutes",
    "crop_px",
    "batch_size",
    "lr",
    "save_every_s",
    "eval_every_s",
    "num_threads",
    "seed",
    "max_steps",
    "device",
    "ddp_backend",
)
FLAGS = {"num_threads": "--threads"}


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--data",
        action="append",
        default=None,
        help="training image folder (repeatable; default: BSDS500 train and val)",
    )
    p.add_argument("--val", default=None, help="validation image folder (default: BSDS500 test)")
    p.add_argument(
        "--out",
        required=True,
        help="output folder (checkpoints, log.jsonl, summary.json); a folder holding an "
        "earlier training (last_state.pt) is resumed, any other non-empty folder is refused "
        "without --overwrite",
    )
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="train into an --out folder that holds other files, or start over in one that "
        "holds a training (with --no-resume, or when the arguments differ from that "
        "training's); without it such a folder is refused (exit 2)",
    )
    probability = checks.number(0.0, 1.0)
    add_config_arguments(
        p,
        TrainConfig,
        CONFIG_FIELDS,
        flags=FLAGS,
        types={
            "channel": None,
            "p_wide_snr": probability,
            "p_focus_m": probability,
            "decay_fraction": probability,
            "max_minutes": checks.number(0.0, checks.MAX_BUDGET_S / 60, "min", low_open=True),
            "crop_px": checks.count(16, 512),
            "batch_size": checks.count(1, 256),
            "lr": checks.number(0.0, 0.1, low_open=True),
            "save_every_s": checks.seconds,
            "eval_every_s": checks.seconds,
            "num_threads": checks.count(1, 64),
            "seed": checks.seed,
            "max_steps": checks.count(0, 10_000_000),
            "warmup_steps": checks.count(0, 1_000_000),
        },
    )
    p.add_argument(
        "--init", default=None, help="start from this checkpoint (fine-tuning, e.g. on rayleigh)"
    )
    p.add_argument(
        "--no-resume",
        action="store_true",
        help="start over even if OUT holds a training (needs --overwrite)",
    )


def run(args: argparse.Namespace) -> int:
    cfg, data, val, init, out, resume = parse(args)
    inputs_checked()  # from here on a failure is a runtime failure (exit 1)
    summary = train_codec(cfg, data, val, init, out, resume=resume)
    report(cfg, summary, out)
    return 0


def parse(args: argparse.Namespace):
    """Check every input before any work: (config, data folders, validation folder, init
    checkpoint or None, output folder, whether to resume the training there)."""
    cfg = config_from_args(TrainConfig, args, CONFIG_FIELDS, flags=FLAGS)
    cfg = with_architecture(cfg)  # --model left out: the codec's own first architecture
    _check_backend(cfg)
    build_codec(cfg, None)  # an unknown codec, architecture or checkpoint: refused before work
    bsds = shared_data_dir() / "bsds500"
    where = "$OSNERF_DATA" if os.environ.get("OSNERF_DATA") else "the shared data folder"
    data = [Path(d) for d in (args.data or [bsds / "train", bsds / "val"])]
    for d in data:
        if not d.is_dir():
            if args.data:
                raise FileNotFoundError(f"--data folder not found: {d}")
            raise FileNotFoundError(
                f"{where} {str(shared_data_dir())!r} has no {d.name} in bsds500/; give --data"
            )
    val = Path(args.val) if args.val else bsds / "test"
    if not val.is_dir():
        if args.val:
            raise FileNotFoundError(f"--val folder not found: {val}")
        raise FileNotFoundError(
            f"{where} {str(shared_data_dir())!r} has no bsds500/test; give --val"
        )
    init = Path(args.init) if args.init else None
    inputs = {**{f"--data {d}": str(d) for d in data}, "--val": str(val)}
    out = checks.output_dir(
        args.out,
        "--out",
        overwrite=args.overwrite,
        resumable=lambda d: not args.no_resume and (d / "last_state.pt").is_file(),
        inputs=inputs,
    )
    resume = not args.no_resume and _resumable(args, cfg, data, init, out)
    return cfg, data, val, init, out, resume


def _check_backend(cfg) -> None:
    """``--ddp-backend`` names the process group's backend: it needs torchrun (more than one
    process), and nccl needs ``--device cuda``."""
    if cfg.ddp_backend == "nccl" and not cfg.device.startswith("cuda"):
        raise UsageError(
            f"--ddp-backend nccl needs --device cuda (got --device {cfg.device}); use gloo "
            "(or auto) on cpu"
        )
    if cfg.ddp_backend != "auto" and int(os.environ.get("WORLD_SIZE", "1")) <= 1:
        raise UsageError(
            f"--ddp-backend {cfg.ddp_backend} applies only under torchrun with more than one "
            "process (WORLD_SIZE > 1); leave it out to train in one process"
        )


def _resumable(args, cfg, data, init, out: Path) -> bool:
    """True when ``out`` holds a training that this run continues; False when there is none,
    or when it is another training's and ``--overwrite`` starts over.

    Raises:
        UsageError: the state is unreadable, or resuming would change a field that may not
            change (``semcodec.training.RESUMABLE_FIELDS``), named with its flag, without
            --overwrite.
    """
    state = out / "last_state.pt"
    if not state.exists():
        return False
    try:
        st = load_train_state(state)
    except ValueError as e:
        raise UsageError(f"{e}; start over with --no-resume --overwrite") from None
    try:
        check_resume(st, cfg, train_inputs(data, init), state)
    except ResumeRefused as e:
        names = {n: flag_of(n, FLAGS) for n in CONFIG_FIELDS} | {"data": "--data", "init": "--init"}
        what = f"changes {describe_changes(e.changes, names)}" if e.changes else None
        if args.overwrite:
            print(
                f"train-codec: --overwrite: starting over in {out} (its training at step "
                f"{st['step']}: {what or e})",
                file=sys.stderr,
            )
            return False
        if not e.changes:
            raise checks.flag_error(e) from None
        raise UsageError(
            f"--out {str(out)!r} holds another training: this run {what}; rerun with its "
            "arguments to resume it, give --overwrite to start over, or train into a new --out "
            f"with --init {out / 'last.safetensors'}"
        ) from None
    return True


def train_codec(cfg, data, val, init, out, resume: bool) -> dict:
    """Train (resuming when asked and possible); the summary with its result header."""
    try:
        summary = train(
            cfg,
            data,
            out,
            val_dir=val,
            resume=resume,
            init=init,
            card_extra={"name": f"{cfg.codec.split(':')[0]}-{cfg.model}-{cfg.channel}"},
        )
    except ValueError as e:
        raise checks.flag_error(e, {n: flag_of(n, FLAGS) for n in CONFIG_FIELDS}) from None
    return {**result_header(dataclasses.asdict(cfg), cfg.seed), **summary}


def trained_codec(cfg, out: Path) -> dict:
    """The record (:func:`osnerf.provenance.codec_record`) of ``OUT/best.safetensors``, loaded
    through the codec's own factory: its sha256 and, for a plugin, its distribution."""
    spec = f"{parse_codec_spec(cfg.codec)[0]}:{out / 'best.safetensors'}"
    return codec_record(open_codec(spec, allow_untrained=True), spec)


def report(cfg, summary: dict, out: Path) -> None:
    if int(os.environ.get("RANK", "0")) != 0:  # under torchrun, rank 0 writes
        return
    if summary.get("nothing_to_do"):  # a finished training: its files stay as they are
        return
    write_json_atomic(out / "summary.json", {**summary, "codec": trained_codec(cfg, out)})
    print(
        f"train-codec: {summary['steps']} steps, validation {summary['validation']}; {out}",
        file=sys.stderr,
    )

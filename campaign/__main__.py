"""``python -m campaign continue|promote|pack|status``: the codec training campaign.

* ``continue``: one stretch of a line on whatever device is here (two learning rates from
  the line's best, scored on the held-out set, the log appended, the better kept).
* ``promote``: a candidate against the shipped default on Kodak and over the air; promotes
  it only by :data:`campaign.promotion.RULE`.
* ``pack``: the folder a bare GPU machine needs (training images, held-out set, sionna).
* ``status``: each line's best, minutes and next learning rates.

Exit 0 on success, 2 on bad input (one line naming the option), 1 on a runtime failure.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from campaign.pack import PACK, is_pack, pack
from campaign.promotion import add_arguments, run
from campaign.store import Campaign, at_work
from common import InputError
from osnerf.paths import shared_data_dir

ROOT = Path(__file__).resolve().parent.parent
HERE = Path(__file__).resolve().parent


class _Parser(argparse.ArgumentParser):
    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message}\n")


def _positive(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        v = float("nan")
    if not 0 < v <= 600:
        raise argparse.ArgumentTypeError(f"must be a number of minutes in (0, 600], got {text!r}")
    return v


def _count(lo: int, hi: int):
    def parse(text: str) -> int:
        if not text.isdigit() or not lo <= int(text) <= hi:
            raise argparse.ArgumentTypeError(f"must be an integer in [{lo}, {hi}], got {text!r}")
        return int(text)

    return parse


def _lrs(text: str) -> tuple[float, float]:
    try:
        vals = tuple(float(v) for v in text.split(","))
    except ValueError:
        vals = ()
    if len(vals) != 2 or not all(0 < v <= 0.1 for v in vals):
        raise argparse.ArgumentTypeError(f"must be two learning rates in (0, 0.1], got {text!r}")
    return vals  # type: ignore[return-value]


def _add_continue(sub) -> None:
    p = sub.add_parser("continue", help="one stretch of a line on this machine's device")
    p.add_argument("--campaign", default=str(HERE), help="campaign folder (default: this one)")
    p.add_argument("--line", default=None, help="line of runs (default: the campaign's)")
    budget = p.add_mutually_exclusive_group(required=True)
    budget.add_argument("--minutes", type=_positive, help="training minutes of each run")
    budget.add_argument("--steps", type=_count(1, 10**7), help="optimiser steps of each run")
    p.add_argument("--device", default="auto", choices=("auto", "cpu", "cuda"))
    p.add_argument(
        "--data",
        action="append",
        default=None,
        help="training image folder (repeatable; default: .campaign-carry/data/train and val "
        "when packed, else the shared BSDS500 train and val)",
    )
    p.add_argument(
        "--val",
        default=None,
        help="held-out images (default: .campaign-carry/data/test, else BSDS500 test)",
    )
    p.add_argument("--work", default=None, help="folder for the runs (default: a new temp folder)")
    p.add_argument(
        "--lrs", type=_lrs, default=None, help="two learning rates (default: the line's)"
    )
    p.add_argument(
        "--jobs", type=_count(1, 2), default=None, help="2: two processes (CUDA default)"
    )
    p.add_argument("--batch-size", type=_count(1, 256), default=None, help="override the recipe")
    p.add_argument("--crop-px", type=_count(16, 512), default=None, help="override the recipe")
    p.add_argument("--warmup-steps", type=_count(0, 10**6), default=None, help="override")


def _add_promote(sub) -> None:
    add_arguments(sub.add_parser("promote", help="compare a candidate with the shipped default"))


def _add_pack(sub) -> None:
    p = sub.add_parser("pack", help="write the folder a GPU machine needs (carry it)")
    p.add_argument("--bsds", default=None, help="BSDS500 folder (default: the shared data's)")
    p.add_argument("--out", default=str(ROOT / PACK), help=f"folder to write (default {PACK})")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="python -m campaign", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="verb", required=True, parser_class=_Parser)
    _add_continue(sub)
    _add_promote(sub)
    _add_pack(sub)
    s = sub.add_parser("status", help="each line's best and minutes")
    s.add_argument("--campaign", default=str(HERE))
    return parser


def _data_defaults(args) -> tuple[list[Path], Path]:
    packed = ROOT / PACK / "data"
    base = packed if is_pack(ROOT / PACK) else shared_data_dir() / "bsds500"
    data = [Path(d) for d in args.data] if args.data else [base / "train", base / "val"]
    val = Path(args.val) if args.val else base / "test"
    for flag, d in [*(("--data", d) for d in data), ("--val", val)]:
        if not d.is_dir():
            raise InputError(f"{flag} folder not found: {d}")
    return data, val


def _continue(args) -> int:
    import tempfile

    from campaign.stretch import StretchOptions, continue_line, resolve_device

    camp = Campaign.open(args.campaign)
    name, line = camp.line(args.line)
    camp.best_path(line)  # a moved reference is refused before any work
    camp.check_writable()  # and a folder that cannot take the results
    data, val = _data_defaults(args)
    resolve_device(args.device)
    _check_channels(line["train"]["channel"], camp.doc["validation"]["channels"])
    names = {"batch_size": args.batch_size, "crop_px": args.crop_px}
    names["warmup_steps"] = args.warmup_steps
    overrides = {k: v for k, v in names.items() if v is not None}
    work = Path(args.work) if args.work else Path(tempfile.mkdtemp(prefix="campaign-"))
    opts = StretchOptions(
        name,
        args.minutes or 0.0,
        args.steps or 0,
        args.device,
        data,
        val,
        work,
        args.lrs,
        args.jobs,
        overrides,
    )
    summary = at_work(continue_line, camp, opts)
    vset = summary["validation_set"]
    if not vset["campaign_set"]:
        print(
            f"campaign: scored on {vset['folder']}, not the campaign's held-out set: logged, "
            "never kept as the line's best",
            file=sys.stderr,
        )
    for r in summary["records"]:
        print(
            f"campaign: {r['line']} stretch {r['stretch']} lr {r['lr']:g}: score "
            f"{r['score']:.3f} dB after {r['steps']} steps on {r['device']}"
            + (" (kept as the line's best)" if r["kept"] else ""),
            file=sys.stderr,
        )
    return 0


def _check_channels(*mixtures: str) -> None:
    """Every channel known, and sionna importable when TDL is in a mixture (``pack`` brings it
    to a GPU machine)."""
    import importlib.util

    from semcodec.training import TRAIN_CHANNELS

    for mix in mixtures:
        for ch in mix.split(","):
            if ch not in TRAIN_CHANNELS:
                raise InputError(f"campaign channel {ch!r} is not in semcodec.jscc.TRAIN_CHANNELS")
            if "tdl" in ch and importlib.util.find_spec("sionna") is None:
                raise InputError(
                    f"channel {ch} needs sionna, not importable here: run python -m campaign "
                    "pack and set PYTHONPATH=.campaign-carry/site"
                )


def _status(args) -> int:
    camp = Campaign.open(args.campaign)
    for name, line in camp.doc["lines"].items():
        best = line.get("best")
        where = f"{best['path']} score {best.get('score', float('nan')):.3f}" if best else "none"
        print(
            f"{name}: {line['model']}, best {where}, {line.get('stretches', 0)} stretches, "
            f"{line.get('device_minutes', 0):.1f} device-min, {line.get('cpu_minutes', 0):.1f} "
            f"CPU-min, next lrs {line['lrs']}"
        )
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as e:
        return int(e.code or 0)
    try:
        if args.verb == "continue":
            return _continue(args)
        if args.verb == "promote":
            return run(args)
        if args.verb == "pack":
            bsds = Path(args.bsds) if args.bsds else shared_data_dir() / "bsds500"
            count = Campaign.open().doc["validation"]["count"]
            print(pack(bsds, Path(args.out), int(count)))
            return 0
        return _status(args)
    except (ValueError, KeyError, FileNotFoundError) as e:
        msg = e.args[0] if isinstance(e, KeyError) and e.args else e
        line = (str(msg).strip().splitlines() or [type(e).__name__])[0]
        print(f"python -m campaign {args.verb}: error: {line}", file=sys.stderr)
        return 2
    except (RuntimeError, OSError) as e:
        line = (str(e).strip().splitlines() or [type(e).__name__])[0]
        print(f"python -m campaign {args.verb}: failed: {line}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(
            f"python -m campaign {args.verb}: interrupted; {_UNTOUCHED[args.verb]}", file=sys.stderr
        )
        return 130


_UNTOUCHED = {
    "continue": "campaign.json and log.jsonl unchanged (the runs' folders keep what they wrote)",
    "promote": "nothing promoted, no file changed",
    "pack": "the pack folder not written",
    "status": "nothing changed",
}


if __name__ == "__main__":
    sys.exit(main())

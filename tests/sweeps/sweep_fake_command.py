"""A tiny stand-in osnerf command for the sweep tests: `fake --snr-db X --mode M --seed S --out F`.

Its metric is a known function of its options and seed, so tests can check every point's
result. It appends one line per invocation to --log (to count how often a point ran), can
sleep (to be killed mid-sweep), can fail on purpose at one SNR, and can leave a progress bar
drawn on stderr when it fails (as a command that fails mid-loop does).
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np

from osnerf import result_header, write_json_atomic

NAME = "fake"
ENTRY = ("sweep_fake_command", "stand-in command for the sweep tests")


def expected_value(snr_db: float, mode: str, seed: int) -> float:
    """The metric a point reports: 10*snr + (1 if mode == 'b') + first uniform of the seed."""
    return (
        10.0 * snr_db + (1.0 if mode == "b" else 0.0) + float(np.random.default_rng(seed).random())
    )


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--snr-db", type=float, required=True)
    p.add_argument("--mode", choices=["a", "b"], default="a")
    p.add_argument("--verbose", action="store_true")
    p.add_argument("--sleep-s", type=float, default=0.0)
    p.add_argument("--fail-snr-db", type=float, default=None, help="raise at this SNR")
    p.add_argument("--fail-once-flag", default=None, help="fail while this file does not exist")
    p.add_argument("--interrupt-snr-db", type=float, default=None, help="Ctrl-C at this SNR")
    p.add_argument("--level", default="low", help="low or high, checked in run() only")
    p.add_argument("--log", default=None)
    p.add_argument("--bar", action="store_true", help="draw a progress bar, left open")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", required=True)


def run(args: argparse.Namespace) -> int:
    if args.log:
        with open(args.log, "a") as f:
            f.write(f"{args.snr_db} {args.mode} {args.seed} {os.getpid()}\n")
    time.sleep(args.sleep_s)
    if args.bar:
        import sys

        from tqdm import tqdm

        bar = tqdm(total=4, desc="fake", file=sys.stderr)
        bar.update(1)
    if args.fail_snr_db is not None and args.snr_db == args.fail_snr_db:
        if args.fail_once_flag is None or not os.path.exists(args.fail_once_flag):
            raise RuntimeError(f"planned failure at snr_db={args.snr_db}")
    if args.level not in ("low", "high"):
        raise ValueError(f"--level must be one of low, high; got {args.level!r}")
    if args.interrupt_snr_db is not None and args.snr_db == args.interrupt_snr_db:
        raise KeyboardInterrupt
    config = {"snr_db": args.snr_db, "mode": args.mode}
    out = result_header(config, args.seed)
    out["results"] = [
        {"snr_db": args.snr_db, "value": expected_value(args.snr_db, args.mode, args.seed)}
    ]
    # `--out x.json` names the file; any other --out is a run folder holding metrics.json
    path = Path(args.out) if args.out.endswith(".json") else Path(args.out) / "metrics.json"
    write_json_atomic(path, out)
    if path.name == "metrics.json":
        (path.parent / "view.txt").write_text("a rendered view\n")
    return 0

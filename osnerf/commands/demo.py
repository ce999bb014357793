"""`osnerf demo`: the main job on its embedded default.

The end-to-end pipeline (`osnerf run`) on the default scene and demand at 0 dB over
Rayleigh fading.
"""

from __future__ import annotations

import argparse

from osnerf.cli import main


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", default="runs/demo", help="output folder (default: runs/demo)")
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="write into an --out that holds something other than this demo's own run "
        "(refused without it, as `osnerf run` does)",
    )


def run(args: argparse.Namespace) -> int:
    argv = ["run", "--channel", "rayleigh", "--snr-db", "0", "--seed", "0", "--out", args.out]
    return main(argv + (["--overwrite"] if args.overwrite else []))

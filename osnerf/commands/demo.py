"""`osnerf demo`: the main job on its embedded default.

The end-to-end pipeline (`osnerf run`) on the default scene and demand at 0 dB over
Rayleigh fading. Until the pipeline is in this checkout it runs a BER sweep.
"""

from __future__ import annotations

import argparse
import importlib.util
import sys


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", default="runs/demo", help="output folder (default: runs/demo)")


def run(args: argparse.Namespace) -> int:
    from osnerf.cli import main

    if importlib.util.find_spec("osnerf.commands.run") is not None:
        return main(
            ["run", "--channel", "rayleigh", "--snr-db", "0", "--seed", "0", "--out", args.out]
        )
    out = f"{args.out}/ber.json"
    rc = main(
        [
            "ber",
            "--channel",
            "awgn",
            "--modulation",
            "qpsk",
            "--snr-db",
            "0,2,4,6,8,10",
            "--num-bits",
            "200000",
            "--seed",
            "0",
            "--out",
            out,
            "--plot",
            f"{args.out}/ber.png",
        ]
    )
    if rc == 0:
        print(f"results: {out}", file=sys.stderr)
    return rc

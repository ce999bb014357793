"""`osnerf plot results.jsonl --out DIR [--no-anchors] [--formats png,pdf]`.

Writes every figure the sweep results support (BER vs SNR with theory; PSNR/SSIM vs SNR
per scheme with published Kodak anchors; PSNR vs CBR; the digital baseline's cliff) as PNG
and PDF into DIR, and lists them on stderr.
"""

from __future__ import annotations

import argparse
import sys


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("results", metavar="RESULTS", help="results file of `osnerf sweep` (JSON Lines)")
    p.add_argument("--out", required=True, help="folder for the figures")
    p.add_argument(
        "--no-anchors",
        action="store_true",
        help="leave out the published reference curves (jscc-anchors)",
    )
    p.add_argument(
        "--formats", default="png,pdf", help="comma-separated: png, pdf, svg (default png,pdf)"
    )
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="write into an --out folder that already holds files; without it such a folder is refused (exit 2)",
    )


def run(args: argparse.Namespace) -> int:
    from osnerf.cli import inputs_checked
    from osnerf.commands import args as checks
    from osnerf.plots import make_plots
    from osnerf.sweeps import read_results

    checks.output_dir(args.out, "--out", overwrite=args.overwrite)
    formats = tuple(f.strip().lower() for f in args.formats.split(",") if f.strip())
    records = read_results(args.results)
    if not records:
        raise ValueError(f"RESULTS {args.results!r} holds no finished points")
    inputs_checked()  # from here on a failure is a runtime failure (exit 1)
    written = make_plots(records, args.out, anchors=not args.no_anchors, formats=formats)
    for path in written:
        print(f"wrote {path}", file=sys.stderr)
    return 0

"""`osnerf plot RESULTS [RESULTS ...] --out DIR [--no-anchors] [--formats png,pdf]`.

RESULTS: sweep results (JSON Lines) or ``osnerf eval-codec`` result files (JSON), one or more,
drawn together. Writes every figure they support (BER vs SNR with theory; PSNR/SSIM/MS-SSIM
vs SNR per scheme with published Kodak anchors; PSNR vs CBR; the digital baseline's
staircase and envelope in PSNR and MS-SSIM; the SNR-mismatch panel; the outage CDF on block
fading) as PNG and PDF into DIR, and lists them on stderr.
"""

from __future__ import annotations

import argparse
import sys

from osnerf.cli import inputs_checked
from osnerf.commands import args as checks
from osnerf.sweeps import read_results


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "results",
        metavar="RESULTS",
        nargs="+",
        help="results of `osnerf sweep` (JSON Lines) or `osnerf eval-codec` (JSON), one or more",
    )
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
        help=(
            "write into an --out folder that already holds files; without it such a folder is "
            "refused (exit 2)"
        ),
    )


def run(args: argparse.Namespace) -> int:
    from osnerf.plots import make_plots

    checks.output_dir(args.out, "--out", overwrite=args.overwrite)
    formats = tuple(f.strip().lower() for f in args.formats.split(",") if f.strip())
    records = []
    for path in args.results:
        got = _records(path)
        if not got:
            raise ValueError(f"RESULTS {path!r} holds no finished points")
        records += got
    inputs_checked()  # from here on a failure is a runtime failure (exit 1)
    written = make_plots(records, args.out, anchors=not args.no_anchors, formats=formats)
    for path in written:
        print(f"wrote {path}", file=sys.stderr)
    return 0


def _records(path: str) -> list[dict]:
    """The records of one results file: an eval-codec JSON document (one record), else sweep
    JSON Lines."""
    import json
    from pathlib import Path

    from osnerf.plots import eval_record

    p = Path(path)
    if p.suffix == ".json" and p.is_file():
        try:
            doc = json.loads(p.read_text())
        except json.JSONDecodeError:
            doc = None
        if isinstance(doc, dict) and isinstance(doc.get("results"), list):
            return [eval_record(doc)]
    return read_results(path)

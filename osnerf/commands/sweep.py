"""`osnerf sweep SPEC --out results.jsonl [--executor local|ray|serial] [--workers N]`.

Runs every point of a YAML/TOML sweep spec (see ``osnerf.sweeps.spec``) that is not yet in
the results file, appending one JSON line per finished point. Re-running the same command
skips finished points and retries failed ones. Exit 1 when a point failed (the others are
kept; their errors are in ``<out>.errors.jsonl``).
"""

from __future__ import annotations

import argparse
import sys

from osnerf.commands import args as checks
from osnerf.sweeps import errors_path, load_spec, run_sweep
from osnerf.sweeps.spec import MAX_POINTS

MAX_POINTS_LIMIT = 10_000_000
MAX_WORKERS = 256


def max_points(text: str) -> int:
    """``--max-points``: an integer in [1, MAX_POINTS_LIMIT]."""
    return checks.int_in(text, 1, MAX_POINTS_LIMIT)


def workers(text: str) -> int:
    """``--workers``: an integer in [1, MAX_WORKERS]."""
    return checks.int_in(text, 1, MAX_WORKERS)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("spec", metavar="SPEC", help="sweep spec (.yaml, .yml or .toml)")
    p.add_argument(
        "--out",
        required=True,
        help="results file, JSON Lines: an existing one of the same spec is resumed (finished "
        "points kept, failed ones retried); any other existing file is refused",
    )
    p.add_argument(
        "--executor",
        default="local",
        choices=["local", "ray", "serial"],
        help="local process pool (default), a Ray cluster, or serial in this process",
    )
    p.add_argument(
        "--workers",
        type=workers,
        default=None,
        help=f"points run in parallel, 1..{MAX_WORKERS} (default: half the CPU cores)",
    )
    p.add_argument(
        "--ray-address",
        default=None,
        help="Ray cluster address for --executor ray (default: $RAY_ADDRESS or a local instance)",
    )
    p.add_argument(
        "--keep-outputs",
        default=None,
        metavar="DIR",
        help=(
            "keep each point's own output (JSON, or run folder with views) in DIR (default: "
            "deleted)"
        ),
    )
    p.add_argument(
        "--max-points",
        type=max_points,
        default=MAX_POINTS,
        help=f"refuse a spec with more points than this, counted before they are expanded "
        f"(default {MAX_POINTS}; at most {MAX_POINTS_LIMIT})",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    checks.output_file(args.out, "--out", resume=True, inputs={"SPEC": args.spec})
    if args.keep_outputs:
        checks.output_dir(args.keep_outputs, "--keep-outputs", resumable=lambda _: True)
    spec = load_spec(args.spec, args.max_points)
    summary = run_sweep(
        spec,
        args.out,
        executor=args.executor,
        workers=args.workers,
        progress=not args.no_progress,
        ray_address=args.ray_address,
        keep=args.keep_outputs,
    )
    print(
        f"osnerf sweep: {summary.total} points: {summary.skipped} already done, "
        f"{summary.finished} finished now, {len(summary.failed)} failed -> {args.out}",
        file=sys.stderr,
    )
    if summary.failed:
        print(
            f"osnerf sweep: failed: {len(summary.failed)} point(s), errors in "
            f"{errors_path(args.out)}; re-run the same command to retry them",
            file=sys.stderr,
        )
        return 1
    print(f"osnerf sweep: plot with `osnerf plot {args.out} --out DIR`", file=sys.stderr)
    return 0

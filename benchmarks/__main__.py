"""Run every benchmark (or those named) and write bench-results/<name>.json."""

from __future__ import annotations

import argparse
import importlib
import sys
import time
import traceback
from pathlib import Path

from common import tune_malloc
from osnerf import git_commit, result_header, write_json_atomic

HERE = Path(__file__).resolve().parent


def main(argv: list[str] | None = None) -> int:
    names = sorted(p.stem[len("bench_") :] for p in HERE.glob("bench_*.py"))
    parser = argparse.ArgumentParser(prog="python -m benchmarks")
    parser.add_argument(
        "names", nargs="*", help=f"benchmarks to run (default all): {', '.join(names)}"
    )
    parser.add_argument("--out", default="bench-results", help="output folder")
    args = parser.parse_args(argv)
    unknown = sorted(set(args.names) - set(names))
    if unknown:
        print(f"unknown benchmark(s) {unknown}; known: {names}", file=sys.stderr)
        return 2
    out = Path(args.out)
    malloc_tuned = tune_malloc()
    git_commit()  # read once, now: results name the code the benchmarks started with (cached)
    failed = []
    for name in args.names or names:
        print(f"== benchmark {name}", file=sys.stderr)
        t0 = time.perf_counter()
        try:
            module = importlib.import_module(f"benchmarks.bench_{name}")
            results = module.run(out)
        except Exception:  # noqa: BLE001 - report and go on with the others
            traceback.print_exc()
            failed.append(name)
            continue
        record = result_header({"benchmark": name, "malloc_tuned": malloc_tuned}, None)
        record.update({"seconds": time.perf_counter() - t0, "results": results})
        path = write_json_atomic(out / f"{name}.json", record)
        print(f"   wrote {path}", file=sys.stderr)
    if failed:
        print(f"failed: {failed}", file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())

"""Sweep runner overhead: the same `osnerf ber` points run directly, by the serial executor,
by the local process pool and by a local Ray instance, side by side in one run.

Reports wall seconds per executor, the runner's overhead per point against calling the
command directly (serial), and the start-up cost of the pool and of Ray. Numbers on a shared
2-core machine are noisy.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import osnerf.cli
from osnerf.sweeps import read_results, run_sweep, spec_from_dict

NUM_BITS = 2000
SNRS = [0, 2, 4, 6, 8, 10]
MODULATIONS = ["qpsk", "16qam"]


def run(out_dir: Path) -> dict:
    spec = spec_from_dict(
        {
            "command": "ber",
            "fixed": {"channel": "awgn", "num_bits": NUM_BITS},
            "axes": {"modulation": MODULATIONS, "snr_db": SNRS},
            "seeds": [0],
        }
    )
    n = spec.num_points
    results: dict = {"num_points": n, "num_bits_per_point": NUM_BITS}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        osnerf.cli.main(
            ["ber", "--snr-db", "0", "--num-bits", "100", "--out", str(tmp / "warm.json")]
        )
        t0 = time.perf_counter()
        for m in MODULATIONS:
            for s in SNRS:
                rc = osnerf.cli.main(
                    [
                        "ber",
                        "--channel",
                        "awgn",
                        "--num-bits",
                        str(NUM_BITS),
                        "--modulation",
                        m,
                        "--snr-db",
                        str(s),
                        "--seed",
                        "0",
                        "--out",
                        str(tmp / "direct.json"),
                        "--overwrite",  # the same scratch file for every point
                    ]
                )
                assert rc == 0
        direct = time.perf_counter() - t0
        results["direct_seconds"] = direct
        metrics = {}
        for executor, workers in (("serial", 1), ("local", 2), ("ray", 2)):
            path = tmp / f"{executor}.jsonl"
            t0 = time.perf_counter()
            summary = run_sweep(spec, path, executor=executor, workers=workers, progress=False)
            wall = time.perf_counter() - t0
            assert summary.finished == n and not summary.failed, summary.failed
            recs = read_results(path)
            metrics[executor] = {
                (r["point"]["modulation"], r["point"]["snr_db"]): r["metrics"]["ber"] for r in recs
            }
            results[executor] = {
                "workers": workers,
                "wall_seconds": wall,
                "overhead_per_point_s_vs_direct": (wall - direct) / n,
                "mean_point_seconds": sum(r["seconds"] for r in recs) / n,
            }
        results["same_results_all_executors"] = (
            metrics["serial"] == metrics["local"] == metrics["ray"]
        )
    return results

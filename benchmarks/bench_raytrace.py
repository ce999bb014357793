"""Ray-tracing time per drone position (sionna-rt PathSolver -> CIR -> CFR), 2 threads.

For each scene and ``max_depth``: the first call (includes Dr.Jit compilation), then fresh
positions traced in batches of 1, 8 and 32 (one solver call per batch), and a cached call.
Positions lie on a circle of drone positions 30-60 m up around the ground station. Times
on a shared 2-core machine are noisy: CPU seconds (all threads of this process) are
reported beside wall seconds.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import torch

from phy.raytrace import RayTracer, RayTracingConfig, clear_cache

FREQS = (np.arange(64) - 32) * 15e3
SETUPS = [
    ("simple_street_canyon", (0.0, 0.0, 1.5), 2),
    ("simple_street_canyon", (0.0, 0.0, 1.5), 3),
    ("munich", (8.5, 21.0, 27.0), 2),
]


def _circle(num: int, offset: float, radius_m: float = 40.0) -> np.ndarray:
    ang = offset + np.linspace(0, 2 * np.pi, num, endpoint=False)
    z = 30.0 + 30.0 * (np.arange(num) % 2)
    return np.stack([radius_m * np.cos(ang), radius_m * np.sin(ang), z], axis=1)


def run(out_dir: Path) -> dict:
    torch.set_num_threads(2)
    rows = []
    for scene, rx, depth in SETUPS:
        clear_cache()
        t0 = time.perf_counter()
        tracer = RayTracer(scene, rx, 3.5e9, RayTracingConfig(max_depth=depth))
        load_s = time.perf_counter() - t0
        t0 = time.perf_counter()
        tracer.cfr(_circle(1, 0.0), FREQS)
        first_s = time.perf_counter() - t0
        row = {
            "scene": scene,
            "max_depth": depth,
            "load_s": round(load_s, 3),
            "first_call_s": round(first_s, 3),
        }
        for i, batch in enumerate((1, 8, 32)):
            pos = _circle(batch, 0.1 * (i + 1))
            t0, c0 = time.perf_counter(), time.process_time()
            tracer.cfr(pos, FREQS)
            dt, dc = time.perf_counter() - t0, time.process_time() - c0
            row[f"batch_{batch}_s_per_position"] = round(dt / batch, 4)
            row[f"batch_{batch}_cpu_s_per_position"] = round(dc / batch, 4)
        t0 = time.perf_counter()
        h, outage = tracer.cfr(pos, FREQS)
        row["cached_32_s"] = round(time.perf_counter() - t0, 4)
        stats = tracer.stats(pos)
        row["outage_fraction"] = float(outage.float().mean())
        row["median_path_gain_db"] = (
            float(np.median(stats.path_gain_db[~stats.outage])) if (~stats.outage).any() else None
        )
        row["median_rms_delay_spread_ns"] = float(np.median(stats.rms_delay_spread_s) * 1e9)
        print(row)
        rows.append(row)
    return {"num_subcarriers": len(FREQS), "setups": rows}

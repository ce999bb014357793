"""Codec training throughput: crops per second, 1 process x 2 threads against 2 processes x
1 thread (``torchrun --standalone``, DDP over gloo), and 1 CUDA process where a GPU is present.

Every configuration runs ``semcodec.training.loop.train`` under torchrun in a fresh process with
the same global batch and seed, for a fixed number of steps; throughput is
``steps * batch_size / training seconds``, where training seconds are the trainer's own
step clock (the slowest rank's step time, summed; start-up, data loading and validation are
not counted).

Environment: ``OSNERF_BENCH_TRAINING_STEPS`` (default 60), ``OSNERF_BENCH_TRAINING_CROP_PX``
(96), ``OSNERF_BENCH_TRAINING_BATCH`` (12), ``OSNERF_BENCH_TRAINING_CODECS``
(comma-separated registry names, default ``jscc``), ``OSNERF_BENCH_TRAINING_DATA`` (a
training image folder, default BSDS500 train).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import torch

from osnerf import git_commit

ROOT = Path(__file__).resolve().parent.parent
DRIVER = """
import json, sys
from pathlib import Path
from semcodec.training.loop import TrainConfig, train
cfg, data, out = json.loads(sys.argv[1]), sys.argv[2], sys.argv[3]
summary = train(TrainConfig(**cfg), [Path(data)], Path(out), resume=False)
import torch.distributed as dist
if not dist.is_initialized() or dist.get_rank() == 0:
    print("SUMMARY " + json.dumps(summary), flush=True)
"""
SEED = 0


def _layouts() -> list[dict]:
    """(processes, threads per process, device) to compare."""
    rows = [
        {"processes": 1, "threads": 2, "device": "cpu"},
        {"processes": 2, "threads": 1, "device": "cpu"},
    ]
    if torch.cuda.is_available():
        rows.append({"processes": 1, "threads": 2, "device": "cuda"})
    return rows


def _run_one(codec: str, layout: dict, steps: int, crop_px: int, batch: int, data: Path) -> dict:
    cfg = {
        "codec": codec,
        "model": None,  # the codec's default architecture
        "crop_px": crop_px,
        "batch_size": batch,
        "max_steps": steps,
        "num_threads": layout["threads"],
        "device": layout["device"],
        "seed": SEED,
        "save_every_s": 1e9,
        "eval_every_s": 1e9,
    }
    with tempfile.TemporaryDirectory() as tmp:
        driver = Path(tmp) / "driver.py"
        driver.write_text(DRIVER)
        env = {**os.environ, "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": str(layout["threads"])}
        cmd = [sys.executable, "-m", "torch.distributed.run", "--standalone"]
        cmd += [f"--nproc-per-node={layout['processes']}", str(driver)]
        cmd += [json.dumps(cfg), str(data), str(Path(tmp) / "out")]
        proc = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=3600)
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("SUMMARY ")]
    if proc.returncode != 0 or not lines:
        tail = (proc.stderr or proc.stdout).strip().splitlines()[-1:] or ["no output"]
        raise RuntimeError(f"training run {layout} failed ({proc.returncode}): {tail[0]}")
    summary = json.loads(lines[-1][len("SUMMARY ") :])
    seconds = summary["minutes"] * 60.0
    return {
        **layout,
        "codec": codec,
        "steps": summary["steps"],
        "training_seconds": seconds,
        "crops_per_s": summary["steps"] * batch / seconds,
    }


def run(out: Path) -> dict:
    """Measure every layout for every codec; returns the table and its configuration."""
    steps = int(os.environ.get("OSNERF_BENCH_TRAINING_STEPS", "60"))
    crop_px = int(os.environ.get("OSNERF_BENCH_TRAINING_CROP_PX", "96"))
    batch = int(os.environ.get("OSNERF_BENCH_TRAINING_BATCH", "12"))
    codecs = os.environ.get("OSNERF_BENCH_TRAINING_CODECS", "jscc").split(",")
    default_data = ROOT.parent / "shared" / "data" / "bsds500" / "train"
    data = Path(os.environ.get("OSNERF_BENCH_TRAINING_DATA", default_data))
    rows = [
        _run_one(c, layout, steps, crop_px, batch, data) for c in codecs for layout in _layouts()
    ]
    for r in rows:
        print(
            f"   {r['codec']:10s} {r['processes']} proc x {r['threads']} thr {r['device']:4s}: "
            f"{r['crops_per_s']:.1f} crops/s",
            file=sys.stderr,
        )
    return {
        "config": {"steps": steps, "crop_px": crop_px, "batch_size": batch, "data": str(data)},
        "seed": SEED,
        "git_commit": git_commit(),
        "cpu_count": os.cpu_count(),
        "rows": rows,
    }

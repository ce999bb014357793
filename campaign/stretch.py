"""One stretch of a line: two learning rates side by side from the line's best, both scored
on the campaign's fixed held-out set, the log appended and the better written back.

Each run is :func:`semcodec.train` started from the line's best with ``init`` (a fresh
optimiser and warm-up; never a resume of another run's state) into its own folder under
``work``. On CUDA the two runs are two processes sharing the GPU (the JSCC is launch-bound,
so two cost about one); on a CPU they take turns in this process, each with every thread.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from campaign.store import Campaign, images_sha256, next_lrs, now_utc
from campaign.worker import train_one
from common import list_images, read_image, to_chw
from osnerf import git_commit
from semcodec import make_codec
from semcodec.training import validate

ROOT = Path(__file__).resolve().parent.parent


@dataclass(frozen=True)
class StretchOptions:
    """What one ``continue`` is asked for.

    Attributes:
        line: the line to continue (None: the campaign's default line).
        minutes: training minutes of each run (0 with ``steps``).
        steps: optimiser steps of each run (0: by ``minutes``).
        device: "cpu", "cuda" or "auto" (CUDA when present).
        data: training image folders.
        val: the held-out image folder (its first ``validation.count`` images).
        work: folder for the runs' checkpoints and logs (outside the campaign).
        lrs: two learning rates (None: the line's).
        jobs: 2 (two processes) or 1 (one after the other); None: 2 on CUDA, 1 on a CPU.
        overrides: TrainConfig fields that replace the line's recipe for this stretch.
    """

    line: str | None
    minutes: float
    steps: int
    device: str
    data: list[Path]
    val: Path
    work: Path
    lrs: tuple[float, float] | None = None
    jobs: int | None = None
    overrides: dict = field(default_factory=dict)


def resolve_device(device: str) -> tuple[str, str]:
    """(torch device, the machine's name for the log): ``auto`` picks CUDA when present."""
    import torch

    if device == "auto":
        device = "cuda" if torch.cuda.is_available() else "cpu"
    if device.startswith("cuda"):
        if not torch.cuda.is_available():
            raise ValueError("--device cuda: no CUDA device here")
        return device, torch.cuda.get_device_name(torch.device(device))
    return device, "cpu"


def load_validation(folder: Path, count: int, side_px: int):
    """The held-out set: the first ``count`` images of ``folder`` (sorted by name), each cut
    to the top-left square of one side (<= ``side_px``, a multiple of 4), quantised to 8 bits.

    Returns:
        [count, 3, side, side] float32 in [0, 1].
    """

    imgs = [read_image(p) for p in list_images(folder, "--val")[:count]]
    side = min(side_px, min(min(im.shape[:2]) for im in imgs)) // 4 * 4
    if side < 16:
        raise ValueError(f"--val: images of {folder} are under 16 px a side")
    arr = np.stack([np.round(im[:side, :side] * 255.0) / 255.0 for im in imgs])
    return to_chw(arr.astype(np.float32))


def score(path: Path, validation: dict, images, device: str) -> tuple[dict, float]:
    """(per channel and SNR PSNR, their mean: the campaign's score) of a JSCC checkpoint on
    the held-out ``images`` ([batch, 3, height, width] float32), noise from a fixed seed."""
    codec = make_codec(f"jscc:{path}")
    codec.module.to(device)
    metrics = validate(
        codec,
        images.to(device),
        validation["channels"],
        tuple(validation["snrs_db"]),
        validation["cbr"],
        validation["seed"],
    )
    return {k: round(v, 4) for k, v in metrics.items()}, float(np.mean(list(metrics.values())))


def _run_specs(camp: Campaign, name: str, line: dict, opts: StretchOptions, device: str):
    """The two runs' specifications (what :mod:`campaign.worker` trains)."""
    init = camp.best_path(line)
    lrs = list(opts.lrs or line["lrs"])
    stretch = int(line.get("stretches", 0))
    jobs = opts.jobs or (2 if device.startswith("cuda") else 1)
    threads = 2 if device.startswith("cuda") else max(1, (os.cpu_count() or 1) // jobs)
    budget_s = (opts.minutes or 1.0) * 60.0
    specs = []
    for i, lr in enumerate(lrs):
        cfg = {
            **line["train"],
            **opts.overrides,
            "codec": "jscc",
            "model": line["model"],
            "lr": lr,
            "seed": int(line.get("seed", 0)) + 2 * stretch + i,
            "device": device,
            "num_threads": min(threads, 64),
            "max_minutes": opts.minutes if opts.minutes else 10000.0,
            "max_steps": opts.steps,
            "eval_every_s": max(30.0, budget_s / 5),
            "save_every_s": max(30.0, budget_s / 5),
        }
        out = opts.work / f"{name}-s{stretch}-lr{lr:g}"
        specs.append(
            {
                "config": cfg,
                "data": [str(d) for d in opts.data],
                "val": str(opts.val),
                "init": str(init) if init else None,
                "out": str(out),
                "card": {"name": f"{line['model']}-campaign-{name}-s{stretch}"},
            }
        )
    return specs, jobs, init


def _train_all(specs: list[dict], jobs: int) -> list[dict]:
    """Train every spec (``jobs`` at a time as processes, or here when 1); their results."""
    if jobs == 1:
        return [train_one(s) for s in specs]
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]),
    }
    procs = []
    try:
        for s in specs:
            out = Path(s["out"])
            out.mkdir(parents=True, exist_ok=True)
            (out / "spec.json").write_text(json.dumps(s))
            err = open(out / "stderr.log", "w")  # noqa: SIM115 - closed below
            cmd = [sys.executable, "-m", "campaign.worker", str(out / "spec.json")]
            procs.append((subprocess.Popen(cmd, cwd=ROOT, env=env, stderr=err), err, out))
        results = []
        for proc, err, out in procs:
            rc = proc.wait()
            err.close()
            if rc != 0:
                lines = (out / "stderr.log").read_text().strip().splitlines() or ["no output"]
                raise RuntimeError(f"training run {out.name} failed (exit {rc}): {lines[-1][:200]}")
            results.append(json.loads((out / "result.json").read_text()))
        return results
    finally:  # an interrupt or a failed run: no run is left training on its own
        for proc, err, _ in procs:
            if proc.poll() is None:
                proc.terminate()
                proc.wait()
            err.close()


def _held_out(camp: Campaign, opts: StretchOptions):
    """(the held-out images, their set as logged); the set is the campaign's own when its
    sha256 is the one ``validation.images_sha256`` pins (pinned by the first stretch)."""
    val = camp.doc["validation"]
    images = load_validation(opts.val, int(val["count"]), int(val["side_px"]))
    sha = images_sha256(images)
    pinned = val.get("images_sha256")
    own = pinned is None or pinned == sha
    return images, {"folder": str(opts.val), "sha256": sha, "campaign_set": own}


def continue_line(camp: Campaign, opts: StretchOptions) -> dict:
    """One stretch of ``opts.line``: train two learning rates, score both, append both to the
    log, keep the better as the line's best when it beats the best so far. Returns a summary.

    Only the campaign's own held-out set decides a best: runs scored on another set are
    logged (``validation_set`` names it) and never kept. The end is a read-merge-save under
    the campaign's lock, so a stretch that ran beside another keeps both's records and
    minutes, and its winner is compared with the best as it stands then."""

    name, line = camp.line(opts.line)
    device, machine = resolve_device(opts.device)
    val = camp.doc["validation"]
    images, val_set = _held_out(camp, opts)
    specs, jobs, init = _run_specs(camp, name, line, opts, device)
    best = line.get("best")
    if val_set["campaign_set"] and best is not None and "score" not in best:
        best["validation"], best["score"] = score(init, val, images, device)  # not yet scored
    t0 = time.perf_counter()
    results = _train_all(specs, jobs)
    wall_min = (time.perf_counter() - t0) / 60.0
    for r in results:
        r["validation"], r["score"] = score(
            Path(r["out"]) / "best.safetensors", val, images, device
        )
    winner = max(results, key=lambda r: r["score"])
    with camp.locked():  # re-read: another stretch may have saved since this one began
        now = camp.doc["lines"].get(name)
        if now is None:
            raise RuntimeError(f"line {name} left campaign.json while this stretch ran")
        pinned = camp.doc["validation"].get("images_sha256")  # pinned meanwhile, maybe
        val_set["campaign_set"] = pinned is None or pinned == val_set["sha256"]
        now_best = now.get("best")
        if now_best is not None and "score" not in now_best and val_set["campaign_set"]:
            if best is not None and best.get("sha256") == now_best["sha256"]:
                now_best.update(validation=best["validation"], score=best["score"])
            else:
                now_best["validation"], now_best["score"] = score(
                    camp.best_path(now), val, images, device
                )
        incumbent = now_best["score"] if now_best else -math.inf
        kept = val_set["campaign_set"] and winner["score"] > incumbent
        records = _records(name, line, specs, results, winner, kept, machine, jobs, wall_min)
        for rec in records:
            rec["validation_set"] = val_set
            rec["incumbent_score"] = round(incumbent, 4) if now_best else None
        if kept:
            rec = records[results.index(winner)]
            ref = camp.store_best(
                name, Path(winner["out"]) / "best.safetensors", {"campaign": _provenance(rec)}
            )
            now["best"] = {**ref, "score": rec["score"], "validation": rec["validation"]}
            now["steps"] = rec["line_steps"]
            now["device_minutes"] = rec["line_device_minutes"]
            now["cpu_minutes"] = rec["line_cpu_minutes"]
        now["stretches"] = int(now.get("stretches", 0)) + 1
        if val_set["campaign_set"]:
            now["lrs"] = next_lrs([s["config"]["lr"] for s in specs], winner["lr"])
            camp.doc["validation"].setdefault("images_sha256", val_set["sha256"])
        spent = camp.doc.setdefault("spent", {"device_minutes": 0.0, "cpu_minutes": 0.0})
        for rec in records:
            spent["device_minutes"] = round(spent["device_minutes"] + rec["device_minutes"], 3)
            spent["cpu_minutes"] = round(spent["cpu_minutes"] + rec["cpu_minutes"], 3)
        camp.save(records)
    return {
        "line": name,
        "kept": kept,
        "records": records,
        "best": now.get("best"),
        "validation_set": val_set,
    }


def _provenance(rec: dict) -> dict:
    """What a stored best's card says of the run that made it."""
    keys = ("line", "stretch", "lr", "seed", "steps", "device", "commit", "score")
    return {
        **{k: rec[k] for k in keys},
        "line_device_minutes": rec["line_device_minutes"],
        "line_cpu_minutes": rec["line_cpu_minutes"],
    }


def _records(name, line, specs, results, winner, kept, machine, jobs, wall_min) -> list[dict]:
    """The log's records of a stretch's runs (minutes of this run, and of its lineage: the
    line's best it started from plus this run)."""
    best = line.get("best")
    incumbent = best["score"] if best else -math.inf
    on_gpu = specs[0]["config"]["device"].startswith("cuda")
    records = []
    for spec, r in zip(specs, results, strict=True):
        minutes = r["summary"]["minutes"]
        records.append(
            {
                "time": now_utc(),
                "commit": git_commit(),
                "line": name,
                "stretch": int(line.get("stretches", 0)),
                "lr": spec["config"]["lr"],
                "seed": spec["config"]["seed"],
                "steps": r["summary"]["steps"],
                "device": machine,
                "jobs": jobs,
                "device_minutes": round(minutes, 3) if on_gpu else 0.0,
                "cpu_minutes": 0.0 if on_gpu else round(minutes, 3),
                "wall_minutes": round(wall_min, 3),
                "line_steps": int(line.get("steps", 0)) + r["summary"]["steps"],
                "line_device_minutes": round(
                    line.get("device_minutes", 0.0) + (minutes if on_gpu else 0.0), 3
                ),
                "line_cpu_minutes": round(
                    line.get("cpu_minutes", 0.0) + (0.0 if on_gpu else minutes), 3
                ),
                "init_sha256": best["sha256"] if best else None,
                "sha256": r["sha256"],
                "validation": r["validation"],
                "score": round(r["score"], 4),
                "incumbent_score": round(incumbent, 4) if best else None,
                "won_stretch": r is winner,
                "kept": kept and r is winner,
                "config": {k: spec["config"][k] for k in sorted(spec["config"])},
            }
        )
    return records

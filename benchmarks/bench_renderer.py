"""Renderer benchmark on lego: the fields' training speed, and the renderers where novel views
are watched.

* **Fields** (100 px, 2 threads): the grid field's PSNR-vs-time curve on held-out test views
  within a budget, beside a vanilla NeRF MLP on the same budget, sampler and renderer, and
  the time each needs to reach the MLP's best PSNR (goal: grid >= 10x faster).
* **Renderers** at each size of ``OSNERF_BENCH_SIZES`` (default 100, 200, 400 px): a field
  trained at that size with ``renderer.TrainConfig.for_resolution`` (or loaded), then every
  renderer of ``renderer.RENDERERS`` on lego's path of 64 consecutive test views (2.45
  degrees apart), one thread, scored against the ground-truth views: time per view, PSNR,
  and each renderer's setup (wall and CPU seconds, the process's peak memory after it).
  Goals for the learned renderer against the full render of the same field at 200 and 400
  px (:data:`GOALS`: speed-up, dB under, setup CPU seconds, break-even views, peak memory);
  each entry records the bounds it misses. Each learned renderer is built as ``osnerf
  render`` builds it (the size's settings, distilled around the cameras the field stores),
  and records its break-even view count (``renderer.break_even_views``: setup seconds over the
  seconds it saves per view). At 100 px (and at every size, for the record) it is compared with the
  two cheap alternatives at its own time per view: the full render marched at a coarser step, and a
  half-resolution full render upsampled bicubically (each a sweep of marching steps, PSNR
  interpolated in time per view).

The machine is shared: the fields' budget clock is ``cpu`` (process CPU seconds over the
threads) unless OSNERF_BENCH_CLOCK=wall. Environment: OSNERF_BENCH_SECONDS (the 100 px
field-speed budget, default 120), OSNERF_BENCH_FIELDS (default "grid,mlp"; "" skips that
part), OSNERF_BENCH_SIZES (default "100,200,400"), OSNERF_BENCH_FIELD_SECONDS (budget of
each size's field, CPU clock, default 150 s per 100 px of width), OSNERF_BENCH_MODEL_<px> (a
field saved by `osnerf train-nerf` on lego at that size: used instead of training one),
OSNERF_FEATURES_STEPS (the feature renderer's distillation steps, as ``--renderer-steps``;
default its own budget for the size, ``renderer.FeatureConfig.for_resolution``),
OSNERF_FEATURES_REFINE (as ``--renderer-refine``: pixels rendered again by the field),
OSNERF_BENCH_THREADS (threads of the field training, default 2; the renderers are always
timed on one). Each size's results are also written on their own to ``renderer_<px>.json``
in the output folder.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import resource
import time
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

from common import write_figure
from osnerf import result_header, write_json_atomic
from osnerf.commands.args import RESOLUTION_PX_RANGE
from osnerf.commands.render import renderer_config
from osnerf.paths import shared_data_dir
from renderer import (
    RENDERERS,
    TrainConfig,
    break_even_views,
    evaluate,
    image_metrics,
    load_dataset,
    load_model,
    make_renderer,
    render_views,
    train,
)

PATH_VIEWS = 64
GOALS = {
    200: {
        "min_speedup": 5.0,
        "max_db_under": 1.0,
        "max_setup_cpu_s": 180.0,
        "max_break_even_views": 1500.0,
    },
    400: {
        "min_speedup": 8.0,
        "max_db_under": 1.0,
        "max_setup_cpu_s": 600.0,
        "max_peak_memory_mb": 4096.0,
    },
}
"""Image width (px) -> the bounds a learned renderer's results must meet there (each key's
result and direction: :data:`_GOAL_FIELDS`)."""
COARSE_STEPS = (1.25, 1.5, 2.0, 2.5, 3.0, 4.0, 6.0, 9.0, 14.0)
"""Marching-step factors of the full render at full resolution (cheap alternative 1)."""
HALF_RES_STEPS = (1.0, 1.5, 2.0, 3.0, 4.0, 6.0)
"""Marching-step factors of the half-resolution render upsampled bicubically (alternative 2)."""


def _time_to_reach(curve: list[dict], target: float, key: str = "seconds") -> float | None:
    """First time the curve reaches ``target`` PSNR (linear interpolation between points)."""
    prev = None
    for p in curve:
        if p["psnr"] >= target:
            if prev is None:
                return p[key]
            frac = (target - prev["psnr"]) / max(p["psnr"] - prev["psnr"], 1e-9)
            return prev[key] + frac * (p[key] - prev[key])
        prev = p
    return None


def _peak_memory_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _plot(curves: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5, 3.5))
    for name, curve in curves.items():
        ax.plot([p["seconds"] for p in curve], [p["psnr"] for p in curve], marker=".", label=name)
    ax.set_xlabel("training seconds")
    ax.set_ylabel("test PSNR (dB), lego")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    write_figure(path, fig, dpi=120)
    plt.close(fig)


def _field_speed(root: Path, clock: str, budget: float, out_dir: Path) -> dict:
    """Grid field against the vanilla MLP at 100 px: curves, steps, final test PSNR."""
    fields = [f for f in os.environ.get("OSNERF_BENCH_FIELDS", "grid,mlp").split(",") if f]
    if not fields:
        return {}
    torch.set_num_threads(2)
    train_set = load_dataset(root, "train", 100)
    test_set = load_dataset(root, "test", 100, aabb=train_set.aabb).subset(range(0, 200, 8))
    results: dict = {"resolution": 100, "clock": clock, "budget_seconds": budget, "threads": 2}
    curves = {}
    intervals = {"grid": budget / 20, "mlp": budget / 6}
    for name in fields:
        cfg = TrainConfig(
            field=name, max_seconds=budget, clock=clock, eval_every_seconds=intervals[name]
        )
        w0, c0 = time.perf_counter(), time.process_time()
        res = train(train_set, cfg, torch.Generator().manual_seed(0), eval_dataset=test_set)
        wall, cpu = time.perf_counter() - w0, time.process_time() - c0
        final = evaluate(res.model, test_set)
        curves[name] = res.curve
        results[name] = {
            "config": cfg.as_dict(),
            "steps": res.steps,
            "train_seconds": res.seconds,
            "wall_seconds_incl_eval": wall,
            "cpu_seconds_incl_eval": cpu,
            "test_psnr": final["psnr"],
            "render_seconds_per_view": final["seconds_per_view"],
            "curve": res.curve,
        }
    if "mlp" in curves and "grid" in curves:
        mlp_best = max(p["psnr"] for p in curves["mlp"])
        t_mlp = _time_to_reach(curves["mlp"], mlp_best)
        t_grid = _time_to_reach(curves["grid"], mlp_best)
        results["mlp_best_psnr"] = mlp_best
        results["seconds_to_mlp_best"] = {"grid": t_grid, "mlp": t_mlp}
        results["grid_speedup_to_mlp_best"] = (t_mlp / t_grid) if t_grid and t_mlp else None
    if "grid" in results:
        results["grid_goal_26db_met"] = results["grid"]["test_psnr"] >= 26.0
    out_dir.mkdir(parents=True, exist_ok=True)
    _plot(curves, out_dir / "renderer_curve.png")
    return results


def _timed(fn, poses: torch.Tensor) -> tuple[torch.Tensor, float]:
    """(rgb, seconds per view) of ``fn(poses)``, after one warm-up view."""
    fn(poses[:1])
    t0 = time.perf_counter()
    rgb = fn(poses)
    return rgb, (time.perf_counter() - t0) / poses.shape[0]


def alternatives(model, path, intr, truth) -> dict:
    """The cheap alternatives' (seconds per view, PSNR) curves along the path."""
    coarse, half = [], []
    for f in COARSE_STEPS:
        rgb, spv = _timed(
            lambda p, f=f: render_views(model, p, intr, step_m=model.step_m * f)["rgb"], path
        )
        coarse.append({"step_factor": f, "seconds_per_view": spv, "psnr": _psnr(rgb, truth)})
    lo_h, lo_w = -(-intr.height // 2), -(-intr.width // 2)
    for f in HALF_RES_STEPS:

        def half_res(p, f=f):
            low = render_views(model, p, intr, lo_h, lo_w, step_m=model.step_m * f)["rgb"]
            up = F.interpolate(
                low.permute(0, 3, 1, 2),
                size=(intr.height, intr.width),
                mode="bicubic",
                align_corners=False,
            )
            return up.permute(0, 2, 3, 1).clamp(0, 1)

        rgb, spv = _timed(half_res, path)
        half.append({"step_factor": f, "seconds_per_view": spv, "psnr": _psnr(rgb, truth)})
    return {"coarse_step": coarse, "half_res_bicubic": half}


def psnr_at(curve: list[dict], seconds: float) -> dict:
    """The alternative's PSNR at ``seconds`` per view, interpolated linearly in its
    (seconds per view, PSNR) curve. Faster than its fastest point: that point's PSNR (the
    alternative then gets more time than it is compared at: in its favour), marked
    ``"clipped"``; slower than its slowest: that point's."""
    pts = sorted((p["seconds_per_view"], p["psnr"]) for p in curve)
    xs, ys = [p[0] for p in pts], [p[1] for p in pts]
    return {
        "psnr": float(np.interp(seconds, xs, ys)),
        "clipped": not xs[0] <= seconds <= xs[-1],
    }


def _psnr(rgb: torch.Tensor, truth: torch.Tensor) -> float:
    return image_metrics(rgb, truth)["psnr"]


def _field(root: Path, px: int, train_set, clock: str) -> tuple[object, dict]:
    """The lego field at ``px``: loaded from OSNERF_BENCH_MODEL_<px>, else trained."""
    saved = os.environ.get(f"OSNERF_BENCH_MODEL_{px}")
    if saved:
        return load_model(saved), {"loaded_from": saved}
    seconds = float(os.environ.get("OSNERF_BENCH_FIELD_SECONDS", 1.5 * px))
    torch.set_num_threads(int(os.environ.get("OSNERF_BENCH_THREADS", "2")))
    cfg = TrainConfig.for_resolution(px, max_seconds=seconds, clock=clock, progress=False)
    w0 = time.perf_counter()
    res = train(train_set, cfg, torch.Generator().manual_seed(0))
    return res.model, {
        "config": cfg.as_dict(),
        "steps": res.steps,
        "train_seconds": res.seconds,
        "wall_seconds": time.perf_counter() - w0,
    }


def _cli_config(name: str, px: int):
    """The renderer's settings as ``osnerf render --renderer NAME --resolution PX`` picks
    them (``--renderer-steps`` from OSNERF_FEATURES_STEPS, ``--renderer-refine`` from
    OSNERF_FEATURES_REFINE), without the progress bar."""
    steps = os.environ.get("OSNERF_FEATURES_STEPS")
    refine = os.environ.get("OSNERF_FEATURES_REFINE")
    args = argparse.Namespace(
        renderer=name,
        renderer_steps=int(steps) if steps else None,
        renderer_cpu_seconds=None,
        renderer_refine=float(refine) if refine else None,
    )
    config = renderer_config(args, px)
    return None if config is None else dataclasses.replace(config, progress=False)


def _renderers_at(root: Path, px: int, clock: str) -> dict:
    """Every renderer on the 64-view test path at ``px``, one thread, against ground truth."""
    train_set = load_dataset(root, "train", px)
    path = load_dataset(root, "test", px, aabb=train_set.aabb).subset(range(PATH_VIEWS))
    model, field = _field(root, px, train_set, clock)
    torch.set_num_threads(1)
    out: dict = {"resolution": px, "num_views": PATH_VIEWS, "field": field, "renderers": {}}
    for name in RENDERERS:
        t0, c0 = time.perf_counter(), time.process_time()
        # as `osnerf render --renderer NAME --resolution PX --seed 0` builds it: the
        # settings of that size, distilled around the cameras the field stores
        rend, stats = make_renderer(
            name, model, None, _cli_config(name, px), torch.Generator().manual_seed(0)
        )
        setup, setup_cpu = time.perf_counter() - t0, time.process_time() - c0
        rgb, spv = _timed(lambda p, r=rend: r.render_path(p, path.intrinsics)["rgb"], path.poses)
        out["renderers"][name] = {
            "psnr": _psnr(rgb, path.images),
            "seconds_per_view": spv,
            "setup_seconds": setup,
            "setup_cpu_seconds": setup_cpu,
            "setup_stats": stats,
            "peak_memory_mb_after_setup": _peak_memory_mb(),
            "settings": rend.settings(),
        }
    full = out["renderers"]["full"]
    alts = alternatives(model, path.poses, path.intrinsics, path.images)
    out["cheap_alternatives"] = alts
    for r in out["renderers"].values():
        if r is full:
            continue
        r["speedup_vs_full"] = full["seconds_per_view"] / r["seconds_per_view"]
        r["db_under_full"] = full["psnr"] - r["psnr"]
        r["break_even_views"] = break_even_views(
            r["setup_seconds"], r["seconds_per_view"], full["seconds_per_view"]
        )
        r["alternatives_at_same_time"] = {
            k: psnr_at(curve, r["seconds_per_view"]) for k, curve in alts.items()
        }
        r["beats_alternatives_at_same_time"] = all(
            r["psnr"] > v["psnr"] for v in r["alternatives_at_same_time"].values()
        )
        if px in GOALS:
            r["goal"] = GOALS[px]
            r["goal_missed"] = goal_missed(r, GOALS[px])
            r["goal_met"] = not r["goal_missed"]
    return out


_GOAL_FIELDS = {
    "min_speedup": ("speedup_vs_full", 1),
    "max_db_under": ("db_under_full", -1),
    "max_setup_cpu_s": ("setup_cpu_seconds", -1),
    "max_break_even_views": ("break_even_views", -1),
    "max_peak_memory_mb": ("peak_memory_mb_after_setup", -1),
}
"""A goal's key -> (the renderer's result it bounds, +1 for a lower bound, -1 for an upper)."""


def goal_missed(result: dict, goal: dict) -> list[str]:
    """The keys of ``goal`` (of :data:`GOALS`) that ``result`` (a learned renderer's entry)
    misses; a break-even of None (nothing saved per view) misses its bound."""
    missed = []
    for key, bound in goal.items():
        name, sign = _GOAL_FIELDS[key]
        value = result[name]
        if value is None or sign * (value - bound) < 0:
            missed.append(key)
    return missed


def run(out_dir: Path) -> dict:
    clock = os.environ.get("OSNERF_BENCH_CLOCK", "cpu")
    budget = float(os.environ.get("OSNERF_BENCH_SECONDS", "120"))
    sizes = [int(s) for s in os.environ.get("OSNERF_BENCH_SIZES", "100,200,400").split(",") if s]
    low, high = RESOLUTION_PX_RANGE
    for px in sizes:
        if not low <= px <= high:
            raise ValueError(f"OSNERF_BENCH_SIZES must be in [{low}, {high}], got {px}")
    root = shared_data_dir() / "nerf_synthetic" / "lego"
    results: dict = {"dataset": "nerf_synthetic/lego", "loadavg_start": os.getloadavg()}
    results["fields"] = _field_speed(root, clock, budget, out_dir)
    results["sizes"] = {}
    for px in sizes:
        results["sizes"][str(px)] = _renderers_at(root, px, clock)
        # each size also on its own: a run of one size does not replace another's
        record = result_header({"benchmark": "renderer", "resolution": px}, None)
        record["results"] = results["sizes"][str(px)]
        write_json_atomic(out_dir / f"renderer_{px}.json", record)
    results["loadavg_end"] = os.getloadavg()
    return results

"""Renderer benchmark on lego at 100x100 by default (2 CPU threads).

* grid field: PSNR-vs-time curve on held-out test views within a 120 s budget;
* vanilla NeRF MLP on the same budget, sampler and renderer;
* the time each needs to reach the MLP's best PSNR (goal: grid >= 10x faster);
* the renderers of ``renderer.RENDERERS`` side by side in this one run along two camera
  paths: time per view and PSNR of the lightweight renderer against full-resolution
  volume rendering of the same field and (on lego's first 64 test views, which form a
  path) against ground truth, beside bilinear upsampling of the low-resolution render
  (goal: >= 5x faster, <= 1 dB under the full render against ground truth);
* the feature renderer (a learned feature field + decoder, :mod:`renderer.features`) on the
  same test path beside the full render (OSNERF_FEATURES_SECONDS of training, default the
  renderer's own).

The machine is shared: the budget clock is ``cpu`` (process CPU seconds / 2 threads, the
wall time the same work takes on two idle cores; optimistic for single-threaded Python
parts) unless OSNERF_BENCH_CLOCK=wall. Wall seconds and the load average are recorded
beside it. Environment: OSNERF_BENCH_SECONDS (default 120), OSNERF_LIGHTWEIGHT_SECONDS
(default 60), OSNERF_LIGHTWEIGHT_SEQUENCES (default 96), OSNERF_BENCH_THREADS (default 2;
on an oversubscribed machine 1 thread is many times faster because OpenMP threads wait on
each other), OSNERF_BENCH_FIELDS (default "grid,mlp"; "grid" skips the MLP baseline),
OSNERF_LIGHTWEIGHT_VARIANTS (JSON list of LightweightConfig overrides measured beside the
default on the test path, e.g. '[{"downsample": 2}]'; default none), OSNERF_BENCH_MODEL
(a field saved by `osnerf train-nerf` on lego: the renderers are measured on it and
no field is trained; OSNERF_BENCH_FIELDS is then ignored), OSNERF_BENCH_RESOLUTION (image
width of every view, trained and rendered, in osnerf's RESOLUTION_PX_RANGE; default 100,
the goal's).
"""

from __future__ import annotations

import dataclasses
import json
import os
import time
from pathlib import Path

import torch

from common import psnr, write_figure
from osnerf.commands.args import RESOLUTION_PX_RANGE
from osnerf.paths import shared_data_dir
from renderer import (
    FeatureConfig,
    FullRenderer,
    LightweightConfig,
    TrainConfig,
    evaluate,
    image_metrics,
    load_dataset,
    load_model,
    orbit_path,
    render_views,
    train,
    train_features,
    train_lightweight,
)


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


def _pooled_psnr(a: torch.Tensor, b: torch.Tensor) -> float:
    """PSNR of the MSE over all frames (finite when some frames are exact)."""
    return psnr(a, b)


def _lightweight_on_path(lw, path: torch.Tensor, intr, truth: torch.Tensor | None = None) -> dict:
    """Time per view and PSNRs of the lightweight renderer, the full render and bilinear
    upsampling of the low-resolution render along ``path`` [num_views, 4, 4]."""
    model, cfg = lw.model, lw.config
    full_renderer = FullRenderer(model)
    full_renderer.render_path(path[:2], intr)  # warm-up
    full_out = full_renderer.render_path(path, intr)
    full, full_spv = full_out["rgb"], full_out["seconds_per_view"]
    lw.render_path(path[:2], intr)  # warm-up
    out = lw.render_path(path, intr)
    low = render_views(
        model, path, intr, intr.height // cfg.downsample, intr.width // cfg.downsample
    )
    bilinear = (
        torch.nn.functional.interpolate(
            low["rgb"].permute(0, 3, 1, 2),
            size=(intr.height, intr.width),
            mode="bilinear",
            align_corners=False,
        )
        .permute(0, 2, 3, 1)
        .clamp(0, 1)
    )
    key = out["keyframes"]
    rest = [i for i in range(path.shape[0]) if i not in key]
    bilinear_keyed = bilinear.clone()
    bilinear_keyed[key] = full[key]  # bilinear with the same keyframes: same cost minus the decoder
    r = {
        "num_views": path.shape[0],
        "keyframes": key,
        "full_seconds_per_view": full_spv,
        "lightweight_seconds_per_view": out["seconds_per_view"],
        "speedup": full_spv / out["seconds_per_view"],
        "empty_fraction": out["empty_fraction"],
        "rerendered_fraction": out["rerendered_fraction"],
    }
    refs = {"vs_full": full} if truth is None else {"vs_full": full, "vs_truth": truth}
    for ref_name, ref in refs.items():
        r[f"psnr_{ref_name}"] = {
            "lightweight_non_keyframes": image_metrics(out["rgb"][rest], ref[rest])["psnr"],
            "bilinear_non_keyframes": image_metrics(bilinear[rest], ref[rest])["psnr"],
            "lightweight_pooled": _pooled_psnr(out["rgb"], ref),
            "bilinear_pooled": _pooled_psnr(bilinear, ref),
            "bilinear_with_same_keyframes_pooled": _pooled_psnr(bilinear_keyed, ref),
        }
        if ref_name == "vs_truth":
            r[f"psnr_{ref_name}"]["lightweight"] = image_metrics(out["rgb"], ref)["psnr"]
            r[f"psnr_{ref_name}"]["full_render"] = image_metrics(full, ref)["psnr"]
            r[f"psnr_{ref_name}"]["full_render_non_keyframes"] = image_metrics(
                full[rest], ref[rest]
            )["psnr"]
            r["lightweight_db_under_full_vs_truth"] = (
                r[f"psnr_{ref_name}"]["full_render"] - r[f"psnr_{ref_name}"]["lightweight"]
            )
    return r


def _renderer_on_path(rend, model, path: torch.Tensor, intr, truth: torch.Tensor) -> dict:
    """Time per view and PSNR of ``rend`` beside the full render of ``model`` along ``path``
    (measured back to back in this process), against the full render and ground truth."""
    full_renderer = FullRenderer(model)
    full_renderer.render_path(path[:2], intr)  # warm-up
    full_out = full_renderer.render_path(path, intr)
    rend.render_path(path[:2], intr)  # warm-up
    out = rend.render_path(path, intr)
    full_psnr = image_metrics(full_out["rgb"], truth)["psnr"]
    psnr = image_metrics(out["rgb"], truth)["psnr"]
    return {
        "num_views": path.shape[0],
        "full_seconds_per_view": full_out["seconds_per_view"],
        "seconds_per_view": out["seconds_per_view"],
        "speedup": full_out["seconds_per_view"] / out["seconds_per_view"],
        "psnr_vs_truth": {"renderer": psnr, "full_render": full_psnr},
        "psnr_vs_full": image_metrics(out["rgb"], full_out["rgb"].clamp(0, 1))["psnr"],
        "db_under_full_vs_truth": full_psnr - psnr,
        "goal_5x_within_1db_met": full_out["seconds_per_view"] / out["seconds_per_view"] >= 5
        and full_psnr - psnr <= 1.0,
    }


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


def run(out_dir: Path) -> dict:
    threads = int(os.environ.get("OSNERF_BENCH_THREADS", "2"))
    torch.set_num_threads(threads)
    clock = os.environ.get("OSNERF_BENCH_CLOCK", "cpu")
    budget = float(os.environ.get("OSNERF_BENCH_SECONDS", "120"))
    lw_seconds = float(os.environ.get("OSNERF_LIGHTWEIGHT_SECONDS", "60"))
    resolution = int(os.environ.get("OSNERF_BENCH_RESOLUTION", "100"))
    low, high = RESOLUTION_PX_RANGE
    if not low <= resolution <= high:
        raise ValueError(f"OSNERF_BENCH_RESOLUTION must be in [{low}, {high}], got {resolution}")
    root = shared_data_dir() / "nerf_synthetic" / "lego"
    train_set = load_dataset(root, "train", resolution)
    test_set = load_dataset(root, "test", resolution, aabb=train_set.aabb)
    test_set = test_set.subset(range(0, 200, 8))
    results: dict = {
        "dataset": "nerf_synthetic/lego",
        "resolution": resolution,
        "num_train_views": train_set.num_views,
        "num_test_views": test_set.num_views,
        "curve_views": 10,
        "clock": clock,
        "budget_seconds": budget,
        "loadavg_start": os.getloadavg(),
        "threads": torch.get_num_threads(),
    }
    curves = {}
    fields = os.environ.get("OSNERF_BENCH_FIELDS", "grid,mlp").split(",")
    if os.environ.get("OSNERF_BENCH_MODEL"):
        fields = []
        grid_model = load_model(os.environ["OSNERF_BENCH_MODEL"])
        results["field_loaded_from"] = os.environ["OSNERF_BENCH_MODEL"]
    intervals = {"grid": budget / 20, "mlp": budget / 6}
    for name, interval in ((f, intervals[f]) for f in fields):
        cfg = TrainConfig(field=name, max_seconds=budget, clock=clock, eval_every_seconds=interval)
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
            "test_ssim": final["ssim"],
            "render_seconds_per_view": final["seconds_per_view"],
            "occupancy_fraction": res.model.occupancy.fraction_occupied,
            "curve": res.curve,
            "loadavg_after": os.getloadavg(),
        }
        if name == "grid":
            grid_model = res.model
    if "mlp" in curves:
        mlp_best = max(p["psnr"] for p in curves["mlp"])
        t_mlp = _time_to_reach(curves["mlp"], mlp_best)
        t_grid = _time_to_reach(curves["grid"], mlp_best)
        results["mlp_best_psnr"] = mlp_best
        results["seconds_to_mlp_best"] = {"grid": t_grid, "mlp": t_mlp}
        results["grid_speedup_to_mlp_best"] = (t_mlp / t_grid) if t_grid and t_mlp else None
    if "grid" in results:
        results["grid_goal_26db_met"] = results["grid"]["test_psnr"] >= 26.0
    out_dir.mkdir(parents=True, exist_ok=True)
    if curves:
        _plot(curves, out_dir / "renderer_curve.png")

    # lightweight renderer along an orbit of 3-degree steps and along the test views
    lw_cfg = LightweightConfig(
        train_seconds=lw_seconds,
        num_sequences=int(os.environ.get("OSNERF_LIGHTWEIGHT_SEQUENCES", "96")),
    )
    lw, stats = train_lightweight(grid_model, train_set, lw_cfg, torch.Generator().manual_seed(0))
    radius = (train_set.poses[:, :3, 3] - train_set.aabb.mean(0)).norm(dim=-1).mean().item()
    orbit = orbit_path(
        30, radius, 30.0, train_set.aabb.mean(0), start_azimuth_deg=20.0, arc_deg=90.0
    )
    test_path = load_dataset(root, "test", resolution, aabb=train_set.aabb).subset(range(64))
    results["lightweight"] = {
        "config": lw_cfg.as_dict(),
        "train_stats": stats,
        "orbit": _lightweight_on_path(lw, orbit, train_set.intrinsics),
        "test_path": _lightweight_on_path(
            lw, test_path.poses, test_path.intrinsics, test_path.images
        ),
        "note": "orbit: 30 views 3 deg apart at 30 deg elevation, no ground truth; test_path: "
        "lego test views 0-63 (2.45 deg apart) with ground truth. 'vs_full': against the "
        "same field's full-resolution volume rendering. Keyframes are full renders (their "
        "time is in the lightweight time per view); *_non_keyframes excludes them, "
        "*_pooled is the PSNR of the MSE over all frames; vs_truth.lightweight and "
        "full_render are means of per-view PSNR over all 64 views.",
    }
    variants = []
    for overrides in json.loads(os.environ.get("OSNERF_LIGHTWEIGHT_VARIANTS", "[]")):
        cfg = dataclasses.replace(lw_cfg, **overrides)
        v, v_stats = train_lightweight(grid_model, train_set, cfg, torch.Generator().manual_seed(0))
        variants.append(
            {
                "overrides": overrides,
                "train_stats": v_stats,
                "test_path": _lightweight_on_path(
                    v, test_path.poses, test_path.intrinsics, test_path.images
                ),
            }
        )
    results["lightweight"]["variants"] = variants

    # the feature renderer (a learned feature field + decoder) on the same test path
    feat_seconds = os.environ.get("OSNERF_FEATURES_SECONDS")
    feat_cfg = FeatureConfig(progress=False)
    if feat_seconds:
        feat_cfg = dataclasses.replace(feat_cfg, train_seconds=float(feat_seconds))
    feat, feat_stats = train_features(
        grid_model, train_set, feat_cfg, torch.Generator().manual_seed(0)
    )
    results["features"] = {
        "config": feat_cfg.as_dict(),
        "train_stats": feat_stats,
        "test_path": _renderer_on_path(
            feat, grid_model, test_path.poses, test_path.intrinsics, test_path.images
        ),
    }
    results["loadavg_end"] = os.getloadavg()
    return results

"""The renderer benchmark's own arithmetic: the goals it checks, the cheap alternatives it
compares the learned renderer with, and their PSNR at a given time per view."""

import pytest
import torch
import torch.nn.functional as F

from benchmarks.bench_renderer import GOALS, alternatives, goal_missed, psnr_at
from renderer import image_metrics, render_views


def _entry(**changes) -> dict:
    entry = {
        "speedup_vs_full": 5.2,
        "db_under_full": 0.9,
        "setup_cpu_seconds": 170.0,
        "break_even_views": 1400,
        "peak_memory_mb_after_setup": 2500.0,
    }
    return {**entry, **changes}


def test_goals_name_each_bound_a_renderer_misses():
    assert goal_missed(_entry(), GOALS[200]) == []
    assert goal_missed(_entry(), GOALS[400]) == ["min_speedup"]
    assert goal_missed(_entry(db_under_full=1.63, break_even_views=2341), GOALS[200]) == [
        "max_db_under",
        "max_break_even_views",
    ]
    # nothing saved per view: it never breaks even
    assert goal_missed(_entry(break_even_views=None), GOALS[200]) == ["max_break_even_views"]
    assert goal_missed(_entry(speedup_vs_full=11.5, setup_cpu_seconds=601), GOALS[400]) == [
        "max_setup_cpu_s"
    ]
    assert goal_missed(
        _entry(speedup_vs_full=11.5, peak_memory_mb_after_setup=4100.0), GOALS[400]
    ) == ["max_peak_memory_mb"]
    # the bounds themselves are met
    assert goal_missed(_entry(speedup_vs_full=5.0, db_under_full=1.0), GOALS[200]) == []


def test_psnr_at_interpolates_in_time_and_clips_outside_the_curve():
    curve = [
        {"seconds_per_view": 0.04, "psnr": 30.0},
        {"seconds_per_view": 0.01, "psnr": 20.0},
        {"seconds_per_view": 0.02, "psnr": 26.0},
    ]
    assert psnr_at(curve, 0.03) == {"psnr": pytest.approx(28.0), "clipped": False}
    assert psnr_at(curve, 0.015) == {"psnr": pytest.approx(23.0), "clipped": False}
    # faster than its fastest point: that point's PSNR, marked
    assert psnr_at(curve, 0.005) == {"psnr": pytest.approx(20.0), "clipped": True}
    assert psnr_at(curve, 0.1) == {"psnr": pytest.approx(30.0), "clipped": True}


def test_the_cheap_alternatives_are_the_full_render_coarser_or_upsampled(sphere_model):
    model, views = sphere_model
    views = views.subset(range(2))
    intr, truth = views.intrinsics, views.images
    curves = alternatives(model, views.poses, intr, truth)
    assert set(curves) == {"coarse_step", "half_res_bicubic"}
    for curve in curves.values():
        assert all(p["seconds_per_view"] > 0 for p in curve)
    # each point is the full render at that step, scored against the truth
    with torch.no_grad():
        f = curves["coarse_step"][0]["step_factor"]
        coarse = render_views(model, views.poses, intr, step_m=model.step_m * f)["rgb"]
        h, w = -(-intr.height // 2), -(-intr.width // 2)
        low = render_views(model, views.poses, intr, h, w)["rgb"]
    up = F.interpolate(
        low.permute(0, 3, 1, 2), (intr.height, intr.width), mode="bicubic", align_corners=False
    ).permute(0, 2, 3, 1)
    first_half = curves["half_res_bicubic"][0]
    assert first_half["step_factor"] == 1.0
    assert first_half["psnr"] == pytest.approx(image_metrics(up.clamp(0, 1), truth)["psnr"])
    assert curves["coarse_step"][0]["psnr"] == pytest.approx(image_metrics(coarse, truth)["psnr"])
    # upsampling loses detail: the half-resolution render is under the full one
    full = render_views(model, views.poses, intr)["rgb"]
    assert first_half["psnr"] < image_metrics(full, truth)["psnr"]
    # the coarsest step (14 of the field's) jumps across the sphere's edge: far under the finest
    assert curves["coarse_step"][-1]["psnr"] < curves["coarse_step"][0]["psnr"] - 10

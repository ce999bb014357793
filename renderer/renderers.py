"""The renderers a trained field is viewed with: one table, one interface, one scorer.

``RENDERERS[name](model, dataset=None, config=None, generator=None) -> (renderer, stats)``
builds a renderer (a learned one is distilled first; ``dataset`` gives the
training cameras, None the cameras the field stores). Every renderer has
``render_path(poses [num_views, 4, 4], intrinsics) -> {"rgb": [num_views, height, width,
3] float32, "seconds_per_view": float, ...}`` and ``settings() -> dict``.
:func:`score_renderers` renders held-out views with each and compares them with the images.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import torch
from torch import Tensor

from common import Registry
from renderer.bake import break_even_views
from renderer.cameras import Intrinsics
from renderer.dataset import Dataset
from renderer.feature_config import FeatureConfig
from renderer.features import train_features
from renderer.metrics import image_metrics
from renderer.model import RadianceField, render_views


class FullRenderer:
    """Volume rendering of every pixel at the field's own marching step (eq. 4), a grid
    field's colour read only where it counts (:func:`~renderer.model.render_views`)."""

    name = "full"

    def __init__(self, model: RadianceField):
        self.model = model

    def settings(self) -> dict:
        return {"renderer": self.name, "step_m": self.model.step_m}

    @torch.no_grad()
    def render_path(self, poses: Tensor, intrinsics: Intrinsics) -> dict:
        """{"rgb": [num_views, height, width, 3] float32, "seconds_per_view": float}."""
        t0 = time.perf_counter()
        rgb = render_views(self.model, poses, intrinsics)["rgb"]
        seconds = (time.perf_counter() - t0) / max(poses.shape[0], 1)
        return {"rgb": rgb, "seconds_per_view": seconds}


def _full(model, dataset=None, config=None, generator=None):
    if config is not None:
        raise ValueError("the full renderer takes no config")
    return FullRenderer(model), {}


def _features(model, dataset=None, config=None, generator=None):
    config = FeatureConfig(progress=False) if config is None else config
    return train_features(model, dataset, config, generator)


RENDERERS = Registry[Callable](
    "renderer",
    {
        "full": _full,
        "features": _features,
    },
)
"""name -> builder ``(model, dataset=None, config=None, generator=None) -> (renderer,
stats)``: the one table of renderers (the CLI's ``--renderer`` choices). ``full``: volume
rendering of every pixel; ``features``: a learned feature field rendered at low resolution
and decoded (:mod:`renderer.features`, the paper's eq. 5 lightweight renderer)."""


def make_renderer(
    name: str,
    model: RadianceField,
    dataset: Dataset | None = None,
    config=None,
    generator: torch.Generator | None = None,
):
    """Build the renderer ``name`` of :data:`RENDERERS`: ``(renderer, stats)``.

    Raises:
        KeyError: unknown name (the message lists the known ones).
    """
    if name not in RENDERERS:
        raise KeyError(f"unknown renderer {name!r}; known: {list(RENDERERS)}")
    return RENDERERS[name](model, dataset, config, generator)


def score_renderers(
    model: RadianceField,
    test_dataset: Dataset,
    train_dataset: Dataset | None = None,
    names: list[str] | None = None,
    configs: dict | None = None,
    generator: torch.Generator | None = None,
    timing_repeats: int = 3,
) -> dict:
    """Render ``test_dataset``'s views in their order with each renderer and compare with
    its images.

    Args:
        train_dataset: the cameras a learned renderer is distilled around (None: the
            cameras the field stores).
        names: renderers to score (default: all of :data:`RENDERERS`).
        configs: name -> config (e.g. ``{"features": FeatureConfig(...)}``).
        timing_repeats: timed passes over the views after the first (which warms up and
            gives the images), >= 1; the fastest counts, as ``timeit`` does: a short path of
            small views takes tens of milliseconds, and one pass is at the mercy of a page
            fault or another process.
    Returns:
        {name: {"psnr", "ssim" (means of per-view values against the images),
        "seconds_per_view" (the fastest of ``timing_repeats`` passes), "setup_seconds"
        and "setup_cpu_seconds" (building it: the decoder's training; wall and this
        process's CPU), "setup_stats" (the builder's), "num_views", "settings"[, "masked_psnr"]
        [, "speedup_vs_full", "break_even_views" (:func:`~renderer.bake.break_even_views`)]}}.
    """
    if timing_repeats < 1:
        raise ValueError(f"timing_repeats must be >= 1, got {timing_repeats}")
    if generator is None:
        generator = torch.Generator().manual_seed(0)
    results: dict = {}
    for name in names or list(RENDERERS):
        t0, c0 = time.perf_counter(), time.process_time()
        r, stats = make_renderer(name, model, train_dataset, (configs or {}).get(name), generator)
        setup, setup_cpu = time.perf_counter() - t0, time.process_time() - c0
        out = r.render_path(test_dataset.poses, test_dataset.intrinsics)
        seconds = min(
            r.render_path(test_dataset.poses, test_dataset.intrinsics)["seconds_per_view"]
            for _ in range(timing_repeats)
        )
        m = image_metrics(out["rgb"], test_dataset.images, test_dataset.masks)
        results[name] = {
            "psnr": m["psnr"],
            "ssim": m["ssim"],
            "seconds_per_view": seconds,
            "setup_seconds": setup,
            "setup_cpu_seconds": setup_cpu,
            "setup_stats": stats,
            "num_views": m["num_views"],
            "settings": r.settings(),
        }
        if "masked_psnr" in m:
            results[name]["masked_psnr"] = m["masked_psnr"]
    if "full" in results:
        for name, r in results.items():
            if name != "full":
                full = results["full"]["seconds_per_view"]
                r["speedup_vs_full"] = full / r["seconds_per_view"]
                r["break_even_views"] = break_even_views(
                    r["setup_seconds"], r["seconds_per_view"], full
                )
    return results

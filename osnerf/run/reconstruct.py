"""Reconstruction and scoring: a radiance field per scheme, trained on its received views in
memory, scored on held-out views against the ground-truth renders."""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import torch

import renderer
from common import ms_ssim
from osnerf.scheme_types import NerfBudget


@dataclass
class Reconstruction:
    """A scheme's field, scored.

    Attributes:
        metrics: psnr, ssim, lpips (whole view; object-routed schemes against the demanded
            objects on the background), psnr_object, mask_iou, nerf_steps, nerf_curve,
            nerf_seconds, nerf_wall_seconds, num_test_views, num_test_views_with_object.
        rgb: [num_test, height, width, 3] float32 renders; opacity: [num_test, height, width].
    """

    metrics: dict
    rgb: np.ndarray
    opacity: np.ndarray

    def to_cache(self) -> tuple[dict, dict]:
        """(arrays, JSON info) for ``StageCache.save``."""
        return {"rgb": self.rgb, "opacity": self.opacity}, self.metrics

    @classmethod
    def from_cache(cls, arrays: dict, info: dict) -> Reconstruction:
        """The inverse of :meth:`to_cache`."""
        return cls(info, arrays["rgb"], arrays["opacity"])


def received_dataset(images: torch.Tensor, poses, intrinsics, background, aabb, masks=None):
    """The views a scheme received as a ``renderer.Dataset`` (no disk round trip).

    Args:
        images: [num_views, 3, height, width] float32 in [0, 1]; poses: [num_views, 4, 4].
        masks: [num_views, height, width] what the receiver knows was sent, or None.
    """
    return renderer.Dataset(
        images=images.detach().clamp(0, 1).permute(0, 2, 3, 1).contiguous().float(),
        poses=torch.as_tensor(np.asarray(poses), dtype=torch.float32),
        intrinsics=intrinsics,
        background=(float(background[0]), float(background[1]), float(background[2])),
        aabb=torch.as_tensor(np.asarray(aabb), dtype=torch.float32),
        masks=None if masks is None else torch.as_tensor(np.asarray(masks), dtype=torch.float32),
    )


def mask_iou(opacity: np.ndarray, mask: np.ndarray, threshold: float = 0.5) -> float:
    """Intersection over union of ``opacity > t`` and ``mask > t`` (1.0 when both are empty)."""
    a, b = opacity > threshold, mask > threshold
    union = np.logical_or(a, b).sum()
    return float(np.logical_and(a, b).sum() / union) if union else 1.0


def lpips_mean(pred: np.ndarray, ref: np.ndarray) -> float | None:
    """Mean LPIPS (AlexNet) over views [n, h, w, 3], None where the weights are not set up."""
    try:
        return float(np.mean(np.asarray(renderer.lpips(pred, ref), np.float64)))
    except (FileNotFoundError, ValueError):  # weights not set up, or views under 31 px
        return None


def reconstruct(
    ds, views, union: np.ndarray, budget: NerfBudget, seed: int, object_routed: bool
) -> Reconstruction:
    """Train the renderer on ``ds`` and score it on the held-out views of ``views``.

    Args:
        union: [num_test, height, width] union mask of the demanded objects on the test views.
    """
    test = views.indices("test")
    gt = views.images[test]
    ref = gt
    if object_routed:
        bg = np.asarray(views.background, np.float32)
        ref = gt * union[..., None] + bg * (1.0 - union[..., None])
    seen = [k for k in range(len(test)) if (union[k] > 0.5).sum() >= 4]
    held_out = _held_out_dataset(ds, views, test, union, seen)
    if ds.num_views == 0:  # nothing arrived: an empty field, the background everywhere
        rgb = np.broadcast_to(np.asarray(views.background, np.float32), gt.shape).copy()
        op = np.zeros(gt.shape[:3], np.float32)
        training = {"nerf_steps": 0, "nerf_curve": [], "nerf_seconds": 0.0}
        training |= {"nerf_wall_seconds": 0.0, "renderers": None}
    else:
        rgb, op, training = _train_and_render(ds, views, held_out, budget, seed, object_routed)
    metrics = _scores(rgb, op, gt, ref, union, seen, object_routed) | training
    return Reconstruction(metrics, rgb, op)


def _held_out_dataset(ds, views, test, union: np.ndarray, seen: list[int]) -> renderer.Dataset:
    """The held-out views as a ``renderer.Dataset`` in ``ds``'s frame, with the objects'
    masks of the views in ``seen`` (the training curve's object PSNR)."""
    curve_masks = np.zeros_like(union)
    curve_masks[seen] = union[seen] > 0.5
    return renderer.Dataset(
        images=torch.from_numpy(np.ascontiguousarray(views.images[test], np.float32)),
        poses=torch.as_tensor(views.poses[test], dtype=torch.float32),
        intrinsics=ds.intrinsics,
        background=ds.background,
        aabb=ds.aabb,
        masks=torch.from_numpy(curve_masks.astype(np.float32)),
    )


def _train_config(budget: NerfBudget, num_test: int) -> renderer.TrainConfig:
    """The radiance field's training settings of the run's ``budget``."""
    return renderer.TrainConfig(
        max_seconds=float(budget.max_seconds),
        max_steps=budget.steps,
        clock=budget.clock,
        progress=False,
        eval_every_seconds=max(float(budget.max_seconds) / 12, 0.5),
        eval_every_steps=max(budget.steps // 12, 1) if budget.steps else None,
        eval_views=num_test,
    )


def _train_and_render(ds, views, held_out, budget: NerfBudget, seed: int, object_routed: bool):
    """Train the field on ``ds`` and render the held-out views. Returns (rgb [n, h, w, 3],
    opacity [n, h, w], the training's metrics: steps, curve, seconds, renderers)."""
    torch.set_num_threads(min(2, torch.get_num_threads()))
    t = time.perf_counter()
    result = renderer.train(
        ds,
        _train_config(budget, held_out.num_views),
        generator=torch.Generator().manual_seed(seed),
        eval_dataset=held_out,
    )
    wall = time.perf_counter() - t
    with torch.no_grad():
        out = renderer.render_views(
            result.model,
            held_out.poses,
            ds.intrinsics,
            views.intrinsics.height,
            views.intrinsics.width,
        )
    renderers = None
    if budget.renderer_steps > 0:
        renderers = score_renderers(result.model, held_out, ds, budget, seed, object_routed)
    rgb = np.asarray(out["rgb"].detach().cpu(), np.float32)
    op = np.asarray(out["opacity"].detach().cpu(), np.float32).reshape(rgb.shape[:3])
    training = {
        "nerf_steps": int(result.steps),
        "nerf_curve": [
            {"seconds": c["seconds"], "step": c["step"], "psnr_object": c.get("masked_psnr")}
            for c in result.curve
        ],
        "nerf_seconds": float(result.seconds),
        "nerf_wall_seconds": wall,
        "renderers": renderers,
    }
    return rgb, op, training


def chw(image: np.ndarray) -> np.ndarray:
    """[height, width, 3] -> [3, height, width] (the renderer's views, for common's metrics)."""
    return np.ascontiguousarray(np.asarray(image).transpose(2, 0, 1))


def _mean_or_none(values: list) -> float | None:
    """The mean, or None when a value is missing (views too small for MS-SSIM)."""
    return None if not values or any(v is None for v in values) else float(np.mean(values))


def _scores(rgb, op, gt, ref, union, seen: list[int], object_routed: bool) -> dict:
    """Scores of the renders ``rgb`` (opacity ``op``) of the held-out views: whole view
    against ``ref``, over the objects against ``gt`` on the views in ``seen``."""
    n = len(gt)
    return {
        "psnr": float(np.mean([renderer.psnr(rgb[k], ref[k]) for k in range(n)])),
        "ssim": float(np.mean([renderer.ssim(rgb[k], ref[k]) for k in range(n)])),
        "ms_ssim": _mean_or_none([ms_ssim(chw(rgb[k]), chw(ref[k])) for k in range(n)]),
        "lpips": lpips_mean(rgb, ref),
        "psnr_object": float(
            np.mean([renderer.masked_psnr(rgb[k], gt[k], union[k] > 0.5) for k in seen])
        )
        if seen
        else None,
        "mask_iou": float(np.mean([mask_iou(op[k], union[k]) for k in seen]))
        if seen and object_routed
        else None,
        "num_test_views": int(n),
        "num_test_views_with_object": len(seen),
    }


def score_renderers(
    model, held_out, ds, budget: NerfBudget, seed: int, object_routed: bool
) -> dict:
    """The full render and the learned renderer (``features``, distilled for
    ``budget.renderer_steps`` steps from renders of the received views' cameras and
    jittered copies) on the held-out views, in their order: psnr_object exactly as the
    scheme's (against the ground-truth views over the objects' pixels of the views showing
    them), and for whole-scene schemes psnr and ssim of the whole view. One thread: times
    per view and setup CPU seconds are single-threaded."""
    configs = {"features": learned_renderer_config(budget.renderer_steps)}
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # small operations: a second thread costs CPU, saves little time
    try:
        out = renderer.score_renderers(
            model,
            held_out,
            ds,
            names=["full", "features"],
            configs=configs,
            generator=torch.Generator().manual_seed(seed),
        )
    finally:
        torch.set_num_threads(threads)
    for r in out.values():
        po = r.pop("masked_psnr", None)
        r["psnr_object"] = None if po is None or not np.isfinite(po) else float(po)
        if object_routed:  # the background was never sent: whole-view scores mean nothing
            r.pop("psnr")
            r.pop("ssim")
    return out


def learned_renderer_config(steps: int) -> renderer.FeatureConfig:
    """The feature renderer as the pipeline builds it: ``steps`` optimiser steps of one
    view each (the seconds cap only guards against a pathological machine), 40 jittered
    teachers beside the received views' cameras, and a feature grid at half the field's
    vertices per axis: the pipeline's views have fewer pixels than its fields have cells,
    and the coarser grid costs an eighth per step (docs/design-notes.md)."""
    return renderer.FeatureConfig(
        train_steps=steps,
        train_seconds=3600.0,
        extra_views=40,
        batch_size=1,
        grid_scale=0.5,
        progress=False,
    )


def view_metrics(received: np.ndarray, sent: np.ndarray, masks: np.ndarray | None) -> dict:
    """PSNR of the received views against what was sent (mean of per-view PSNR), whole and
    over the demanded objects; None for a scheme that sent nothing over a channel."""
    if np.array_equal(received, sent):
        return {"psnr_received": None, "psnr_received_object": None}
    out = {
        "psnr_received": float(np.mean([renderer.psnr(r, s) for r, s in zip(received, sent)])),
        "psnr_received_object": None,
    }
    if masks is not None:
        obj = [
            renderer.masked_psnr(received[k], sent[k], masks[k] > 0.5)
            for k in range(len(sent))
            if (masks[k] > 0.5).sum() > 0
        ]
        out["psnr_received_object"] = float(np.mean(obj)) if obj else None
    return out

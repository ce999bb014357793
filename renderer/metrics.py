"""Image quality of rendered views: PSNR (peak 1.0, :func:`common.psnr`), SSIM (scikit-image,
data_range=1.0), PSNR inside an object mask, and (on request) LPIPS-AlexNet
(:mod:`renderer.perceptual`, weights converted at setup); MS-SSIM is :func:`common.ms_ssim`.
Multi-view results are means of per-view values.
"""

from __future__ import annotations

import math

import numpy as np
from skimage.metrics import structural_similarity
from torch import Tensor

from common import psnr  # the project's one PSNR, re-exported as renderer.psnr
from renderer.perceptual import lpips


def _np(x) -> np.ndarray:
    return x.detach().cpu().numpy() if isinstance(x, Tensor) else np.asarray(x)


def ssim(pred, target) -> float:
    """SSIM of one image pair [height, width, 3] in [0, 1] (scikit-image, data_range=1.0,
    7x7 window, mean over channels)."""
    p, t = _np(pred).astype(np.float64), _np(target).astype(np.float64)
    return float(structural_similarity(p, t, data_range=1.0, channel_axis=-1))


def masked_psnr(pred, target, mask) -> float:
    """PSNR (:func:`common.psnr`) over the pixels where mask > 0.5: pred, target
    [height, width, 3], mask [height, width]. NaN when the mask is empty."""
    return psnr(pred, target, _np(mask)[..., None])


def image_metrics(preds, targets, masks=None, with_lpips: bool = False) -> dict:
    """Mean over views of per-view PSNR and SSIM (and masked PSNR when masks are given).

    Args:
        preds, targets: [num_views, height, width, 3] in [0, 1].
        masks: [num_views, height, width] or None.
        with_lpips: also LPIPS-AlexNet (:func:`renderer.lpips`; needs the converted weights
            and views of at least 31x31 px).
    Returns:
        {"psnr", "ssim", "num_views", "psnr_per_view", ["masked_psnr"], ["lpips",
        "lpips_per_view"]}: means of per-view values.
    """
    preds, targets = _np(preds), _np(targets)
    if preds.shape != targets.shape:
        raise ValueError(f"preds {preds.shape} and targets {targets.shape} differ in shape")
    per_view = [psnr(p, t) for p, t in zip(preds, targets)]
    out = {
        "psnr": float(np.mean(per_view)),
        "ssim": float(np.mean([ssim(p, t) for p, t in zip(preds, targets)])),
        "num_views": int(preds.shape[0]),
        "psnr_per_view": per_view,
    }
    if masks is not None:
        vals = [masked_psnr(p, t, m) for p, t, m in zip(preds, targets, _np(masks))]
        vals = [v for v in vals if not math.isnan(v)]
        out["masked_psnr"] = float(np.mean(vals)) if vals else math.nan
    if with_lpips:
        per_view_lpips = [float(v) for v in lpips(preds, targets)]
        out["lpips"] = float(np.mean(per_view_lpips))
        out["lpips_per_view"] = per_view_lpips
    return out


def to_uint8(image) -> np.ndarray:
    """[height, width, 3] float in [0, 1] -> uint8 RGB."""
    return (np.clip(_np(image), 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)

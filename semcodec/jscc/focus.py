"""On-demand object focus (paper section 3.2): which feature positions serve the demand.

The demand is K objects with masks ``mask_j`` and weights ``lambda_j``; the demand score
is the weighted masked reconstruction quality

    S(f) = - sum_pixels W * (decode(f) - x)^2 / sum_pixels W,   W = sum_j lambda_j mask_j,

and the importance of feature position p is its Grad-CAM-style attribution
``sum_c f_pc * dS/df_pc``, averaged along the path ``alpha * f`` (alpha in (0, 1], i.e.
integrated gradients, so the attributions add up to S(f) - S(0)). Positions are ranked by
it; the transmitter sends the smallest box of the positions with at least half the peak
attribution (the core of the object and the rim its reconstruction depends on most: the
attribution's long tail spreads over much of the view) and of every position
showing a demanded object (a peaky attribution must not cut the object off: version-2
models concentrate theirs on a part of it), at the rate the budget allows, or, when the
budget is below one channel over that box, the part of the box of the box's shape that holds
the most attribution and takes one channel on every position (:func:`densest_box`).
"""

from __future__ import annotations

import numpy as np
import torch
from torch import Tensor
from torch.nn import functional as F

from semcodec.jscc.model import JSCCModel, awgn_reliability, side_info

PATH_STEPS = (0.25, 0.5, 0.75, 1.0)


def _demand(mask, demand_weights, batch: int, height: int, width: int) -> tuple[Tensor, Tensor]:
    """The checked demand: (masks [batch, K, height, width] float32, weights [batch, K])."""
    m = torch.as_tensor(
        np.asarray(mask) if not isinstance(mask, Tensor) else mask, dtype=torch.float32
    )
    if m.dim() == 3:
        m = m[:, None]
    if m.dim() != 4 or m.shape[0] != batch or tuple(m.shape[2:]) != (height, width):
        raise ValueError(
            f"mask must be [batch={batch}, K, {height}, {width}], got shape {tuple(m.shape)}"
        )
    if not torch.isfinite(m).all() or m.min() < 0 or m.max() > 1:
        raise ValueError("mask values must be in [0, 1]")
    k = m.shape[1]
    if demand_weights is None:
        return m, torch.ones(batch, k)
    lam = torch.as_tensor(np.asarray(demand_weights, dtype=np.float32)).reshape(-1)
    if lam.numel() == k:
        lam = lam.reshape(1, k).expand(batch, k)
    elif lam.numel() == batch * k:
        lam = lam.reshape(batch, k)
    else:
        raise ValueError(
            f"demand_weights must have K={k} or batch*K={batch * k} values, got {lam.numel()}"
        )
    if not torch.isfinite(lam).all() or (lam < 0).any() or (lam.sum(dim=1) <= 0).any():
        raise ValueError("demand_weights must be >= 0 with a positive sum per image")
    return m, lam


def demand_weight_map(mask, demand_weights, batch: int, height: int, width: int) -> Tensor:
    """W = sum_j lambda_j mask_j / sum_j lambda_j: [batch, 1, height, width] float32 in [0, 1].

    Args:
        mask: [batch, K, height, width], [batch, height, width] or [batch, 1, height, width],
            values in [0, 1] (tensor or numpy).
        demand_weights: None (equal), K weights, or [batch, K] (or [batch] when K = 1).
    """
    m, lam = _demand(mask, demand_weights, batch, height, width)
    w = (m * lam[:, :, None, None]).sum(dim=1, keepdim=True) / lam.sum(dim=1).reshape(
        batch, 1, 1, 1
    )
    empty = w.flatten(1).sum(dim=1) <= 0
    if empty.any():  # object not visible: fall back to the whole image
        w[empty] = 1.0
    return w


def demand_positions(
    mask, demand_weights, size: tuple[int, int], padded: tuple[int, int]
) -> Tensor:
    """[batch, padded H / 4, padded W / 4] bool: the feature positions whose 4 x 4 block
    holds a pixel of a demanded object (mask >= 0.5 of an object with a positive weight).

    Args:
        mask, demand_weights: as :func:`demand_weight_map`.
        size: (height, width) of the images; padded: their padded size, multiples of 4.
    """
    m, lam = _demand(mask, demand_weights, len(mask), *size)
    obj = ((m >= 0.5) & (lam > 0)[:, :, None, None]).any(dim=1, keepdim=True).float()
    obj = F.pad(obj, (0, padded[1] - size[1], 0, padded[0] - size[0]))
    return F.max_pool2d(obj, 4)[:, 0] > 0


def demand_heatmap(
    model: JSCCModel,
    xp: Tensor,
    feat: Tensor,
    snr_db: Tensor,
    mask,
    demand_weights,
    size: tuple[int, int],
) -> Tensor:
    """Importance of each feature position for the demand.

    Args:
        xp: [batch, 3, H4, W4] padded images; feat: [batch, 2*C, H4/4, W4/4] encoder output.
        snr_db: [batch]; size: (height, width) of the unpadded images.
    Returns:
        [batch, H4/4, W4/4] float32, larger = serves the demand more.
    """
    b, c2 = feat.shape[:2]
    h, w = size
    wmap = demand_weight_map(mask, demand_weights, b, h, w)
    wmap = F.pad(wmap, (0, xp.shape[3] - w, 0, xp.shape[2] - h))
    side = side_info(snr_db, c2 // 2, c2 // 2, b)
    base = feat.detach()
    grad_sum = torch.zeros_like(base)
    with torch.enable_grad():
        for alpha in PATH_STEPS:
            f = (alpha * base).requires_grad_(True)
            rel = awgn_reliability(snr_db, (b, c2 // 2, *f.shape[2:]))
            y = model.decoder(f, side, rel)
            score = -((wmap * (y - xp) ** 2).flatten(1).sum(1) / wmap.flatten(1).sum(1)).sum()
            (g,) = torch.autograd.grad(score, f)
            grad_sum += g
    heat = (base * grad_sum / len(PATH_STEPS)).sum(dim=1).clamp_min(0)  # [batch, hf, wf]
    # tie-break toward the object where attributions vanish
    pooled = F.avg_pool2d(wmap, 4)[:, 0]
    return (
        heat
        + 1e-6 * pooled * heat.flatten(1).amax(1).clamp_min(1e-12)[:, None, None]
        + 1e-12 * pooled
    )


FOCUS_REL_THRESHOLD = 0.5
"""Positions with at least this fraction of the peak attribution form the focus box."""


def attribution_box(
    heat: Tensor, rel_threshold: float = FOCUS_REL_THRESHOLD, include: Tensor | None = None
) -> tuple[int, int, int, int]:
    """Smallest axis-aligned box (union over the batch) of the positions whose attribution
    is at least ``rel_threshold`` times the largest one, and of the positions ``include``
    marks (the demanded objects themselves: a peaky attribution must not cut them off).

    The AF modules' global pooling spreads a thin tail of attribution over every position;
    a threshold relative to the peak cuts that tail and keeps the object and the rim its
    reconstruction depends on most; a low threshold lets the tail stretch the box over most
    of a small view, spending the symbols on background (docs/design-notes.md, "End to end").

    Args:
        heat: [batch, hf, wf] float32 >= 0.
        include: optional [batch, hf, wf] bool.
    Returns:
        (top, left, rows, cols) in feature-grid units.
    """
    total = heat.sum(dim=0)  # [hf, wf]
    peak = float(total.max())
    keep = total >= rel_threshold * peak if peak > 0 else torch.ones_like(total, dtype=torch.bool)
    if include is not None:
        keep = keep | include.any(dim=0)
    rows = torch.nonzero(keep.any(dim=1)).flatten()
    cols = torch.nonzero(keep.any(dim=0)).flatten()
    top, left = int(rows[0]), int(cols[0])
    return top, left, int(rows[-1]) - top + 1, int(cols[-1]) - left + 1


def densest_box(
    heat: Tensor, box: tuple[int, int, int, int], max_positions: int
) -> tuple[int, int, int, int]:
    """The part of ``box`` with at most ``max_positions`` feature positions, about the box's
    aspect ratio, that holds the most attribution (summed over the batch; the first such
    window, row-major): where a budget below one channel over the whole box goes. ``box``
    itself when it is small enough.

    Args:
        heat: [batch, hf, wf] float32 >= 0.
        box: (top, left, rows, cols) in feature-grid units, inside ``heat``.
        max_positions: >= 1.
    Returns:
        (top, left, rows, cols) in feature-grid units.
    """
    top, left, rows, cols = (int(v) for v in box)
    if max_positions < 1:
        raise ValueError(f"max_positions must be >= 1, got {max_positions}")
    if rows * cols <= max_positions:
        return top, left, rows, cols
    shrink = (max_positions / (rows * cols)) ** 0.5
    r = min(rows, max(1, int(rows * shrink)))
    c = min(cols, max(1, max_positions // r))
    inner = heat.sum(dim=0)[top : top + rows, left : left + cols].double()
    win = F.avg_pool2d(inner[None, None], (r, c), stride=1)[0, 0]  # every r x c window
    dt, dl = divmod(int(win.flatten().argmax()), win.shape[1])
    return top + dt, left + dl, r, c

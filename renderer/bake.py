"""Baking a radiance field into the feature renderer's grid (as SNeRG and MobileNeRF bake
theirs): direct queries of the field's colour and density at the grid's vertices
(:func:`bake_field`), so the renderer starts from the field itself and distillation only
fine-tunes it; and what a setup costs against the views it speeds up
(:func:`break_even_views`)."""

from __future__ import annotations

import math

import torch
from torch import Tensor

from renderer.fields import GridField, trilinear
from renderer.model import RadianceField

BAKE_CHUNK = 65536
"""Grid vertices queried per field call."""


def grid_points(aabb: Tensor, shape: tuple[int, int, int]) -> Tensor:
    """The vertices of a grid of ``shape`` (z, y, x) spanning ``aabb`` [2, 3], corners
    included: [z * y * x, 3] world points (x, y, z) in vertex-major (z, y, x) order."""
    nz, ny, nx = shape
    axes = [
        torch.linspace(float(aabb[0, a]), float(aabb[1, a]), n) for a, n in enumerate((nx, ny, nz))
    ]
    zz, yy, xx = torch.meshgrid(axes[2], axes[1], axes[0], indexing="ij")
    return torch.stack([xx, yy, zz], -1).reshape(-1, 3)


@torch.no_grad()
def bake_field(model: RadianceField, shape: tuple[int, int, int]) -> tuple[Tensor, Tensor]:
    """The field's colour and density queried at the vertices of a grid of ``shape`` (z, y,
    x) over its box.

    Returns:
        (colour [num_vertices, 3 (d + 1)^2]: a grid field's SH coefficients (logits, degree
        d), else the logits of its colour seen along no direction (d = 0);
        opacity [num_vertices]: ``1 - exp(-sigma * step_m)``, the share of light one
        marching step at that point stops, in [0, 1]).
    """
    field = model.field
    colour, opacity = [], []
    for p in grid_points(model.aabb, shape).split(BAKE_CHUNK):
        if isinstance(field, GridField):
            colour.append(trilinear(field.color_grid, field.aabb, p))
            sigma = field.density(p)
        else:
            sigma, rgb = field(p, None)
            colour.append(torch.logit(rgb.clamp(1e-3, 1 - 1e-3)))
        opacity.append(1.0 - torch.exp(-sigma * model.step_m))
    return torch.cat(colour), torch.cat(opacity)


def break_even_views(
    setup_seconds: float, seconds_per_view: float, full_seconds_per_view: float
) -> float | None:
    """Views after which a renderer's setup has paid for itself: ``setup_seconds`` over the
    time it saves per view against the full render (``full_seconds_per_view -
    seconds_per_view``). 0 with no setup; None when it saves nothing per view (it never
    pays off)."""
    if setup_seconds <= 0:
        return 0.0
    saved = full_seconds_per_view - seconds_per_view
    if not saved > 0:
        return None
    return math.ceil(setup_seconds / saved)

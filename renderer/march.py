"""Ray marching that stops where it no longer matters: :func:`march_until_opaque`.

:func:`~renderer.sampler.sample_along_rays` generates every step of every ray across the
scene box and then drops those in empty cells; behind the first surface it keeps marching.
This marches all rays together a segment of ``chunk`` steps at a time, front to back, only
across the box of the occupied cells and only while a ray's transmittance is still at
least ``min_transmittance`` (early ray termination). The steps are those of
``sample_along_rays`` (the same lattice along each ray, the box's entry snapped to it), so
what it returns is the same as marching every sample, except on the samples behind a
ray's end: each of those had a weight below the transmittance at the end, so none of them
is above a ``weight_threshold`` at least ``min_transmittance``, and the opacity differs by
less than ``min_transmittance``. Before each segment a ray in an empty cell jumps ahead
over the steps that lie within the empty cells around it (``hops`` times; the distance to
the nearest occupied cell, :meth:`~renderer.sampler.OccupancyGrid.empty_distance`): the
same samples are evaluated, from fewer occupancy lookups. No Python loop over rays: one
over the segments of the longest ray.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import torch
from torch import Tensor

from renderer.cameras import intersect_aabb
from renderer.sampler import OccupancyGrid
from renderer.volume import packed_weights


@dataclass(frozen=True)
class Marched:
    """The weighted samples of a march, ray by ray in order of t."""

    positions: Tensor  # [num_kept, 3] world points of the samples above the weight threshold
    weights: Tensor  # [num_kept] eq. 4 weights
    rays: Tensor  # [num_kept] int64, non-decreasing
    opacity: Tensor  # [num_rays] 1 - transmittance where the ray ended
    evaluated: Tensor  # [num_rays] int64 density evaluations per ray


@torch.no_grad()
def march_until_opaque(
    origins: Tensor,
    directions: Tensor,
    aabb: Tensor,
    step_m: float,
    occupancy: OccupancyGrid,
    density: Callable[[Tensor], Tensor],
    min_transmittance: float,
    weight_threshold: float,
    chunk: int = 16,
    hops: int = 2,
) -> Marched:
    """March rays [num_rays, 3] (unit directions) through ``aabb`` at ``step_m`` (the
    steps of :func:`~renderer.sampler.sample_along_rays` without perturbation), evaluating
    ``density(points [n, 3]) -> sigma [n]`` only at steps in occupied cells, inside the
    occupied cells' box, on rays whose transmittance is at least ``min_transmittance``
    (in (0, 1)); samples whose weight is at most ``weight_threshold`` are dropped. ``hops``:
    jumps over empty cells before each segment (0: none)."""
    if not 0 < min_transmittance < 1:
        raise ValueError(f"min_transmittance must be in (0, 1), got {min_transmittance}")
    num_rays = origins.shape[0]
    t_box, _ = intersect_aabb(origins, directions, aabb)
    t_near, t_far = intersect_aabb(origins, directions, occupancy.occupied_box(margin_cells=0))
    # the first step of the scene box's lattice at or before the occupied box's entry
    first = torch.floor(((t_near - t_box) / step_m).clamp_min(0.0))
    start = t_box.double() + (first.double() + 0.5) * step_m  # [num_rays] the first step's t
    depth = torch.zeros(num_rays, dtype=torch.float64)  # optical depth so far
    evaluated = torch.zeros(num_rays, dtype=torch.long)
    limit = -math.log(min_transmittance)
    live = (t_far > t_near).nonzero()[:, 0]
    offsets = torch.arange(chunk, dtype=torch.float32) * step_m
    kept: list[tuple[Tensor, Tensor, Tensor]] = []
    skip = _Skipper(origins, directions, occupancy, step_m) if hops else None
    while live.numel():
        if skip is not None:
            for _ in range(hops):
                start.index_add_(0, live, skip.steps(live, start.index_select(0, live)))
            inside = start.index_select(0, live) < t_far.index_select(0, live).double()
            live = live.index_select(0, inside.nonzero()[:, 0])
            if not live.numel():
                break
        t = (start.index_select(0, live).float()[:, None] + offsets).reshape(-1)
        rays = live.repeat_interleave(chunk)
        # steps past the box are dropped with the empty cells (outside: none occupied)
        occ = occupancy.query_along(origins, directions, rays, t, inside_only=False)
        rays, t = rays.index_select(0, occ), t.index_select(0, occ)
        pos = origins.index_select(0, rays) + t[:, None] * directions.index_select(0, rays)
        sigma = density(pos) if t.numel() else t
        deltas = torch.full_like(t, step_m)
        w, _ = packed_weights(sigma, deltas, rays, num_rays)
        w = w * torch.exp(-depth.index_select(0, rays)).float()
        depth.index_add_(0, rays, (sigma * deltas).double())
        evaluated.index_add_(0, rays, torch.ones_like(rays))
        keep = (w > weight_threshold).nonzero()[:, 0]
        kept.append(
            (pos.index_select(0, keep), w.index_select(0, keep), rays.index_select(0, keep))
        )
        start.index_add_(0, live, torch.full((live.numel(),), chunk * step_m, dtype=torch.float64))
        go = (depth.index_select(0, live) < limit) & (
            start.index_select(0, live) < t_far.index_select(0, live).double()
        )
        live = live.index_select(0, go.nonzero()[:, 0])
    positions, weights, rays = (torch.cat(x) for x in zip(*kept)) if kept else _empty()
    order = torch.sort(rays, stable=True).indices  # segment by segment -> ray by ray
    return Marched(
        positions.index_select(0, order),
        weights.index_select(0, order),
        rays.index_select(0, order),
        (-torch.expm1(-depth)).float(),
        evaluated,
    )


class _Skipper:
    """How far each ray can jump ahead through empty cells: from a point in a cell at
    distance k (:meth:`OccupancyGrid.empty_distance`), every point within k - 1 cells along
    each axis is in an empty cell, so the ray may pass the steps within that reach."""

    def __init__(
        self, origins: Tensor, directions: Tensor, occupancy: OccupancyGrid, step_m: float
    ):
        self.occupancy = occupancy
        self.rays = occupancy.rays_in_cells(origins, directions)
        # steps along the ray per cell of travel in its fastest axis: [num_rays]
        self.reach = 1.0 / (self.rays[1].abs().amax(0).double() * step_m)
        self.dist = occupancy.empty_distance().reshape(-1).double()
        self.step_m = step_m

    def steps(self, live: Tensor, t: Tensor) -> Tensor:
        """Metres [n] float64 each ray of ``live`` can advance from ``t`` [n] float64 (a step
        of its lattice, looked up in the cell its segment's first sample falls in) to a
        later step, every step passed lying in an empty cell. A point outside the grid is
        taken at its nearest cell: it can reach no cell that one could not."""
        cell, _ = self.occupancy.cells_along(self.rays, live, t.float(), inside_only=True)
        k = self.dist.index_select(0, cell)
        n = torch.where(k > 0, torch.floor((k - 1) * self.reach.index_select(0, live)) + 1, 0.0)
        return n * self.step_m


def _empty() -> tuple[Tensor, Tensor, Tensor]:
    return torch.zeros(0, 3), torch.zeros(0), torch.zeros(0, dtype=torch.long)

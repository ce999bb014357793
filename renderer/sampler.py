"""Where along a ray to evaluate the field: uniform steps inside the scene box, minus the
steps that fall into cells an occupancy grid marks empty (empty-space skipping).

nerfacc's ray marching is CUDA-only; this is the same idea in plain torch.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from renderer.cameras import Intrinsics, intersect_aabb, project_points


class OccupancyGrid(nn.Module):
    """A boolean grid of cells over ``aabb``; a cell is occupied when its largest alpha
    ``1 - exp(-sigma * step_m)`` exceeds ``threshold`` (then dilated by one cell).

    A cell's largest density is taken over its 8 corners and its centre. For a
    :class:`~renderer.fields.GridField` whose vertices are this grid's corners
    (``OccupancyGrid.for_grid_field``) that is exact: a trilinear field takes its extreme
    values at the corners and softplus is monotonic, so no occupied cell is ever skipped.
    All cells start occupied.
    """

    def __init__(self, aabb: Tensor, cells: tuple[int, int, int]):
        super().__init__()
        if min(cells) < 1:
            raise ValueError(f"cells must be >= 1 per axis, got {cells}")
        self.register_buffer("aabb", torch.as_tensor(aabb, dtype=torch.float32).clone())
        nx, ny, nz = cells
        self.register_buffer("occupied", torch.ones(nz, ny, nx, dtype=torch.bool))  # [z, y, x]
        # cells known to be empty from the views (visual hull): never occupied again
        self.register_buffer("free", torch.zeros(nz, ny, nx, dtype=torch.bool))  # [z, y, x]

    @classmethod
    def for_grid_field(cls, field) -> OccupancyGrid:
        """Cells whose corners are the vertices of ``field``'s grids."""
        nx, ny, nz = field.resolution
        return cls(field.aabb, (nx - 1, ny - 1, nz - 1))

    @property
    def cells(self) -> tuple[int, int, int]:
        """Cells per axis (x, y, z)."""
        return (self.occupied.shape[2], self.occupied.shape[1], self.occupied.shape[0])

    @property
    def fraction_occupied(self) -> float:
        return self.occupied.float().mean().item()

    def _lattice(self, offset: float) -> Tensor:
        """Points at (i + offset) cell sizes from the min corner: [z, y, x, 3] (x, y, z order)."""
        nx, ny, nz = self.cells
        extra = 1 if offset == 0.0 else 0
        axes = [
            self.aabb[0, a]
            + (torch.arange(n + extra, dtype=torch.float32) + offset)
            * (self.aabb[1, a] - self.aabb[0, a])
            / n
            for a, n in enumerate((nx, ny, nz))
        ]
        z, y, x = torch.meshgrid(axes[2], axes[1], axes[0], indexing="ij")
        return torch.stack([x, y, z], dim=-1)

    @torch.no_grad()
    def update(
        self,
        density_fn: Callable[[Tensor], Tensor],
        step_m: float,
        threshold: float = 1e-3,
        vertex_density: Tensor | None = None,
        chunk: int = 65536,
    ) -> float:
        """Recompute occupancy from ``density_fn(points [n, 3]) -> sigma [n]``.

        Args:
            vertex_density: [z+1, y+1, x+1] sigma at the cell corners when already known
                (a grid field's own vertices); otherwise evaluated with ``density_fn``.
        Returns:
            the fraction of cells occupied.
        """

        def evaluate(points: Tensor) -> Tensor:
            flat = points.reshape(-1, 3)
            out = torch.cat(
                [density_fn(flat[i : i + chunk]) for i in range(0, flat.shape[0], chunk)]
            )
            return out.reshape(points.shape[:-1])

        corners = vertex_density if vertex_density is not None else evaluate(self._lattice(0.0))
        cell_max = F.max_pool3d(corners[None, None], kernel_size=2, stride=1)[0, 0]  # [z, y, x]
        if vertex_density is None:
            cell_max = torch.maximum(cell_max, evaluate(self._lattice(0.5)))
        alpha = -torch.expm1(-cell_max * step_m)
        occ = (alpha > threshold).float()
        occ = F.max_pool3d(occ[None, None], kernel_size=3, stride=1, padding=1)[0, 0]
        self.occupied = (occ > 0) & ~self.free
        return self.fraction_occupied

    @torch.no_grad()
    def inherit_free(self, coarser: OccupancyGrid) -> float:
        """Mark empty the cells of this grid that lie in space ``coarser`` knows is empty:
        a cell is free when the coarser cell holding its centre and that cell's 26
        neighbours are all free (exact for any cell no larger than the coarser ones).

        Returns:
            the fraction of cells now known to be empty.
        """
        known = F.max_pool3d((~coarser.free).float()[None, None], 3, stride=1, padding=1)[0, 0]
        cx, cy, cz = coarser.cells
        size = torch.tensor([cx, cy, cz], dtype=torch.float32)
        rel = (self._lattice(0.5).reshape(-1, 3) - coarser.aabb[0]) * (
            size / (coarser.aabb[1] - coarser.aabb[0])
        )
        inside = (rel.amin(dim=-1) >= 0) & ((rel - size).amax(dim=-1) < 0)
        cell = torch.minimum(rel.clamp_min(0.0), size - 1).floor_().long()
        free = inside & (known[cell[:, 2], cell[:, 1], cell[:, 0]] == 0)
        self.free |= free.reshape(self.free.shape)
        self.occupied &= ~self.free
        return self.free.float().mean().item()

    @torch.no_grad()
    def carve(
        self,
        poses: Tensor,
        intrinsics: Intrinsics,
        masks: Tensor,
        threshold: float = 0.02,
        max_radius_px: int = 8,
    ) -> float:
        """Mark empty every cell that some view sees entirely against the background
        (space carving: the visual hull of the masks).

        A cell is carved by a view when its bounding sphere lies in front of the camera,
        its whole image footprint lies inside the image, and the mask, max-pooled over a
        square that contains the footprint, stays below ``threshold`` there. Cells whose
        footprint would need a square wider than ``2 * max_radius_px + 1`` (cameras very
        close) are left alone. Conservative: a cell holding any surface that some view
        shows with mask >= ``threshold`` is never carved.

        Args:
            poses: [num_views, 4, 4] camera-to-world.
            intrinsics: of ``masks``.
            masks: [num_views, height, width] float in [0, 1] (1 = object).
        Returns:
            the fraction of cells now known to be empty.
        """
        nx, ny, nz = self.cells
        centres = self._lattice(0.5).reshape(-1, 3)  # [cells, 3]
        size = (self.aabb[1] - self.aabb[0]) / torch.tensor([nx, ny, nz], dtype=torch.float32)
        radius_m = 0.5 * size.norm().item()  # half the cell diagonal
        focal = max(intrinsics.fx, intrinsics.fy)
        h, w = intrinsics.height, intrinsics.width
        # footprint radius (px) = rho_m / depth; off-axis footprints stretch by up to
        # 1 / cos^2 of the angle to the axis, largest in the image corners
        corner = max(abs(intrinsics.cx), abs(w - intrinsics.cx)) / intrinsics.fx
        corner2 = max(abs(intrinsics.cy), abs(h - intrinsics.cy)) / intrinsics.fy
        rho_m = focal * radius_m * (1.0 + corner**2 + corner2**2)
        # background-only maps, one per dilation radius r = 1..max_radius_px
        # (the max over a (2r+1)^2 square is r nested 3 x 3 maxima: one cheap pool per radius)
        pooled, maps = masks.float()[:, None], []  # [views, 1, h, w]
        for _ in range(max_radius_px):
            pooled = F.max_pool2d(pooled, kernel_size=3, stride=1, padding=1)
            maps.append(pooled[:, 0] < threshold)
        dilated = torch.stack(maps, dim=1).reshape(masks.shape[0], -1)  # [views, radii*h*w]
        free = self.free.reshape(-1).clone()
        for k in range(poses.shape[0]):
            todo = (~free).nonzero()[:, 0]
            if todo.numel() == 0:
                break
            uv, z = project_points(centres[todo], poses[k], intrinsics)
            u, v = uv[:, 0], uv[:, 1]
            r = torch.ceil(rho_m / (z - radius_m).clamp_min(1e-6)) + 1.0
            ok = (
                (z > radius_m)
                & (r <= max_radius_px)
                & (u - r >= 0)
                & (u + r <= w)
                & (v - r >= 0)
                & (v + r <= h)
            )
            if not ok.any():
                continue
            ui = u[ok].floor().long().clamp(0, w - 1)
            vi = v[ok].floor().long().clamp(0, h - 1)
            ri = r[ok].long() - 1
            bg = dilated[k][(ri * h + vi) * w + ui]
            free[todo[ok][bg]] = True
        self.free = free.reshape(self.free.shape)
        self.occupied &= ~self.free
        return self.free.float().mean().item()

    def occupied_box(self, margin_cells: int = 2) -> Tensor:
        """The box around the occupied cells, ``margin_cells`` wider on every side and
        clipped to ``aabb``: [2, 3] (the whole ``aabb`` when nothing is occupied)."""
        idx = self.occupied.nonzero()  # [n, 3] (z, y, x)
        if idx.numel() == 0:
            return self.aabb.clone()
        nx, ny, nz = self.cells
        size = (self.aabb[1] - self.aabb[0]) / torch.tensor([nx, ny, nz], dtype=torch.float32)
        lo = idx.amin(0).flip(0).float() - margin_cells  # [3] (x, y, z) in cells
        hi = idx.amax(0).flip(0).float() + 1 + margin_cells
        box = torch.stack([self.aabb[0] + lo * size, self.aabb[0] + hi * size])
        return torch.stack([box[0].maximum(self.aabb[0]), box[1].minimum(self.aabb[1])])

    @torch.no_grad()
    def empty_distance(self, cap: int = 16) -> Tensor:
        """Chebyshev distance in cells from each cell to the nearest occupied one, at most
        ``cap`` (>= 1): [z, y, x] float32, 0 in occupied cells. Every cell within ``k - 1``
        cells (in each axis) of a cell at distance ``k`` is empty. Cached until
        :attr:`occupied` changes."""
        key = (self.occupied.data_ptr(), self.occupied._version, cap)
        cached = getattr(self, "_distance", None)
        if cached is not None and cached[0] == key:
            return cached[1]
        dist = torch.full(self.occupied.shape, float(cap))
        reached = self.occupied.float()[None, None]
        dist[self.occupied] = 0.0
        for k in range(1, cap):
            reached = F.max_pool3d(reached, kernel_size=3, stride=1, padding=1)
            dist[(reached[0, 0] > 0) & (dist == cap)] = float(k)
        self._distance = (key, dist)
        return dist

    def query(self, points: Tensor) -> Tensor:
        """Whether each point lies in an occupied cell: points [n, 3] -> [n] bool
        (False outside the box). The same lookup as :meth:`query_along`, with each point
        its own ray at t = 0."""
        n = points.shape[0]
        keep = self.query_along(
            points, torch.zeros_like(points), torch.arange(n), points.new_zeros(n), False
        )
        return torch.zeros(n, dtype=torch.bool).index_fill_(0, keep, True)

    def rays_in_cells(self, origins: Tensor, directions: Tensor) -> tuple[Tensor, Tensor]:
        """Rays [num_rays, 3] moved into cell units, for :meth:`cells_along`: (origins,
        directions), [3, num_rays] each."""
        nx, ny, nz = self.cells
        scale = torch.tensor([nx, ny, nz], dtype=torch.float32) / (self.aabb[1] - self.aabb[0])
        oc = ((origins - self.aabb[0]) * scale).t().contiguous()
        return oc, (directions * scale).t().contiguous()

    def cells_along(
        self, rays: tuple[Tensor, Tensor], ray_idx: Tensor, t: Tensor, inside_only: bool
    ) -> tuple[Tensor, Tensor | None]:
        """The cells of the points at ``t`` along ``rays[ray_idx]`` (:meth:`rays_in_cells`;
        the points are never formed in world units): (flat (z, y, x) indices [n] int64,
        clamped into the grid; whether each point lies in the box [n] bool, or None with
        ``inside_only``: the caller guarantees every point lies in the box, up to rounding,
        which the clamp absorbs)."""
        nx, ny, nz = self.cells
        oc, dc = rays
        flat, inside = None, None
        for a, (n, stride) in enumerate(((nx, 1.0), (ny, float(nx)), (nz, float(nx * ny)))):
            c = torch.addcmul(oc[a].index_select(0, ray_idx), t, dc[a].index_select(0, ray_idx))
            if not inside_only:
                ok = (c >= 0) & (c <= n)
                inside = ok if inside is None else inside & ok
            c = c.floor_().clamp_(0.0, float(n - 1))
            flat = c.mul_(stride) if flat is None else flat.add_(c, alpha=stride)
        assert flat is not None
        return flat.long(), inside  # exact below 2^24 cells

    def query_along(
        self, origins: Tensor, directions: Tensor, ray_idx: Tensor, t: Tensor, inside_only: bool
    ) -> Tensor:
        """Indices of the points ``origins[ray_idx] + t * directions[ray_idx]`` that lie in
        occupied cells: [k] int64 (:meth:`cells_along`; ``inside_only`` as there)."""
        rays = self.rays_in_cells(origins, directions)
        flat, inside = self.cells_along(rays, ray_idx, t, inside_only)
        occ = self.occupied.reshape(-1).index_select(0, flat)
        if inside is not None:
            occ &= inside
        return occ.nonzero()[:, 0]


@dataclass(frozen=True)
class RaySamples:
    """Packed samples: only those in occupied cells, ray by ray in order of t."""

    positions: Tensor
    """[num_packed, 3] float32 world points."""
    directions: Tensor
    """[num_packed, 3] float32 unit directions of their rays."""
    t: Tensor
    """[num_packed] float32 distance along the ray (m)."""
    deltas: Tensor
    """[num_packed] float32 segment length (m): the step size."""
    ray_indices: Tensor
    """[num_packed] int64, non-decreasing."""


def sample_along_rays(
    origins: Tensor,
    directions: Tensor,
    aabb: Tensor,
    step_m: float,
    occupancy: OccupancyGrid | None = None,
    perturb: bool = False,
    generator: torch.Generator | None = None,
    near_m: float = 0.0,
) -> RaySamples:
    """Uniform samples ``t_k = t_near + (k + u) * step_m`` inside the box, empty cells dropped.

    Args:
        origins, directions: [num_rays, 3] float32 (unit directions).
        aabb: [2, 3] box.
        step_m: step (m), > 0.
        occupancy: cells to keep; None keeps every sample in the box.
        perturb: u ~ U[0, 1) per ray (training); else u = 0.5.
        near_m: no sample nearer than this to the origin.
    Returns:
        :class:`RaySamples`.
    """
    if not step_m > 0:
        raise ValueError(f"step_m must be > 0, got {step_m}")
    num_rays = origins.shape[0]
    t_near, t_far = intersect_aabb(origins, directions, aabb)
    t_near = t_near.clamp_min(near_m)
    span = (t_far - t_near).clamp_min(0.0)
    if perturb:
        u = torch.rand(num_rays, 1, generator=generator)[:, 0]
    else:
        u = torch.full((num_rays,), 0.5)
    # only the samples inside the box, generated packed: ray i has ceil(span_i / step - u_i)
    counts = torch.ceil(span / step_m - u).clamp_min(0.0).long()  # [num_rays]
    total = int(counts.sum().item()) if num_rays else 0
    if total == 0:
        empty = origins.new_zeros(0)
        return RaySamples(
            origins.new_zeros(0, 3),
            origins.new_zeros(0, 3),
            empty,
            empty,
            torch.zeros(0, dtype=torch.long),
        )
    # Every candidate is generated in cell units and only the survivors get world points:
    # candidates usually outnumber occupied samples several times, so per-candidate work is
    # what this function costs. t is formed in float64 from a per-ray offset (exact for
    # millions of samples) and counts make every t fall before t_far, so no test against
    # it is needed. (index_select rather than [] indexing: the same gathers, faster.)
    ray_idx = torch.repeat_interleave(torch.arange(num_rays), counts)  # [total]
    first = torch.cumsum(counts, 0) - counts  # [num_rays] index of each ray's first sample
    offset = t_near.double() + (u.double() - first.double()) * step_m  # [num_rays]
    t64 = offset.index_select(0, ray_idx) + torch.arange(total, dtype=torch.float64) * step_m
    t = t64.float()
    if occupancy is not None:
        keep = occupancy.query_along(
            origins, directions, ray_idx, t, inside_only=_inside(aabb, occupancy.aabb)
        )
        ray_idx, t = ray_idx.index_select(0, keep), t.index_select(0, keep)
    pos = origins.index_select(0, ray_idx) + t[:, None] * directions.index_select(0, ray_idx)
    d = directions.index_select(0, ray_idx)
    return RaySamples(pos, d, t, torch.full_like(t, step_m), ray_idx)


def _inside(box: Tensor, outer: Tensor) -> bool:
    """Whether ``box`` lies within ``outer`` (both [2, 3])."""
    return bool((box[0] >= outer[0]).all() and (box[1] <= outer[1]).all())

"""Radiance fields: what the network predicts at a point (density and colour).

* :class:`GridField`: dense density (1 channel) and colour (3 * (degree + 1)^2 channels:
  spherical-harmonics coefficients, degree 0 = diffuse) voxel grids read with trilinear
  ``grid_sample`` over the scene box, DVGO-style post-activation (``sigma =
  softplus(grid + bias)``, ``rgb = sigmoid(sum_k c_k Y_k(d))``), moved coarse-to-fine
  onto finer and smaller boxes by :meth:`GridField.resample`.
* :class:`MLPField`: the vanilla NeRF: positional encoding + MLP, view-dependent colour.

Both map points ``[num_points, 3]`` (and unit directions) to ``(sigma [num_points],
rgb [num_points, 3])`` and expose ``density(points)`` for the occupancy grid.
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import Tensor, nn


def _normalize(points: Tensor, aabb: Tensor) -> Tensor:
    """World points to grid_sample's [-1, 1] coordinates of the box. [num_points, 3]."""
    return (points - aabb[0]) / (aabb[1] - aabb[0]) * 2.0 - 1.0


def trilinear_corners(aabb: Tensor, shape, points: Tensor) -> tuple[Tensor, Tensor]:
    """The eight vertices around each point of a vertex grid over ``aabb`` and their
    trilinear weights, with ``F.grid_sample``'s ``align_corners=True,
    padding_mode="border"`` (points outside the box read the border).

    Args:
        aabb: [2, 3] the box the grid's corner vertices sit on.
        shape: the grid's (z, y, x) vertex counts, each >= 2.
        points: [num_points, 3] world points (x, y, z).
    Returns:
        (index [num_points * 8] int64 into the flattened (z, y, x) grid,
        weights [num_points, 8] float32 summing to 1 per point).
    """
    nz, ny, nx = (int(n) for n in shape)
    # axis by axis on contiguous rows of [3, n] rather than the same arithmetic on [n, 3]
    # with broadcast outer products: contiguous rows keep each axis's work vectorised
    pt = points.t()
    lows, fracs, bases = aabb[0].tolist(), [], []
    for a, n in enumerate((nx, ny, nz)):
        scale = (n - 1) / float(aabb[1, a] - aabb[0, a])
        u = (pt[a] - lows[a]).mul_(scale).clamp_(0.0, n - 1)
        b = u.floor().clamp_(max=n - 2)  # lower corner, so that u - b is in [0, 1]
        f = u.sub_(b)
        fracs.append((1 - f, f))
        bases.append(b.long())
    (gx, fx), (gy, fy), (gz, fz) = fracs
    zy = (gz * gy, gz * fy, fz * gy, fz * fy)
    weights = torch.stack([q * x for q in zy for x in (gx, fx)], 1)  # [n, 8], (z, y, x) order
    first = (bases[2] * ny + bases[1]) * nx + bases[0]  # [num_points]
    offsets = torch.tensor(
        [z + y + x for z in (0, nx * ny) for y in (0, nx) for x in (0, 1)], device=points.device
    )
    return (first[:, None] + offsets).reshape(-1), weights


def read_corners(grid: Tensor, index: Tensor, weights: Tensor) -> Tensor:
    """Trilinear reads of ``grid`` [1, channels, z, y, x] at the corners of
    :func:`trilinear_corners`: [num_points, channels]. A gather, so the backward pass is
    one ``index_add`` instead of ``grid_sample``'s 3-D backward."""
    c = grid.shape[1]
    values = grid.reshape(c, -1).index_select(1, index).reshape(c, -1, 8)
    return (values * weights).sum(-1).t()


def read_rows(rows: Tensor, index: Tensor, weights: Tensor) -> Tensor:
    """Trilinear reads of a vertex-major table ``rows`` [num_vertices, channels] at the
    corners of :func:`trilinear_corners`: [num_points, channels].

    One ``F.embedding_bag`` (weighted sum of eight rows per point): for inference, where
    one fused gather beats :func:`read_corners`; its backward is slower, so training keeps
    :func:`read_corners`."""
    return F.embedding_bag(index.view(-1, 8), rows, per_sample_weights=weights, mode="sum")


class VertexRows:
    """A vertex-major copy [num_vertices, channels] of a grid [1, channels, z, y, x] for
    :func:`read_rows`, rebuilt when the grid is replaced or changed in place by an
    operation that moves its version counter. **Fused optimisers** (``Adam(fused=True)``)
    do not move it: code that steps one must call :meth:`clear` (GridField does so on
    every ``train()`` / ``eval()`` switch and reads rows only in eval mode). A one-channel
    grid needs no copy."""

    def __init__(self):
        self.clear()

    def clear(self) -> None:
        """Forget the copy (the grid changed in a way its version counter does not show)."""
        self._grid, self._version, self._rows = None, None, None

    def __call__(self, grid: Tensor) -> Tensor:
        c = grid.shape[1]
        if c == 1:
            return grid.detach().reshape(-1, 1)
        if self._grid is not grid or self._version != grid._version:
            self._rows = grid.detach()[0].permute(1, 2, 3, 0).reshape(-1, c).contiguous()
            self._grid, self._version = grid, grid._version
        return self._rows


def trilinear(grid: Tensor, aabb: Tensor, points: Tensor) -> Tensor:
    """``F.grid_sample(grid, points, align_corners=True, padding_mode="border")`` at world
    points, as gathers: [num_points, channels] from ``grid`` [1, channels, z, y, x] over
    ``aabb`` [2, 3] (at least 2 vertices per axis).

    Gathers replace ``grid_sample`` because its 3-D backward is slow on CPU, and a training
    step spends much of its time here.
    """
    return read_corners(grid, *trilinear_corners(aabb, grid.shape[2:], points))


def grid_resolution(aabb: Tensor, resolution: int) -> tuple[int, int, int]:
    """Vertices per axis (x, y, z): ``resolution`` on the longest axis, equal voxel sizes."""
    extent = aabb[1] - aabb[0]
    voxel = extent.max().item() / (resolution - 1)
    return tuple(max(2, int(round(e / voxel)) + 1) for e in extent.tolist())


def sh_basis(directions: Tensor, degree: int) -> Tensor:
    """Real spherical harmonics up to ``degree`` (<= 2) with Y_0 replaced by 1.

    Args:
        directions: [num_points, 3] unit vectors (x, y, z).
    Returns:
        [num_points, (degree + 1)^2]: 1, then -c1 y, c1 z, -c1 x (c1 = 0.4886), then the
        five degree-2 terms (Plenoxels' ordering and constants).
    """
    x, y, z = directions.unbind(-1)
    out = [torch.ones_like(x)]
    if degree >= 1:
        c1 = 0.4886025119029199
        out += [-c1 * y, c1 * z, -c1 * x]
    if degree >= 2:
        out += [
            1.0925484305920792 * x * y,
            -1.0925484305920792 * y * z,
            0.31539156525252005 * (2.0 * z * z - x * x - y * y),
            -1.0925484305920792 * x * z,
            0.5462742152960396 * (x * x - y * y),
        ]
    return torch.stack(out, dim=-1)


def resample_grid(grid: Tensor, aabb: Tensor, new_aabb: Tensor, resolution: int) -> Tensor:
    """Trilinear reads of a vertex grid over ``aabb`` at the vertices of a grid over
    ``new_aabb`` with ``resolution`` vertices on its longest axis (the border value outside
    ``aabb``). Cropping to a smaller box keeps the field exactly at the new vertices.

    Args:
        grid: [1, channels, z, y, x] float32; aabb, new_aabb: [2, 3].
    Returns:
        [1, channels, z', y', x'] float32, contiguous.
    """
    new_aabb = torch.as_tensor(new_aabb, dtype=torch.float32)
    nx, ny, nz = grid_resolution(new_aabb, resolution)
    axes = [torch.linspace(new_aabb[0, a], new_aabb[1, a], n) for a, n in enumerate((nx, ny, nz))]
    z, y, x = torch.meshgrid(axes[2], axes[1], axes[0], indexing="ij")
    coords = _normalize(torch.stack([x, y, z], dim=-1), aabb)  # [z', y', x', 3]
    out = F.grid_sample(
        grid, coords[None], mode="bilinear", align_corners=True, padding_mode="border"
    )
    return out.contiguous()


def expand_sh(grid: Tensor, degree: int) -> Tensor:
    """A colour grid with SH coefficients up to ``degree`` (0, 1 or 2): the existing ones
    kept, new ones zero (higher ones dropped when lowering the degree).

    Args:
        grid: [1, 3 * K, z, y, x] float32, channels ordered [3, K] (colour, coefficient).
    Returns:
        [1, 3 * (degree + 1)^2, z, y, x] float32.
    """
    if degree not in (0, 1, 2):
        raise ValueError(f"degree must be 0, 1 or 2, got {degree}")
    g = grid.reshape(3, -1, *grid.shape[2:])  # [3, K, z, y, x]
    k = (degree + 1) ** 2
    new = g.new_zeros(3, k, *g.shape[2:])
    n = min(k, g.shape[1])
    new[:, :n] = g[:, :n]
    return new.reshape(1, 3 * k, *g.shape[2:])


class GridField(nn.Module):
    """Dense voxel grids over ``aabb`` with DVGO post-activation.

    Grid values sit on vertices (``align_corners=True``): vertex i of axis a is at
    ``aabb[0, a] + i * extent_a / (n_a - 1)``.
    """

    def __init__(
        self, aabb: Tensor, resolution: int = 48, alpha_init: float = 1e-2, step_m: float = 0.02
    ):
        super().__init__()
        if resolution < 2:
            raise ValueError(f"resolution must be >= 2 vertices per axis, got {resolution}")
        if not 0.0 < alpha_init < 1.0:
            raise ValueError(f"alpha_init must be in (0, 1), got {alpha_init}")
        self.register_buffer("aabb", torch.as_tensor(aabb, dtype=torch.float32).clone())
        nx, ny, nz = grid_resolution(self.aabb, resolution)
        # softplus(bias) * step = -log(1 - alpha_init): empty space starts almost transparent.
        sigma0 = -math.log(1.0 - alpha_init) / step_m
        self.density_bias = math.log(math.expm1(sigma0))
        self.density_grid = nn.Parameter(torch.zeros(1, 1, nz, ny, nx))  # [1, 1, z, y, x]
        self.color_grid = nn.Parameter(torch.zeros(1, 3, nz, ny, nx))  # [1, 3, z, y, x]
        self._rows = VertexRows()  # the colour grid's vertex-major copy for eval mode

    def train(self, mode: bool = True) -> GridField:
        """Switch mode; the inference copy of the colour grid is dropped either way (the
        field's trainer steps a fused optimiser, which :class:`VertexRows` cannot see)."""
        self._rows.clear()
        return super().train(mode)

    @property
    def resolution(self) -> tuple[int, int, int]:
        """Vertices per axis (x, y, z)."""
        d = self.density_grid.shape
        return (d[4], d[3], d[2])

    def _sigma(self, raw: Tensor) -> Tensor:
        """Post-activation: sigma = softplus(grid value + bias) from [num_points, 1] reads."""
        return F.softplus(raw[:, 0] + self.density_bias)

    def density(self, points: Tensor) -> Tensor:
        """sigma (1/m) at points [num_points, 3] -> [num_points].

        Without gradients, one fused ``F.grid_sample`` of the single-channel grid (the
        same trilinear read to float rounding, and faster than the gathers for one channel;
        the gathers win from a few channels up and in the backward pass)."""
        if self.training or torch.is_grad_enabled():
            corners = trilinear_corners(self.aabb, self.density_grid.shape[2:], points)
            return self._sigma(self._read(self.density_grid, corners))
        n = points.shape[0]
        where = _normalize(points, self.aabb).view(1, n, 1, 1, 3)
        raw = F.grid_sample(self.density_grid, where, align_corners=True, padding_mode="border")
        return self._sigma(raw.view(n, 1))

    def _read(self, grid: Tensor, corners: tuple[Tensor, Tensor]) -> Tensor:
        """``grid`` at the points of ``corners``: the channel-major gathers while training or
        with gradients, else one read of the vertex-major copy (:func:`read_rows`)."""
        if self.training or torch.is_grad_enabled():
            return read_corners(grid, *corners)
        return read_rows(self._rows(grid), *corners)

    def vertex_density(self) -> Tensor:
        """sigma at every vertex: [z, y, x] (the exact maxima of the trilinear field per cell)."""
        return F.softplus(self.density_grid[0, 0] + self.density_bias)

    @property
    def sh_degree(self) -> int:
        """Spherical-harmonics degree of the colour (0: diffuse; 3 * (degree + 1)^2 channels)."""
        return int(round(math.sqrt(self.color_grid.shape[1] // 3))) - 1

    @torch.no_grad()
    def set_sh_degree(self, degree: int) -> None:
        """Make the colour view-dependent up to SH ``degree`` (0, 1 or 2); new coefficients
        start at zero, so the field renders as before (up to float rounding)."""
        self.color_grid = nn.Parameter(expand_sh(self.color_grid.data, degree))

    def forward(self, points: Tensor, directions: Tensor | None = None) -> tuple[Tensor, Tensor]:
        """(sigma [num_points], rgb [num_points, 3]) at points [num_points, 3] seen along
        unit ``directions`` [num_points, 3] (ignored by a diffuse field; None: the DC term).

        rgb = sigmoid(sum_k c_k Y_k(direction)) with the real SH basis Y_k up to
        :attr:`sh_degree` (Y_0 taken as 1, so a diffuse grid holds logits)."""
        corners = self.corners(points)
        return self.sigma_at(corners), self.color_at(corners, directions)

    def corners(self, points: Tensor) -> tuple[Tensor, Tensor]:
        """:func:`trilinear_corners` of ``points`` [num_points, 3] in this field's grids."""
        return trilinear_corners(self.aabb, self.density_grid.shape[2:], points)

    def sigma_at(self, corners: tuple[Tensor, Tensor]) -> Tensor:
        """sigma [num_points] at the points of :meth:`corners`."""
        return self._sigma(self._read(self.density_grid, corners))

    def color_at(self, corners: tuple[Tensor, Tensor], directions: Tensor | None) -> Tensor:
        """rgb [num_points, 3] at the points of :meth:`corners` seen along unit
        ``directions`` [num_points, 3] (None: the DC term), as in :meth:`forward`."""
        coef = self._read(self.color_grid, corners)  # [num_points, 3 * K]
        k = coef.shape[1] // 3
        if k == 1 or directions is None:
            return torch.sigmoid(coef[:, ::k])
        basis = sh_basis(directions, self.sh_degree)  # [num_points, K]
        logits = (coef.reshape(-1, 3, k) * basis[:, None, :]).sum(-1)  # [num_points, 3]
        return torch.sigmoid(logits)

    @torch.no_grad()
    def resample(self, aabb: Tensor, resolution: int) -> None:
        """Move the grids onto a new box ``aabb`` [2, 3] with ``resolution`` vertices on its
        longest axis (:func:`resample_grid`)."""
        aabb = torch.as_tensor(aabb, dtype=torch.float32)
        for name in ("density_grid", "color_grid"):
            new = resample_grid(getattr(self, name).data, self.aabb, aabb, resolution)
            setattr(self, name, nn.Parameter(new))
        self.aabb.copy_(aabb)

    def total_variation(self) -> Tensor:
        """Mean squared difference of neighbouring density-grid values (a scalar)."""
        g = self.density_grid
        return (
            (g[..., 1:, :, :] - g[..., :-1, :, :]).pow(2).mean()
            + (g[..., :, 1:, :] - g[..., :, :-1, :]).pow(2).mean()
            + (g[..., :, :, 1:] - g[..., :, :, :-1]).pow(2).mean()
        )


def positional_encoding(x: Tensor, num_frequencies: int) -> Tensor:
    """NeRF's gamma(x) = (x, sin(2^k pi x), cos(2^k pi x)) for k < num_frequencies.

    Args:
        x: [num_points, dims].
    Returns:
        [num_points, dims * (1 + 2 * num_frequencies)].
    """
    freqs = (2.0 ** torch.arange(num_frequencies, dtype=x.dtype)) * math.pi
    xf = x[:, None, :] * freqs[:, None]  # [num_points, num_frequencies, dims]
    return torch.cat([x, torch.sin(xf).flatten(1), torch.cos(xf).flatten(1)], dim=-1)


class MLPField(nn.Module):
    """Vanilla NeRF: gamma(x) -> MLP -> sigma, feature; (feature, gamma(d)) -> rgb.

    Positions are normalised to [-1, 1] over ``aabb`` before encoding. The paper uses
    width 256, depth 8; the CPU default is smaller so that it trains at all in minutes.
    """

    def __init__(
        self,
        aabb: Tensor,
        width: int = 128,
        depth: int = 4,
        position_frequencies: int = 10,
        direction_frequencies: int = 4,
    ):
        super().__init__()
        if width < 1 or depth < 1:
            raise ValueError(f"width and depth must be >= 1, got {width}, {depth}")
        self.register_buffer("aabb", torch.as_tensor(aabb, dtype=torch.float32).clone())
        self.position_frequencies = position_frequencies
        self.direction_frequencies = direction_frequencies
        in_x = 3 * (1 + 2 * position_frequencies)
        in_d = 3 * (1 + 2 * direction_frequencies)
        layers: list[nn.Module] = []
        for i in range(depth):
            layers += [nn.Linear(in_x if i == 0 else width, width), nn.ReLU()]
        self.trunk = nn.Sequential(*layers)
        self.sigma_head = nn.Linear(width, 1)
        self.feature = nn.Linear(width, width)
        self.rgb_head = nn.Sequential(
            nn.Linear(width + in_d, width // 2), nn.ReLU(), nn.Linear(width // 2, 3)
        )

    def _trunk(self, points: Tensor) -> Tensor:
        return self.trunk(
            positional_encoding(_normalize(points, self.aabb), self.position_frequencies)
        )

    def density(self, points: Tensor) -> Tensor:
        """sigma (1/m) at points [num_points, 3] -> [num_points]."""
        return F.softplus(self.sigma_head(self._trunk(points))[:, 0] - 1.0)

    def forward(self, points: Tensor, directions: Tensor | None = None) -> tuple[Tensor, Tensor]:
        """(sigma [num_points], rgb [num_points, 3]); directions [num_points, 3] unit."""
        h = self._trunk(points)
        sigma = F.softplus(self.sigma_head(h)[:, 0] - 1.0)
        if directions is None:
            directions = torch.zeros_like(points)
        d = positional_encoding(directions, self.direction_frequencies)
        rgb = torch.sigmoid(self.rgb_head(torch.cat([self.feature(h), d], dim=-1)))
        return sigma, rgb

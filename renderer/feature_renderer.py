"""The lightweight renderer (the paper's §3.3, eq. 5) as it renders: a learned feature field
and a decoder (:class:`FeatureRenderer`); distilled by :func:`renderer.features.train_features`.

A trained radiance field keeps its density; a grid of ``K`` feature channels over the same
box replaces its colour. A view is volume-rendered at ``1 / downsample`` resolution with
the field's own weights (eq. 4, coarser marching step), but only the samples that carry
weight look up features, and a small convolutional decoder maps the ``K`` feature planes
plus opacity to the full-resolution image (sub-pixel shuffle).

The first ``3 (d + 1)^2`` channels start as the field's colour coefficients (SH degree d)
and stay view-dependent: the ray's direction is the same at every sample, so compositing
the coefficients and applying each pixel's SH basis afterwards equals compositing the
view-dependent colour sample by sample. The other channels are free features.

The grid is stored vertex-major and read with one ``F.embedding_bag`` per batch
(:func:`~renderer.fields.read_rows`); its gradient is added into the eight corner rows of
each sample in place (:class:`_GridRead`). Measurements of speed and fidelity against the
full render are in docs/design-notes.md and ``python -m benchmarks renderer``.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from renderer.bake import bake_field
from renderer.cameras import Intrinsics, camera_rays
from renderer.feature_config import FeatureConfig
from renderer.fields import GridField, read_rows, sh_basis, trilinear_corners
from renderer.march import march_until_opaque
from renderer.model import RadianceField
from renderer.refine import edge_mask, field_colours, masked_rays
from renderer.sampler import sample_along_rays
from renderer.volume import packed_sum, packed_weights

COLOUR_EPS = 1e-4
"""Composited colours are clamped to [eps, 1 - eps] before the decoder takes their logit."""


def low_res_intrinsics(intrinsics: Intrinsics, downsample: int) -> Intrinsics:
    """The camera whose pixel (i, j) covers full-resolution pixels [s i, s i + s) x [s j,
    s j + s), s = ``downsample`` (ceil of the size; exact when it does not divide it)."""
    s = float(downsample)
    return Intrinsics(
        intrinsics.fx / s,
        intrinsics.fy / s,
        intrinsics.cx / s,
        intrinsics.cy / s,
        -(-intrinsics.height // downsample),
        -(-intrinsics.width // downsample),
    )


class FeatureDecoder(nn.Module):
    """[batch, C + 1, h, w] planes (the first three: colour logits) and opacity ->
    [batch, 3, s h, s w] colour.

    The output is ``sigmoid(bilinear(f[:3]) + shuffle(residual))``: with the last layer at
    zero (its start) it is the bilinear upsampling of the colour logits. With
    ``colour_input`` the first three planes are colours in [0, 1], not logits, and the
    output is ``sigmoid(logit(bilinear(f[:3])) + shuffle(residual))``."""

    def __init__(
        self,
        channels: int,
        downsample: int,
        hidden: int = 32,
        generator: torch.Generator | None = None,
        colour_input: bool = False,
    ):
        super().__init__()
        self.downsample = downsample
        self.colour_input = colour_input
        self.body = nn.Sequential(
            nn.Conv2d(channels + 1, hidden, 3, padding=1),
            nn.LeakyReLU(0.1),
            nn.Conv2d(hidden, hidden, 3, padding=1),
            nn.LeakyReLU(0.1),
        )
        self.out = nn.Conv2d(hidden, 3 * downsample * downsample, 3, padding=1)
        # PyTorch's default initialisation of the hidden layers, drawn from ``generator``
        # (not the global stream): the same decoder, and the same distillation, every run
        generator = generator if generator is not None else torch.Generator().manual_seed(0)
        for conv in (self.body[0], self.body[2]):
            nn.init.kaiming_uniform_(conv.weight, a=math.sqrt(5), generator=generator)
            bound = 1 / math.sqrt(conv.weight[0].numel())
            nn.init.uniform_(conv.bias, -bound, bound, generator=generator)
        nn.init.zeros_(self.out.weight)
        nn.init.zeros_(self.out.bias)
        # channels-last convolutions: the same results as channels-first, in the layout
        # CPU convolution kernels at these widths run fastest (forward and backward)
        self.to(memory_format=torch.channels_last)

    def forward(self, x: Tensor) -> Tensor:
        s = self.downsample
        x = x.contiguous(memory_format=torch.channels_last)
        base = F.interpolate(x[:, :3], scale_factor=s, mode="bilinear", align_corners=False)
        if self.colour_input:
            base = torch.logit(base.clamp(COLOUR_EPS, 1.0 - COLOUR_EPS))
        return torch.sigmoid(base + F.pixel_shuffle(self.out(self.body(x)), s))


@dataclass
class LowResPass:
    """The weighted samples of one low-resolution view (the field's density, fixed)."""

    positions: Tensor  # [num_kept, 3] world points of the kept samples
    basis: Tensor  # [num_rays, (d + 1)^2] SH basis of each ray's direction (d: the colour's degree)
    weights: Tensor  # [num_kept] eq. 4 weights
    rays: Tensor  # [num_kept] int64 ray (low-resolution pixel) index
    opacity: Tensor  # [num_rays] sum of all weights
    size: tuple[int, int]  # low-resolution (height, width)

    @property
    def nbytes(self) -> int:
        """Memory held by its tensors."""
        tensors = (self.positions, self.basis, self.weights, self.rays, self.opacity)
        return sum(t.numel() * t.element_size() for t in tensors)


class _GridRead(torch.autograd.Function):
    """``read_rows`` whose backward adds ``w * grad`` into the eight corner rows of each
    point of ``target`` (the grid's ``.grad``) in place, corner by corner, and returns no
    gradient for the grid itself.

    Autograd's own path (``F.embedding_bag``'s dense backward, or the channel-major reads
    it replaces) builds a zero gradient the size of the whole grid (tens of MB of fresh
    pages) at every step and adds it to ``.grad``, which at small sizes dominates a step."""

    @staticmethod
    def forward(ctx, grid: Tensor, index: Tensor, weights: Tensor, target: Tensor) -> Tensor:
        ctx.save_for_backward(index, weights)
        ctx.target = target
        return read_rows(grid, index, weights)

    @staticmethod
    def backward(ctx, grad: Tensor):
        index, weights = ctx.saved_tensors
        index = index.view(-1, 8)
        for c in range(8):
            ctx.target.index_add_(0, index[:, c], grad * weights[:, c, None])
        return None, None, None, None


class FeatureRenderer:
    """Renders views of a field through its feature grid and decoder."""

    name = "features"

    def __init__(
        self,
        model: RadianceField,
        config: FeatureConfig,
        generator: torch.Generator | None = None,
    ):
        self.model = model
        self.config = config
        nx, ny, nz = (
            max(2, math.ceil(int(c) * config.grid_scale) + 1) for c in model.occupancy.cells
        )
        # the field's colour at the grid vertices starts the first channels: a grid field's
        # SH coefficients [3, (d + 1)^2] (logits), else the colour logits
        field = model.field
        self.sh_degree = field.sh_degree if isinstance(field, GridField) else 0
        kc = (self.sh_degree + 1) ** 2
        if config.channels < 3 * kc:
            raise ValueError(
                f"channels must be >= {3 * kc} to hold the field's colour (SH degree "
                f"{self.sh_degree}), got {config.channels}"
            )
        if config.bake_density and config.channels <= 3 * kc:
            raise ValueError(
                f"bake_density needs channels > {3 * kc} (a channel beside the colour's), "
                f"got {config.channels}"
            )
        self.grid_shape = (nz, ny, nx)
        # the field baked at the grid's vertices: its colour, and its opacity when asked
        coef, opacity = bake_field(model, self.grid_shape)
        grid = torch.zeros(nz * ny * nx, config.channels)
        grid[:, : 3 * kc] = coef
        if config.bake_density:
            grid[:, 3 * kc] = opacity
        self.grid = nn.Parameter(grid)
        """The feature grid, vertex-major: [num_vertices, K], vertices in (z, y, x) order."""
        bg = torch.zeros(config.channels)
        bg[0 : 3 * kc : kc] = torch.logit(model.background.clamp(1e-3, 1 - 1e-3))
        self.background = nn.Parameter(bg)
        # decoder input: the view-dependent colour logits, the K planes, the opacity
        self.decoder = FeatureDecoder(
            config.channels + 3,
            config.downsample,
            config.hidden_channels,
            generator,
            colour_input=config.sample_colour,
        )

    def settings(self) -> dict:
        return {"renderer": self.name, **self.config.as_dict()}

    def low_res_pass(self, pose: Tensor, intrinsics: Intrinsics) -> LowResPass:
        """Eq. 4 weights of the low-resolution view at the coarse step; samples below the
        weight threshold dropped (they still count in the opacity)."""
        return self.low_res_passes(pose[None], intrinsics)[0]

    @torch.no_grad()
    def low_res_passes(self, poses: Tensor, intrinsics: Intrinsics) -> list[LowResPass]:
        """:meth:`low_res_pass` of several views [num_views, 4, 4] at once: one sampler,
        density and weight call over all their rays (fewer, larger operations)."""
        m, cfg = self.model, self.config
        lo = low_res_intrinsics(intrinsics, cfg.downsample)
        o, d = camera_rays(poses, lo)
        o, d = o.reshape(-1, 3), d.reshape(-1, 3)
        if cfg.min_transmittance > 0:
            run = march_until_opaque(
                o,
                d,
                m.aabb,
                m.step_m * cfg.step_factor,
                m.occupancy,
                m.field.density,
                cfg.min_transmittance,
                cfg.weight_threshold,
            )
            positions, w, rays, opacity = run.positions, run.weights, run.rays, run.opacity
        else:
            s = sample_along_rays(o, d, m.aabb, m.step_m * cfg.step_factor, m.occupancy)
            sigma = m.field.density(s.positions) if s.t.numel() else s.t
            w, _ = packed_weights(sigma, s.deltas, s.ray_indices, o.shape[0])
            opacity = packed_sum(w, s.ray_indices, o.shape[0])
            keep = (w > cfg.weight_threshold).nonzero()[:, 0]
            positions, w, rays = (x.index_select(0, keep) for x in (s.positions, w, s.ray_indices))
        basis = sh_basis(d, self.sh_degree)
        n = lo.height * lo.width
        # samples come ray by ray, so each view's are one contiguous run
        ends = torch.searchsorted(rays, torch.arange(1, poses.shape[0] + 1) * n).tolist()
        sizes = [b - a for a, b in zip([0, *ends[:-1]], ends)]
        return [
            LowResPass(p, bs, ws, rs - v * n, op, (lo.height, lo.width))
            for v, (p, ws, rs, bs, op) in enumerate(
                zip(
                    positions.split(sizes),
                    w.split(sizes),
                    rays.split(sizes),
                    basis.split(n),
                    opacity.split(n),
                )
            )
        ]

    def read(self, positions: Tensor) -> Tensor:
        """The feature grid at world points [n, 3] -> [n, K] (trilinear): one
        ``F.embedding_bag`` over the vertex-major grid (:func:`~renderer.fields.read_rows`).
        With gradients enabled, backward adds into ``grid.grad`` in place (:class:`_GridRead`;
        created at the first read): zero it between steps, not set it to None."""
        index, weights = trilinear_corners(self.model.aabb, self.grid_shape, positions)
        if torch.is_grad_enabled() and self.grid.requires_grad:
            if self.grid.grad is None:
                self.grid.grad = torch.zeros_like(self.grid)
            return _GridRead.apply(self.grid, index, weights, self.grid.grad)
        return read_rows(self.grid.detach(), index, weights)

    def features(self, p: LowResPass, values: Tensor | None = None) -> Tensor:
        """[1, K + 1, h, w]: the composited feature planes (background where transparent)
        and the opacity. ``values``: the grid read at ``p.positions`` [num_kept, K] when
        already done (:meth:`decode` reads a batch's samples at once)."""
        k = self.config.channels
        if values is None:
            values = self.read(p.positions)  # [num_kept, K]
        img = packed_sum(p.weights[:, None] * values, p.rays, p.opacity.shape[0])
        img = img + (1.0 - p.opacity)[:, None] * self.background
        h, w = p.size
        return torch.cat([img, p.opacity[:, None]], 1).t().reshape(1, k + 1, h, w)

    def planes(self, p: LowResPass, values: Tensor | None = None) -> Tensor:
        """[1, 3 + K + 1, h, w]: the decoder's input, the colour seen along each pixel's ray,
        then :meth:`features`. The colour is the composited SH coefficients times the ray's
        basis (logits: the ray's direction is the same at all its samples, so this equals
        compositing the view-dependent logits sample by sample), or with
        ``config.sample_colour`` the composite of each sample's colour (the sigmoid of its
        logits; the background's colour where transparent), as the field renders it."""
        if values is None:
            values = self.read(p.positions)
        f = self.features(p, values)
        kc = p.basis.shape[1]
        h, w = p.size
        if self.config.sample_colour:
            coef = values[:, : 3 * kc].reshape(-1, 3, kc)
            rgb = torch.sigmoid((coef * p.basis.index_select(0, p.rays)[:, None]).sum(-1))
            colour = packed_sum(p.weights[:, None] * rgb, p.rays, p.opacity.shape[0])
            bg = torch.sigmoid(self.background[0 : 3 * kc : kc])
            colour = (colour + (1.0 - p.opacity)[:, None] * bg).t().reshape(1, 3, h, w)
            return torch.cat([colour, f], 1)
        coef = f[0, : 3 * kc].reshape(3, kc, h * w)
        colour = (coef * p.basis.t()[None]).sum(1).reshape(1, 3, h, w)
        return torch.cat([colour, f], 1)

    def decode(self, passes: list[LowResPass], height: int, width: int) -> Tensor:
        """[num_views, height, width, 3] from low-resolution passes of one size."""
        # one read for the whole batch: one gradient of the grid, not one per view
        values = self.read(torch.cat([p.positions for p in passes]))
        parts = values.split([p.positions.shape[0] for p in passes])
        x = torch.cat([self.planes(p, v) for p, v in zip(passes, parts)])
        return self.decoder(x)[:, :, :height, :width].permute(0, 2, 3, 1)

    @torch.no_grad()
    def refine_mask(self, passes: list[LowResPass], rgb: Tensor) -> Tensor | None:
        """The pixels [num_views, height, width] of ``rgb`` (decoded from ``passes``) that
        :meth:`refine` renders again, or None when refinement is off."""
        cfg = self.config
        if not cfg.refine_partial > 0 and not cfg.refine_contrast < 1:
            return None
        opacity = torch.stack([p.opacity.reshape(p.size) for p in passes])
        return edge_mask(opacity, rgb, cfg.downsample, cfg.refine_partial, cfg.refine_contrast)

    @torch.no_grad()
    def refine(
        self, passes: list[LowResPass], poses: Tensor, intrinsics: Intrinsics, rgb: Tensor
    ) -> Tensor:
        """``rgb`` [num_views, height, width, 3] decoded from ``passes`` with the pixels of
        :func:`~renderer.refine.edge_mask` (``config.refine_partial``,
        ``config.refine_contrast``) rendered again by the field itself at full resolution
        (:func:`~renderer.refine.field_colours`, each ray ended at
        ``config.refine_min_transmittance``); unchanged when both are off."""
        mask = self.refine_mask(passes, rgb)
        if mask is None:
            return rgb
        mt = self.config.refine_min_transmittance
        out = rgb.clone()
        rays = masked_rays(poses, intrinsics, mask)
        out[mask] = field_colours(self.model, *rays, min_transmittance=mt, weight_threshold=mt / 10)
        return out

    @torch.no_grad()
    def render_path(self, poses: Tensor, intrinsics: Intrinsics) -> dict:
        """{"rgb": [num_views, height, width, 3] float32, "seconds_per_view": float}."""
        t0 = time.perf_counter()
        b = self.config.render_batch
        out = []
        for i in range(0, poses.shape[0], b):
            passes = self.low_res_passes(poses[i : i + b], intrinsics)
            rgb = self.decode(passes, intrinsics.height, intrinsics.width)
            out.append(self.refine(passes, poses[i : i + b], intrinsics, rgb))
        seconds = (time.perf_counter() - t0) / max(poses.shape[0], 1)
        rgb = torch.cat(out) if out else torch.zeros(0, intrinsics.height, intrinsics.width, 3)
        return {"rgb": rgb.clamp(0, 1), "seconds_per_view": seconds}

"""The lightweight renderer (the paper's §3.3, eq. 5): a learned feature field and a decoder.

A trained radiance field keeps its density; a grid of ``K`` feature channels over the same
box replaces its colour. A view is volume-rendered at ``1 / downsample`` resolution with
the field's own weights (eq. 4, coarser marching step), but only the samples that carry
weight look up features, and a small convolutional decoder maps the ``K`` feature planes
plus opacity to the full-resolution image (sub-pixel shuffle). The feature grid and the
decoder are distilled from the field itself: teacher renders at full resolution of the
training cameras and of jittered copies of them (no images are needed). The teachers are
streamed through a :class:`TeacherPool` of bounded size, so setup memory does not grow
with the number of teachers or, beyond the pool, with the image size.

The first ``3 (d + 1)^2`` channels start as the field's colour coefficients (SH degree d)
and stay view-dependent: the ray's direction is the same at every sample, so compositing
the coefficients and applying each pixel's SH basis afterwards equals compositing the
view-dependent colour sample by sample. The other channels are free features.

The grid is stored vertex-major and read with one ``F.embedding_bag`` per batch
(:func:`~renderer.fields.read_rows`); its gradient is added into the eight corner rows of
each sample in place (:class:`_GridRead`). Measurements of speed and fidelity against the
full render are in the README ("The renderer") and ``python -m benchmarks renderer``.
"""

from __future__ import annotations

import math
import sys
import time
from dataclasses import asdict, dataclass

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from common import trim_heap
from renderer.cameras import Intrinsics, camera_rays, look_at, rotate_pose_about
from renderer.dataset import Dataset
from renderer.fields import (
    GridField,
    read_rows,
    sh_basis,
    trilinear,
    trilinear_corners,
)
from renderer.model import RadianceField, render_views
from renderer.sampler import sample_along_rays
from renderer.train import settings_for_size
from renderer.volume import packed_sum, packed_weights


@dataclass(frozen=True)
class FeatureConfig:
    """How the feature renderer renders and trains."""

    channels: int = 16
    """K: feature channels of the grid, >= 3 (the first ``3 (d + 1)^2`` start as the colour
    coefficients of a grid field of SH degree d, and stay view-dependent; a vanilla MLP
    field's colour logits start the first three)."""
    downsample: int = 2
    """Low-resolution factor per axis, >= 1 (the decoder upsamples by sub-pixel shuffle)."""
    step_factor: float = 1.75
    """Marching step of the low-resolution pass relative to the field's own, >= 1 (a
    coarser step misses thin parts that no feature can bring back)."""
    weight_threshold: float = 1e-3
    """Samples whose volume-rendering weight is below this skip the feature lookup, in [0, 1)."""
    hidden_channels: int = 32
    """Width of the decoder, >= 1."""
    extra_views: int = 3900
    """Jittered copies of the training cameras rendered as extra teachers, >= 0: the
    largest lever on unseen views, given the steps to use them; each costs one full
    render."""
    jitter_deg: float = 17.0
    """Largest turn of a jittered camera about the scene's up axis (and half of it about a
    horizontal axis), degrees, > 0."""
    train_seconds: float = 3600.0
    """Training budget (s) after the first ``pool_views`` teacher renders, > 0; the later
    teachers are rendered within it. With ``train_steps`` it is only a cap."""
    train_steps: int | None = 3000
    """Optimiser steps (>= 1), or None to train for ``train_seconds``. When given, the
    steps drive the teacher schedule: the same work on a busy machine as on an idle one."""
    pool_views: int = 256
    """Teacher renders held in memory at once (8-bit), >= 1. Teachers beyond the pool are
    rendered while training, evenly over the first 80 % of the budget, each replacing the
    oldest; the low-resolution pass of a training view is recomputed at each step. Setup
    memory is therefore bounded at any size: ``pool_views * height * width * 3`` bytes of
    teachers (400 px: 123 MB), ``pass_cache_mb``, the feature grid and one batch."""
    batch_size: int = 4
    """Views per optimiser step, >= 1."""
    width_px: int | None = None
    """Width of the teacher renders (the cameras' intrinsics scaled to it, aspect kept), or
    None for the cameras' own: the size the renderer will be used at, >= 8."""
    pass_cache_mb: int = 512
    """Memory (MB) for keeping the held teachers' low-resolution passes instead of
    recomputing one whenever its teacher is drawn, >= 0; part of the setup bound."""
    grid_scale: float = 1.0
    """Vertices of the feature grid per axis relative to the field's occupancy cells
    (``ceil(cells * grid_scale) + 1``), in (0, 1]: a coarser grid costs proportionally less
    per step (its gradient and Adam update touch every vertex) where the views have fewer
    pixels than the field has cells."""
    grid_lr: float = 0.1
    """Adam learning rate of the feature grid, > 0."""
    decoder_lr: float = 3e-3
    """Adam learning rate of the decoder, > 0 (constant, as is the grid's)."""
    render_batch: int = 8
    """Views of a path rendered together (one sampler, density, feature read and decoder
    call), >= 1: the same images, fewer and larger operations."""
    progress: bool = True
    """Progress bar on stderr."""

    def __post_init__(self):
        for name, low in (
            ("channels", 3),
            ("render_batch", 1),
            ("downsample", 1),
            ("hidden_channels", 1),
            ("batch_size", 1),
            ("extra_views", 0),
            ("pool_views", 1),
            ("pass_cache_mb", 0),
        ):
            if getattr(self, name) < low:
                raise ValueError(f"{name} must be >= {low}, got {getattr(self, name)}")
        if self.width_px is not None and self.width_px < 8:
            raise ValueError(f"width_px must be >= 8 or None, got {self.width_px}")
        if self.train_steps is not None and self.train_steps < 1:
            raise ValueError(f"train_steps must be >= 1 or None, got {self.train_steps}")
        if not 0 < self.grid_scale <= 1:
            raise ValueError(f"grid_scale must be in (0, 1], got {self.grid_scale}")
        if not self.step_factor >= 1:
            raise ValueError(f"step_factor must be >= 1, got {self.step_factor}")
        if not 0 <= self.weight_threshold < 1:
            raise ValueError(f"weight_threshold must be in [0, 1), got {self.weight_threshold}")
        for name in ("jitter_deg", "train_seconds", "grid_lr", "decoder_lr"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)}")

    def as_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def for_resolution(cls, size_px: int, /, **overrides) -> FeatureConfig:
        """The settings for views ``size_px`` wide (:data:`FEATURES_BY_SIZE`: the row of the
        largest size not above it), then ``overrides``. Teacher renders cost the square of
        the size, so larger views get fewer teachers; from 300 px the low-resolution pass
        is a third of the width and the feature grid three quarters of the field's."""
        return cls(**{**settings_for_size(FEATURES_BY_SIZE, size_px), **overrides})


FEATURES_BY_SIZE: dict[int, dict] = {
    0: {},
    150: {"train_steps": 8000},
    300: {
        "extra_views": 1500,
        "downsample": 3,
        "grid_scale": 0.75,
        "pass_cache_mb": 256,
        "train_seconds": 7200.0,
    },
}
"""Smallest image width (px) -> :class:`FeatureConfig` settings that differ from the
defaults (:meth:`FeatureConfig.for_resolution`): from 150 px more steps for the finer
detail; from 300 px fewer teachers (each a full render at that size), a third-width
pass, a feature grid at three quarters of the field's vertices per axis and half the pass
cache (beside the cache, the grid with its gradient and two Adam moments dominates setup
memory at these sizes), and a higher time cap for its slower steps. Measured on lego's
test path (README, "The renderer")."""


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
    zero (its start) it is the bilinear upsampling of the colour logits."""

    def __init__(self, channels: int, downsample: int, hidden: int = 32):
        super().__init__()
        self.downsample = downsample
        self.body = nn.Sequential(
            nn.Conv2d(channels + 1, hidden, 3, padding=1),
            nn.LeakyReLU(0.1),
            nn.Conv2d(hidden, hidden, 3, padding=1),
            nn.LeakyReLU(0.1),
        )
        self.out = nn.Conv2d(hidden, 3 * downsample * downsample, 3, padding=1)
        nn.init.zeros_(self.out.weight)
        nn.init.zeros_(self.out.bias)
        # channels-last convolutions: the same results as channels-first, in the layout
        # CPU convolution kernels at these widths run fastest (forward and backward)
        self.to(memory_format=torch.channels_last)

    def forward(self, x: Tensor) -> Tensor:
        s = self.downsample
        x = x.contiguous(memory_format=torch.channels_last)
        base = F.interpolate(x[:, :3], scale_factor=s, mode="bilinear", align_corners=False)
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

    def __init__(self, model: RadianceField, config: FeatureConfig):
        self.model = model
        self.config = config
        aabb = model.aabb
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
        axes = [
            torch.linspace(float(aabb[0, a]), float(aabb[1, a]), n)
            for a, n in enumerate((nx, ny, nz))
        ]
        zz, yy, xx = torch.meshgrid(axes[2], axes[1], axes[0], indexing="ij")
        points = torch.stack([xx, yy, zz], -1).reshape(-1, 3)
        with torch.no_grad():
            if isinstance(field, GridField):
                coef = torch.cat(
                    [trilinear(field.color_grid, field.aabb, p) for p in points.split(65536)]
                )
            else:
                rgb = torch.cat([field(p, None)[1] for p in points.split(65536)])
                coef = torch.logit(rgb.clamp(1e-3, 1 - 1e-3))
        self.grid_shape = (nz, ny, nx)
        grid = torch.zeros(nz * ny * nx, config.channels)
        grid[:, : 3 * kc] = coef
        self.grid = nn.Parameter(grid)
        """The feature grid, vertex-major: [num_vertices, K], vertices in (z, y, x) order."""
        bg = torch.zeros(config.channels)
        bg[0 : 3 * kc : kc] = torch.logit(model.background.clamp(1e-3, 1 - 1e-3))
        self.background = nn.Parameter(bg)
        # decoder input: the view-dependent colour logits, the K planes, the opacity
        self.decoder = FeatureDecoder(
            config.channels + 3, config.downsample, config.hidden_channels
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
        """[1, 3 + K + 1, h, w]: the decoder's input, the colour logits seen along each
        pixel's ray (the composited SH coefficients times the ray's basis: the ray's
        direction is the same at all its samples, so this equals compositing the
        view-dependent colour sample by sample), then :meth:`features`."""
        f = self.features(p, values)
        kc = p.basis.shape[1]
        h, w = p.size
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
    def render_path(self, poses: Tensor, intrinsics: Intrinsics) -> dict:
        """{"rgb": [num_views, height, width, 3] float32, "seconds_per_view": float}."""
        t0 = time.perf_counter()
        b = self.config.render_batch
        out = [
            self.decode(
                self.low_res_passes(poses[i : i + b], intrinsics),
                intrinsics.height,
                intrinsics.width,
            )
            for i in range(0, poses.shape[0], b)
        ]
        seconds = (time.perf_counter() - t0) / max(poses.shape[0], 1)
        rgb = torch.cat(out) if out else torch.zeros(0, intrinsics.height, intrinsics.width, 3)
        return {"rgb": rgb.clamp(0, 1), "seconds_per_view": seconds}


def scene_up_and_center(model: RadianceField, poses: Tensor) -> tuple[Tensor, Tensor]:
    """World up (mean of the cameras' up axes) and the scene box centre: ([3], [3])."""
    up = F.normalize(poses[:, :3, 1].float().mean(0), dim=0)
    return up, model.aabb.mean(0)


def stored_cameras(model: RadianceField, num_views: int = 64) -> tuple[Tensor, Intrinsics]:
    """Training-like cameras from what the field stores (``model.spec["camera"]``): its
    training poses when stored, else ``num_views`` cameras at the mean training distance
    from the centre, at elevations 10-60 degrees above the horizon (golden-angle spiral).

    Returns:
        (poses [num_views, 4, 4], intrinsics).
    """
    cam = model.spec.get("camera")
    if not cam:
        raise ValueError("the field stores no cameras (spec['camera']); pass a dataset")
    k = cam["intrinsics"]
    intr = Intrinsics(k["fl_x"], k["fl_y"], k["cx"], k["cy"], int(k["h"]), int(k["w"]))
    if cam.get("poses"):
        return torch.tensor(cam["poses"], dtype=torch.float32), intr
    center, up = torch.tensor(cam["center"]), F.normalize(torch.tensor(cam["up"]), dim=0)
    seed = torch.tensor([1.0, 0.0, 0.0]) if abs(up[0]) < 0.9 else torch.tensor([0.0, 1.0, 0.0])
    e1 = F.normalize(seed - (seed @ up) * up, dim=0)
    e2 = torch.linalg.cross(up, e1)
    poses = []
    for i in range(num_views):
        az = i * math.pi * (3.0 - math.sqrt(5.0))
        el = math.radians(10.0 + 50.0 * (i + 0.5) / num_views)
        eye = center + cam["radius_m"] * (
            math.cos(el) * (math.cos(az) * e1 + math.sin(az) * e2) + math.sin(el) * up
        )
        poses.append(look_at(eye, center, up))
    return torch.stack(poses), intr


def jittered_poses(
    poses: Tensor, up: Tensor, center: Tensor, count: int, max_deg: float, generator
) -> Tensor:
    """``count`` copies of ``poses`` (cycled) turned by up to +-``max_deg`` about the up axis
    through ``center`` and +-``max_deg / 2`` about the horizontal axis facing the camera:
    [count, 4, 4]."""
    out = []
    for j in range(count):
        p = poses[j % poses.shape[0]]
        a, b = ((torch.rand(2, generator=generator) * 2 - 1) * math.radians(max_deg)).tolist()
        p = rotate_pose_about(p, center, up, a)
        side = torch.linalg.cross(up, p[:3, 3] - center)
        if float(side.norm()) > 1e-6:
            p = rotate_pose_about(p, center, side, b / 2)
        out.append(p)
    return torch.stack(out) if out else poses.new_zeros(0, 4, 4)


PASS_BATCH_VIEWS = 8
"""Views whose low-resolution passes :class:`TeacherPool` computes in one call."""


class TeacherPool:
    """Teacher renders (8-bit) of a list of cameras, at most ``capacity`` held at once:
    :meth:`render_next` renders the next ``count`` cameras, each replacing the oldest.

    With ``passes`` (``poses -> [LowResPass]``) the low-resolution pass of each held camera
    is kept beside its image while their total stays under ``pass_bytes``; the others are
    recomputed when drawn (:meth:`passes_of`)."""

    def __init__(
        self,
        model: RadianceField,
        poses: Tensor,
        intrinsics: Intrinsics,
        capacity: int,
        passes=None,
        pass_bytes: int = 0,
    ):
        self.model, self.poses, self.intrinsics = model, poses, intrinsics
        self.capacity = max(1, min(capacity, poses.shape[0]))
        self.images = torch.zeros(
            self.capacity, intrinsics.height, intrinsics.width, 3, dtype=torch.uint8
        )
        self.index = torch.zeros(self.capacity, dtype=torch.long)  # camera of each slot
        self.rendered = 0  # cameras rendered so far
        self._passes_fn, self._pass_bytes = passes, pass_bytes
        self._passes: dict[int, LowResPass] = {}  # slot -> its camera's pass
        self._held_bytes = 0

    @property
    def held(self) -> int:
        return min(self.rendered, self.capacity)

    @property
    def remaining(self) -> int:
        return self.poses.shape[0] - self.rendered

    @torch.no_grad()
    def render_next(self, count: int) -> None:
        count = min(count, self.remaining)
        if count <= 0:
            return
        cams = torch.arange(self.rendered, self.rendered + count)
        rgb = render_views(self.model, self.poses[cams], self.intrinsics)["rgb"]
        slots = cams % self.capacity
        self.images[slots] = (rgb.clamp(0, 1) * 255).round().to(torch.uint8)
        self.index[slots] = cams
        self.rendered += count
        for slot in slots.tolist():
            old = self._passes.pop(slot, None)
            self._held_bytes -= 0 if old is None else old.nbytes
        # passes a few views at a time, none once the budget is full: a large batch of
        # new teachers neither holds all its passes at once nor computes discarded ones
        full = self._passes_fn is None
        for start in range(0, count, PASS_BATCH_VIEWS):
            if full or self._held_bytes >= self._pass_bytes:
                break
            chunk = slice(start, start + PASS_BATCH_VIEWS)
            for slot, p in zip(slots[chunk].tolist(), self._passes_fn(self.poses[cams[chunk]])):
                if self._held_bytes + p.nbytes > self._pass_bytes:
                    full = True
                    break
                self._passes[slot] = p
                self._held_bytes += p.nbytes

    def sample(self, count: int, generator: torch.Generator) -> Tensor:
        """``count`` slots [count] drawn uniformly from the held teachers."""
        return torch.randint(self.held, (count,), generator=generator)

    def poses_of(self, slots: Tensor) -> Tensor:
        return self.poses[self.index[slots]]

    def images_of(self, slots: Tensor) -> Tensor:
        """[len(slots), height, width, 3] float in [0, 1]."""
        return self.images[slots].float() / 255.0

    def passes_of(self, slots: Tensor) -> list[LowResPass]:
        """The slots' low-resolution passes: kept ones, the rest computed together."""
        slots = slots.tolist()
        missing = [s for s in slots if s not in self._passes]
        fresh = {}
        if missing:
            computed = self._passes_fn(self.poses[self.index[torch.tensor(missing)]])
            fresh = dict(zip(missing, computed))
        return [self._passes[s] if s in self._passes else fresh[s] for s in slots]


TRIM_EVERY_STEPS = 100
"""Distillation steps between heap trims (:func:`common.trim_heap`): the freed temporaries
of steps and teacher renders stay bounded, at a page fault per reused page a hundred steps
apart."""


def train_features(
    model: RadianceField,
    dataset: Dataset | None = None,
    config: FeatureConfig | None = None,
    generator: torch.Generator | None = None,
) -> tuple[FeatureRenderer, dict]:
    """Distil the feature grid and decoder from the field's own full-resolution renders of
    ``dataset``'s cameras (None: the cameras the field stores) and of jittered copies
    (streamed through a :class:`TeacherPool` of ``config.pool_views``).

    Returns:
        (renderer, stats {"teacher_views", "teacher_size" ([height, width]),
        "teacher_seconds" (the first pool's renders),
        "train_seconds" (the training, later teachers included), "cpu_seconds" (this
        process's CPU time for all of it), "steps", "final_loss", "capped_by_seconds"
        (``train_seconds`` ended the training before ``train_steps``; also said on stderr)}).
    """
    config = config or FeatureConfig()
    generator = generator or torch.Generator().manual_seed(0)
    cpu0 = time.process_time()
    if dataset is None:
        poses, intr = stored_cameras(model)
    else:
        poses, intr = dataset.poses, dataset.intrinsics
    if config.width_px is not None and config.width_px != intr.width:
        intr = intr.resized(
            max(1, round(intr.height * config.width_px / intr.width)), config.width_px
        )
    up, center = scene_up_and_center(model, poses)
    t0 = time.perf_counter()
    poses = torch.cat(
        [poses, jittered_poses(poses, up, center, config.extra_views, config.jitter_deg, generator)]
    )
    rend = FeatureRenderer(model, config)
    trim_heap()  # filling the grid chunk by chunk leaves far more than the grid freed
    pool = TeacherPool(
        model,
        poses,
        intr,
        config.pool_views,
        passes=lambda p: rend.low_res_passes(p, intr),
        pass_bytes=config.pass_cache_mb << 20,
    )
    bar = _setup_bar(config)
    while pool.held < pool.capacity:
        pool.render_next(min(config.render_batch, pool.capacity - pool.held))
        _show(bar, pool, 0.0, None, 0)
    teacher_seconds = time.perf_counter() - t0
    trim_heap()
    opt = torch.optim.Adam(
        [
            {"params": [rend.grid, rend.background], "lr": config.grid_lr},
            {"params": list(rend.decoder.parameters()), "lr": config.decoder_lr},
        ],
        fused=True,  # one pass over the grid per step, not one per Adam operation
    )
    first = pool.rendered
    steps, loss = 0, float("nan")
    t0 = time.perf_counter()
    while (frac := _progress(config, steps, time.perf_counter() - t0)) < 1.0:
        due = first + math.ceil((poses.shape[0] - first) * min(frac / 0.8, 1.0))
        if due > pool.rendered:
            pool.render_next(max(due - pool.rendered, config.render_batch))
        slots = pool.sample(config.batch_size, generator)
        out = rend.decode(pool.passes_of(slots), intr.height, intr.width)
        err = F.mse_loss(out, pool.images_of(slots))
        opt.zero_grad(set_to_none=False)  # the grid's reads add into its .grad in place
        err.backward()
        opt.step()
        steps, loss = steps + 1, float(err.detach())
        if steps % TRIM_EVERY_STEPS == 0:
            trim_heap()
        _show(bar, pool, frac, loss, steps)
    if bar is not None:
        bar.close()
    stats = {
        "teacher_views": int(pool.rendered),
        "teacher_size": [intr.height, intr.width],
        "teacher_seconds": teacher_seconds,
        "train_seconds": time.perf_counter() - t0,
        "cpu_seconds": time.process_time() - cpu0,
        "steps": steps,
        "final_loss": loss,
        "capped_by_seconds": config.train_steps is not None and steps < config.train_steps,
    }
    if stats["capped_by_seconds"]:
        print(
            f"features setup: train_seconds ({config.train_seconds:g} s) reached after {steps}"
            f" of {config.train_steps} steps",
            file=sys.stderr,
        )
    return rend, stats


def _progress(config: FeatureConfig, steps: int, seconds: float) -> float:
    """Fraction of the training budget used: by steps when given (seconds then cap it)."""
    frac = seconds / config.train_seconds
    if config.train_steps is not None:
        frac = max(frac, steps / config.train_steps)
    return frac


def _setup_bar(config: FeatureConfig):
    """Percent of the training budget, with teachers rendered, steps and loss."""
    if not config.progress:
        return None
    from tqdm import tqdm

    return tqdm(total=100, desc="features setup", unit="%", file=sys.stderr)


def _show(bar, pool: TeacherPool, frac: float, loss: float | None, steps: int) -> None:
    if bar is None:
        return
    post = {"teachers": f"{pool.rendered}/{pool.poses.shape[0]}", "step": steps}
    if loss is not None:
        post["loss"] = f"{loss:.5f}"
    bar.set_postfix(post, refresh=False)
    bar.update(min(int(100 * frac), 100) - bar.n)  # redraws at most every mininterval

"""Training a radiance field on posed views within a wall-clock (or CPU) budget.

How the defaults of :class:`TrainConfig` were chosen, with the measurements: README,
"Why the defaults are what they are".
"""

from __future__ import annotations

import math
import sys
import time
from dataclasses import asdict, dataclass

import torch
from torch import Tensor

from renderer.cameras import camera_rays
from renderer.dataset import Dataset
from renderer.fields import GridField, MLPField
from renderer.metrics import image_metrics
from renderer.model import RadianceField, render_views
from renderer.sampler import OccupancyGrid

FIELDS = ("grid", "mlp")
CLOCKS = ("wall", "cpu")


@dataclass(frozen=True)
class TrainConfig:
    """How to train. ``max_seconds`` counts optimisation only (not curve evaluations)."""

    field: str = "grid"
    """"grid" (dense voxel grids, the fast field) or "mlp" (vanilla NeRF)."""
    max_seconds: float = 120.0
    """Wall-clock training budget (s), > 0."""
    clock: str = "wall"
    """What the budget and curve count: "wall" (perf_counter seconds) or "cpu" (this
    process's CPU seconds divided by torch's thread count: the wall time the same work
    would take on otherwise idle cores; use it on a shared machine)."""
    max_steps: int | None = None
    """Optional number of optimiser steps (>= 1). When given, the steps drive the schedule
    (coarse-to-fine stages, learning rate) and ``max_seconds`` is only a cap: a run that
    ends by steps does the same work on a busy machine as on an idle one."""
    grid_resolutions: tuple[int, ...] = (48, 96, 128)
    """Grid vertices on the longest axis per coarse-to-fine stage (grid field)."""
    stage_starts: tuple[float, ...] = (0.0, 0.12, 0.35)
    """Fraction of the budget at which each stage starts (first must be 0, increasing)."""
    step_voxels: float = 0.85
    """Ray-marching step in voxels of the current stage (grid field), > 0."""
    batch_rays: int = 2048
    """Rays per optimiser step (grid field; the first stage uses half), >= 1. Most rays of
    an object scene see only carved space and cost nothing; within a time budget more
    steps beat bigger ones."""
    lr: float = 0.2
    """Adam learning rate on the grids (decays exponentially to lr_final_ratio * lr)."""
    lr_final_ratio: float = 0.1
    """Learning rate at the end of the budget relative to the start, in (0, 1]."""
    tv_weight: float = 0.0
    """Weight of the density total-variation term in the last stage (>= 0). Off by
    default: it cost PSNR on clean and on noisy views alike."""
    occupancy_every_steps: int = 50
    """Steps between occupancy-grid updates, >= 1."""
    occupancy_warmup_steps: int = 20
    """Steps before the first occupancy update (all cells live until then), >= 0."""
    alpha_init: float = 1e-2
    """Initial alpha of every grid sample at the first stage's step (DVGO), in (0, 1).
    Smaller values leave less fog in unseen space but grow surfaces more slowly."""
    occupancy_threshold: float = 1e-3
    """Alpha below which a cell is empty, in (0, 1)."""
    carve: bool = True
    """When the dataset has masks, mark empty every cell some view sees against the
    background (the visual hull) at each coarse-to-fine stage: no fog in space the views
    show empty, so each step samples only near the object."""
    crop: bool = True
    """Grid field: at the first step (after carving) and at each stage change, shrink the
    grids to the box around the occupied cells (2 cells of margin) at the stage's voxel
    size. Nothing outside that box can be occupied, and every step's cost in the dense
    parts (gradients, Adam, total variation) scales with the grids' size."""
    sh_degree: int = 1
    """Grid field: spherical-harmonics degree of the colour (0 diffuse, 1 or 2
    view-dependent), added at stage ``sh_stage``; degree 2 has more channels and so takes
    fewer steps in the same time than degree 1, for no gain."""
    sh_stage: int = -1
    """Coarse-to-fine stage (index into grid_resolutions; negative counts from the end)
    from which the colour is view-dependent."""
    mlp_width: int = 128
    """Hidden width of the vanilla NeRF MLP."""
    mlp_depth: int = 4
    """Hidden layers of the vanilla NeRF MLP."""
    mlp_lr: float = 2e-3
    """Adam learning rate of the MLP."""
    mlp_batch_rays: int = 1024
    """Rays per step for the MLP."""
    mlp_step_voxels: float = 1.0
    """MLP ray-marching step in cells of a 96-cell occupancy grid."""
    use_masks: bool = True
    """When the dataset has masks, train on targets with the background outside the mask
    (object-only training)."""
    eval_every_seconds: float = 10.0
    """Training seconds between points of the PSNR curve (needs ``eval_dataset``), > 0."""
    eval_every_steps: int | None = None
    """Steps between points of the curve instead (>= 1), e.g. with ``max_steps``."""
    eval_views: int = 10
    """Views of ``eval_dataset`` (evenly spaced) used for the curve, >= 1."""
    progress: bool = True
    """Progress bar on stderr."""

    def __post_init__(self):
        if self.field not in FIELDS:
            raise KeyError(f"unknown field {self.field!r}; known: {list(FIELDS)}")
        if self.clock not in CLOCKS:
            raise KeyError(f"unknown clock {self.clock!r}; known: {list(CLOCKS)}")
        if not (self.max_seconds > 0 and math.isfinite(self.max_seconds)):
            raise ValueError(f"max_seconds must be > 0 and finite, got {self.max_seconds}")
        if self.max_steps is not None and self.max_steps < 1:
            raise ValueError(f"max_steps must be >= 1 or None, got {self.max_steps}")
        if self.eval_every_steps is not None and self.eval_every_steps < 1:
            raise ValueError(f"eval_every_steps must be >= 1 or None, got {self.eval_every_steps}")
        if len(self.grid_resolutions) != len(self.stage_starts) or not self.grid_resolutions:
            raise ValueError("grid_resolutions and stage_starts must be non-empty and equally long")
        if self.stage_starts[0] != 0.0 or list(self.stage_starts) != sorted(self.stage_starts):
            raise ValueError(f"stage_starts must start at 0 and increase, got {self.stage_starts}")
        if min(self.grid_resolutions) < 2:
            raise ValueError(f"grid_resolutions must be >= 2, got {self.grid_resolutions}")
        for name in ("step_voxels", "lr", "mlp_lr", "eval_every_seconds", "mlp_step_voxels"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)}")
        for name in ("batch_rays", "mlp_batch_rays", "occupancy_every_steps", "eval_views"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be >= 1, got {getattr(self, name)}")
        if not 0 < self.lr_final_ratio <= 1:
            raise ValueError(f"lr_final_ratio must be in (0, 1], got {self.lr_final_ratio}")
        if self.tv_weight < 0:
            raise ValueError(f"tv_weight must be >= 0, got {self.tv_weight}")
        if self.sh_degree not in (0, 1, 2):
            raise ValueError(f"sh_degree must be 0, 1 or 2, got {self.sh_degree}")
        if not -len(self.grid_resolutions) <= self.sh_stage < len(self.grid_resolutions):
            raise ValueError(
                f"sh_stage must index grid_resolutions (from {-len(self.grid_resolutions)} "
                f"to {len(self.grid_resolutions) - 1}), got {self.sh_stage}"
            )
        if self.occupancy_warmup_steps < 0:
            raise ValueError(
                f"occupancy_warmup_steps must be >= 0, got {self.occupancy_warmup_steps}"
            )
        if not 0 < self.alpha_init < 1:
            raise ValueError(f"alpha_init must be in (0, 1), got {self.alpha_init}")
        if not 0 < self.occupancy_threshold < 1:
            raise ValueError(
                f"occupancy_threshold must be in (0, 1), got {self.occupancy_threshold}"
            )

    def as_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def for_resolution(cls, size_px: int, /, **overrides) -> TrainConfig:
        """The settings for views ``size_px`` wide (:data:`GRIDS_BY_SIZE`: the row of the
        largest size not above it), then ``overrides``: finer grids where the views have
        detail a 128-vertex grid cannot hold."""
        return cls(**{**settings_for_size(GRIDS_BY_SIZE, size_px), **overrides})


def settings_for_size(table: dict[int, dict], size_px: int) -> dict:
    """The row of ``table`` (smallest image width in px -> settings) for views ``size_px``
    wide: that of the largest width not above it, or {} below every row."""
    return table.get(max((s for s in table if s <= size_px), default=None), {})


GRIDS_BY_SIZE: dict[int, dict] = {
    0: {},
    300: {"grid_resolutions": (48, 128, 256), "batch_rays": 8192},
}
"""Smallest image width (px) -> :class:`TrainConfig` settings that differ from the defaults
(:meth:`TrainConfig.for_resolution`); up to 299 px the defaults (a finer grid costs more per
step, which a short budget at small sizes does not repay). More rays per step amortise the
finer grid's dense per-step work (README, "Why the defaults are what they are")."""


@dataclass
class TrainResult:
    model: RadianceField
    """The trained scene (render with :func:`renderer.render_views`)."""
    steps: int
    """Optimiser steps taken."""
    seconds: float
    """Training wall-clock seconds (without curve evaluations)."""
    curve: list[dict]
    """[{"seconds", "step", "psnr"[, "masked_psnr"]}] on the evaluation views, when an eval
    set was given ("masked_psnr" when it has masks)."""


def _voxel_m(aabb: torch.Tensor, resolution: int) -> float:
    return (aabb[1] - aabb[0]).max().item() / (resolution - 1)


def _targets(dataset: Dataset, use_masks: bool) -> torch.Tensor:
    """[num_pixels, 3] training colours: with ``use_masks``, the object on the background
    (images whose masks are their own alpha are that already: compositing them again
    would square the alpha of edge pixels)."""
    images = dataset.images
    if use_masks and dataset.masks is not None and not dataset.composited:
        bg = torch.tensor(dataset.background)
        m = dataset.masks[..., None]
        images = images * m + bg * (1 - m)
    return images.reshape(-1, 3)


def _crop_resolution(box: torch.Tensor, aabb: torch.Tensor, resolution: int) -> int:
    """Vertices on ``box``'s longest axis for the voxel size of ``resolution`` over ``aabb``."""
    return max(2, int(round((box[1] - box[0]).max().item() / _voxel_m(aabb, resolution))) + 1)


def _carve(occupancy: OccupancyGrid, dataset: Dataset, config: TrainConfig) -> None:
    if config.carve and config.use_masks and dataset.masks is not None:
        occupancy.carve(dataset.poses, dataset.intrinsics, dataset.masks)


def _move_grids(
    model: RadianceField, resolution: int, aabb: torch.Tensor, dataset: Dataset, config: TrainConfig
) -> None:
    """Resample the grid field at ``resolution`` (voxel size over ``aabb``) onto the box
    around the occupied cells (``config.crop``) or the whole box, with a new occupancy grid
    that keeps the free space already known and is carved again."""
    coarser = model.occupancy
    box = coarser.occupied_box() if config.crop else model.aabb
    model.field.resample(box, _crop_resolution(box, aabb, resolution))
    model.occupancy = OccupancyGrid.for_grid_field(model.field)
    model.occupancy.inherit_free(coarser)
    _carve(model.occupancy, dataset, config)


def _curve_subset(eval_dataset: Dataset, n: int) -> Dataset:
    idx = (
        torch.linspace(0, eval_dataset.num_views - 1, min(n, eval_dataset.num_views)).round().long()
    )
    return eval_dataset.subset(idx.unique().tolist())


def _initial_model(dataset: Dataset, config: TrainConfig) -> tuple[RadianceField, float, int]:
    """The untrained field (first coarse-to-fine stage for the grid field) with its camera
    spec for later renders; returns (model, learning rate, rays per step)."""
    aabb = dataset.aabb
    if config.field == "grid":
        res = config.grid_resolutions[0]
        step_m = config.step_voxels * _voxel_m(aabb, res)
        field_ = GridField(aabb, resolution=res, alpha_init=config.alpha_init, step_m=step_m)
        occupancy = OccupancyGrid.for_grid_field(field_)
        spec = {
            "field": "grid",
            "resolution": res,
            "step_m": step_m,
            "alpha_init": config.alpha_init,
        }
        lr, batch = config.lr, max(1, config.batch_rays // 2)
    else:
        step_m = config.mlp_step_voxels * (aabb[1] - aabb[0]).max().item() / 96
        field_ = MLPField(aabb, width=config.mlp_width, depth=config.mlp_depth)
        occupancy = OccupancyGrid(aabb, (64, 64, 64))
        spec = {"field": "mlp", "width": config.mlp_width, "depth": config.mlp_depth}
        lr, batch = config.mlp_lr, config.mlp_batch_rays
    centre = aabb.mean(0)
    spec["camera"] = {  # for default camera paths when rendering later
        "intrinsics": dataset.intrinsics.as_dict(),
        "center": centre.tolist(),
        "radius_m": (dataset.poses[:, :3, 3] - centre).norm(dim=-1).mean().item(),
        "up": torch.nn.functional.normalize(dataset.poses[:, :3, 1].mean(0), dim=0).tolist(),
        "poses": dataset.poses.tolist(),  # the lightweight renderer trains around them
    }
    return RadianceField(field_, occupancy, step_m, dataset.background, spec), lr, batch


def _progress_bar(config: TrainConfig):
    if not config.progress:
        return None
    from tqdm import tqdm

    return tqdm(
        total=int(config.max_seconds), unit="s", file=sys.stderr, desc=f"train {config.field}"
    )


def train(
    dataset: Dataset,
    config: TrainConfig = TrainConfig(),
    generator: torch.Generator | None = None,
    eval_dataset: Dataset | None = None,
) -> TrainResult:
    """Fit a radiance field to ``dataset``'s views within ``config.max_seconds``.

    Each step draws ``batch_rays`` random pixels of all training views, marches them
    through the occupancy grid, renders with eq. 4 and minimises the MSE to the pixels.
    Grid field: coarse-to-fine (``grid_resolutions`` at ``stage_starts`` of the budget,
    grids trilinearly resampled onto the box around the occupied cells, Adam reset;
    SH colour from ``sh_stage``), occupancy recomputed every
    ``occupancy_every_steps`` from the exact per-cell maxima of the density grid.

    Returns:
        :class:`TrainResult`; ``curve`` holds PSNR on (up to ``eval_views``) views of
        ``eval_dataset`` every ``eval_every_seconds`` of training and at the end.
    """
    return _Training(dataset, config, generator, eval_dataset).run()


class _Training:
    """The state of one :func:`train` call: the model, its optimiser, the schedule's
    position (stage, step, seconds) and the curve."""

    def __init__(self, dataset, config, generator, eval_dataset):
        self.dataset, self.config = dataset, config
        self.generator = generator if generator is not None else torch.Generator().manual_seed(0)
        origins, dirs = camera_rays(dataset.poses, dataset.intrinsics)
        self.origins, self.dirs = origins.reshape(-1, 3), dirs.reshape(-1, 3)
        self.targets = _targets(dataset, config.use_masks)
        self.curve_set = (
            _curve_subset(eval_dataset, config.eval_views) if eval_dataset is not None else None
        )
        self.model, self.lr, self.batch = _initial_model(dataset, config)
        self.stage, self.res = 0, config.grid_resolutions[0]
        self.sh_stage = config.sh_stage % len(config.grid_resolutions)
        if config.field == "grid" and self.sh_stage == 0:
            self.model.field.set_sh_degree(config.sh_degree)
        self.optimizer = self.make_optimizer()
        self.threads = torch.get_num_threads()
        self.curve: list[dict] = []
        self.train_seconds, self.next_eval, self.step = 0.0, 0.0, 0

    def make_optimizer(self):
        # fused: one pass over each grid per step instead of several
        return torch.optim.Adam(
            self.model.field.parameters(), lr=self.lr, betas=(0.9, 0.99), fused=True
        )

    def now(self) -> float:
        if self.config.clock == "wall":
            return time.perf_counter()
        return time.process_time() / self.threads

    def progress_fraction(self) -> float:
        """Of the schedule: by steps when ``max_steps`` is given, else by seconds."""
        if self.config.max_steps is not None:
            return self.step / self.config.max_steps
        return self.train_seconds / self.config.max_seconds

    def curve_due(self) -> bool:
        if self.config.eval_every_steps is not None:
            return self.step >= self.next_eval
        return self.train_seconds >= self.next_eval

    def record_curve(self) -> None:
        model, cs = self.model, self.curve_set
        model.eval()
        out = render_views(model, cs.poses, cs.intrinsics)
        m = image_metrics(out["rgb"], cs.images, cs.masks)
        point = {"seconds": round(self.train_seconds, 3), "step": self.step, "psnr": m["psnr"]}
        if "masked_psnr" in m:
            point["masked_psnr"] = m["masked_psnr"]
        self.curve.append(point)
        model.train()

    def schedule(self, frac: float) -> bool:
        """Carve and crop at the first step, move to the next coarse-to-fine stage when
        due; True when the grids were just upsampled."""
        config, model, aabb = self.config, self.model, self.dataset.aabb
        if self.step == 0:  # inside the timed step: carving counts against the budget
            _carve(model.occupancy, self.dataset, config)
            if config.field == "grid" and config.crop:
                _move_grids(model, self.res, aabb, self.dataset, config)
                self.optimizer = self.make_optimizer()
        if not (
            config.field == "grid"
            and self.stage + 1 < len(config.grid_resolutions)
            and frac >= config.stage_starts[self.stage + 1]
        ):
            return False
        self.stage += 1
        self.res = config.grid_resolutions[self.stage]
        _move_grids(model, self.res, aabb, self.dataset, config)
        model.step_m = config.step_voxels * _voxel_m(aabb, self.res)
        self.batch = config.batch_rays
        if self.stage == self.sh_stage:
            model.field.set_sh_degree(config.sh_degree)
        self.optimizer = self.make_optimizer()
        return True

    def optimise(self, frac: float, upsampled: bool) -> Tensor:
        """One step: learning rate, occupancy when due, a batch of rays, Adam. The loss."""
        config, model = self.config, self.model
        for g in self.optimizer.param_groups:
            g["lr"] = self.lr * config.lr_final_ratio ** min(frac, 1.0)
        if self.step >= config.occupancy_warmup_steps and (
            self.step % config.occupancy_every_steps == 0 or upsampled
        ):
            vd = model.field.vertex_density().detach() if config.field == "grid" else None
            model.occupancy.update(
                model.field.density, model.step_m, config.occupancy_threshold, vertex_density=vd
            )
        idx = torch.randint(0, self.targets.shape[0], (self.batch,), generator=self.generator)
        out = model.render_rays(
            self.origins[idx],
            self.dirs[idx],
            perturb=True,
            generator=self.generator,
            chunk=self.batch,
        )
        loss = torch.mean((out["rgb"] - self.targets[idx]) ** 2)
        if (
            config.field == "grid"
            and config.tv_weight > 0
            and self.stage == len(config.grid_resolutions) - 1
        ):
            loss = loss + config.tv_weight * model.field.total_variation()
        self.optimizer.zero_grad(set_to_none=True)
        loss.backward()
        self.optimizer.step()
        return loss

    def run(self) -> TrainResult:
        config, model = self.config, self.model
        bar = _progress_bar(config)
        while self.progress_fraction() < 1.0 and self.train_seconds < config.max_seconds:
            if self.curve_set is not None and self.curve_due():
                self.record_curve()
                self.next_eval += config.eval_every_steps or config.eval_every_seconds
            t0 = self.now()
            frac = self.progress_fraction()
            loss = self.optimise(frac, self.schedule(frac))
            self.step += 1
            self.train_seconds += self.now() - t0
            if bar is not None:
                bar.n = min(int(self.train_seconds), int(config.max_seconds))
                bar.set_postfix(
                    step=self.step,
                    loss=f"{loss.item():.4f}",
                    occ=f"{model.occupancy.fraction_occupied:.2f}",
                    refresh=False,
                )
                bar.refresh()
        if bar is not None:
            bar.close()
        if config.field == "grid":
            model.spec["resolution"] = max(model.field.resolution)
        if self.curve_set is not None:
            self.record_curve()
        model.eval()  # (record_curve switches back to training mode)
        return TrainResult(
            model=model, steps=self.step, seconds=self.train_seconds, curve=self.curve
        )


@torch.no_grad()
def evaluate(model: RadianceField, dataset: Dataset) -> dict:
    """Render every view of ``dataset`` and compare with its images.

    Returns:
        {"psnr", "ssim", "num_views", "psnr_per_view", "seconds_per_view"[, "masked_psnr"]}:
        means of per-view values (PSNR peak 1.0, SSIM scikit-image data_range=1.0).
    """
    t0 = time.perf_counter()
    out = render_views(model, dataset.poses, dataset.intrinsics)
    seconds = (time.perf_counter() - t0) / max(dataset.num_views, 1)
    m = image_metrics(out["rgb"], dataset.images, dataset.masks)
    m["seconds_per_view"] = seconds
    return m

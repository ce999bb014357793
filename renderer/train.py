"""Training a radiance field on posed views within a wall-clock (or CPU) budget
(:func:`train`), and scoring one on a dataset (:func:`evaluate`).

The configuration: :mod:`renderer.train_config`; the field it starts from and its
coarse-to-fine moves: :mod:`renderer.field_setup`.
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass

import torch
from torch import Tensor

from renderer.cameras import camera_rays
from renderer.dataset import Dataset
from renderer.field_setup import carve, initial_model, move_grids, training_targets, voxel_m
from renderer.metrics import image_metrics
from renderer.model import RadianceField, render_views
from renderer.train_config import FIELDS, TrainConfig

__all__ = ["FIELDS", "TrainConfig", "TrainResult", "evaluate", "train"]


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


def _curve_subset(eval_dataset: Dataset, n: int) -> Dataset:
    idx = (
        torch.linspace(0, eval_dataset.num_views - 1, min(n, eval_dataset.num_views)).round().long()
    )
    return eval_dataset.subset(idx.unique().tolist())


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
        self.targets = training_targets(dataset, config.use_masks)
        self.curve_set = (
            _curve_subset(eval_dataset, config.eval_views) if eval_dataset is not None else None
        )
        self.model, self.lr, self.batch = initial_model(dataset, config)
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
            carve(model.occupancy, self.dataset, config)
            if config.field == "grid" and config.crop:
                move_grids(model, self.res, aabb, self.dataset, config)
                self.optimizer = self.make_optimizer()
        if not (
            config.field == "grid"
            and self.stage + 1 < len(config.grid_resolutions)
            and frac >= config.stage_starts[self.stage + 1]
        ):
            return False
        self.stage += 1
        self.res = config.grid_resolutions[self.stage]
        move_grids(model, self.res, aabb, self.dataset, config)
        model.step_m = config.step_voxels * voxel_m(aabb, self.res)
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

"""Distillation of the lightweight renderer (the paper's §3.3, eq. 5,
:class:`~renderer.feature_renderer.FeatureRenderer`): :func:`train_features`.

The feature grid and the decoder are distilled from the field itself: teacher renders at
full resolution of the training cameras and of jittered copies of them (no images are
needed; :mod:`renderer.teacher_cameras`). The teachers are streamed through a
:class:`~renderer.teachers.TeacherPool` of bounded size, so setup memory does not grow with
the number of teachers or, beyond the pool, with the image size. Measurements of speed and
fidelity against the full render are in docs/design-notes.md ("The renderer") and
``python -m benchmarks renderer``.
"""

from __future__ import annotations

import math
import sys
import time

import torch

from common import trim_heap
from renderer.cameras import Intrinsics
from renderer.dataset import Dataset
from renderer.feature_config import FeatureConfig
from renderer.feature_renderer import FeatureRenderer
from renderer.model import RadianceField
from renderer.teacher_cameras import jittered_poses, scene_up_and_center, stored_cameras
from renderer.teachers import TeacherPool

TRIM_EVERY_STEPS = 100
"""Distillation steps between heap trims (:func:`common.trim_heap`): the freed temporaries
of steps and teacher renders stay bounded, at a page fault per reused page a hundred steps
apart."""


FIRST_FILL_SHARE = 0.5
"""Share of ``setup_cpu_seconds`` the first teacher renders may use before training starts."""


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
    poses, intr = _teacher_cameras(model, dataset, config)
    up, center = scene_up_and_center(model, poses)
    t0 = time.perf_counter()
    poses = torch.cat(
        [poses, jittered_poses(poses, up, center, config.extra_views, config.jitter_deg, generator)]
    )
    rend = FeatureRenderer(model, config, generator)
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
    # the first teachers fill the pool, within half of a CPU budget (the rest trains)
    while pool.held < pool.capacity and _progress(config, 0, 0.0, cpu0) < FIRST_FILL_SHARE:
        pool.render_next(min(config.render_batch, pool.capacity - pool.held))
        _show(bar, pool, _progress(config, 0, 0.0, cpu0), None, 0, cpu0)
    teacher_seconds = time.perf_counter() - t0
    trim_heap()
    steps, loss, t0 = _distil(rend, pool, config, generator, bar, cpu0)
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
        "cpu_budget_seconds": config.setup_cpu_seconds,
    }
    if stats["capped_by_seconds"]:
        print(
            f"features setup: its time budget (train_seconds {config.train_seconds:g} s,"
            f" setup_cpu_seconds {config.setup_cpu_seconds}) reached after {steps}"
            f" of {config.train_steps} steps",
            file=sys.stderr,
        )
    return rend, stats


def _teacher_cameras(
    model: RadianceField, dataset: Dataset | None, config: FeatureConfig
) -> tuple[torch.Tensor, Intrinsics]:
    """The training cameras (``dataset``'s, else those the field stores) at the teachers'
    size (``config.width_px``, aspect kept): (poses [n, 4, 4], intrinsics)."""
    if dataset is None:
        poses, intr = stored_cameras(model)
    else:
        poses, intr = dataset.poses, dataset.intrinsics
    if config.width_px is not None and config.width_px != intr.width:
        intr = intr.resized(
            max(1, round(intr.height * config.width_px / intr.width)), config.width_px
        )
    return poses, intr


def _distil(
    rend: FeatureRenderer,
    pool: TeacherPool,
    config: FeatureConfig,
    generator: torch.Generator,
    bar,
    cpu0: float,
) -> tuple[int, float, float]:
    """Adam steps on the grid and decoder against the pool's teachers until the budget is
    spent, rendering the later teachers evenly over its first 80 %: (steps, last loss,
    the training's start on ``time.perf_counter``)."""
    intr = pool.intrinsics
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
    while (frac := _progress(config, steps, time.perf_counter() - t0, cpu0)) < 1.0:
        due = first + math.ceil((pool.poses.shape[0] - first) * min(frac / 0.8, 1.0))
        if due > pool.rendered:
            batch = max(due - pool.rendered, config.render_batch)
            if config.setup_cpu_seconds is not None:  # a step at a time, within the budget
                batch = config.render_batch
            pool.render_next(batch)
        slots = pool.sample(config.batch_size, generator, config.focus)
        passes = pool.passes_of(slots)
        out = rend.decode(passes, intr.height, intr.width)
        per_view = distillation_errors(rend, passes, out, pool.images_of(slots))
        err = per_view.mean()
        pool.record_errors(slots, per_view)
        opt.zero_grad(set_to_none=False)  # the grid's reads add into its .grad in place
        err.backward()
        opt.step()
        steps, loss = steps + 1, float(err.detach())
        if steps % TRIM_EVERY_STEPS == 0:
            trim_heap()
        _show(bar, pool, frac, loss, steps, cpu0)
    return steps, loss, t0


def distillation_errors(
    rend: FeatureRenderer, passes: list, out: torch.Tensor, teachers: torch.Tensor
) -> torch.Tensor:
    """Mean squared error [num_views] of the decoded views ``out`` [num_views, height, width,
    3] against their ``teachers``, over every pixel but those the renderer renders again
    with the field (:meth:`FeatureRenderer.refine_mask`, counted as zero): nothing is
    learnt where the decoder's colour is replaced."""
    sq = (out - teachers).square()
    refined = rend.refine_mask(passes, out.detach())
    if refined is not None:
        sq = sq * (~refined)[..., None]
    return sq.mean((1, 2, 3))


def _progress(config: FeatureConfig, steps: int, seconds: float, cpu0: float) -> float:
    """Fraction of the training budget used: by steps when given (seconds then cap it);
    the setup's CPU seconds since ``cpu0`` (``time.process_time``) cap both."""
    frac = seconds / config.train_seconds
    if config.setup_cpu_seconds is not None:
        frac = max(frac, (time.process_time() - cpu0) / config.setup_cpu_seconds)
    if config.train_steps is not None:
        frac = max(frac, steps / config.train_steps)
    return frac


def _setup_bar(config: FeatureConfig):
    """Percent of the budget (steps, or the setup's CPU seconds when that is the larger
    share), with teachers rendered, steps, CPU seconds spent and loss."""
    if not config.progress:
        return None
    from tqdm import tqdm

    return tqdm(total=100, desc="features setup", unit="%", file=sys.stderr)


def _show(bar, pool: TeacherPool, frac: float, loss: float | None, steps: int, cpu0: float) -> None:
    if bar is None:
        return
    post = {
        "teachers": f"{pool.rendered}/{pool.poses.shape[0]}",
        "step": steps,
        "cpu_s": f"{time.process_time() - cpu0:.0f}",
    }
    if loss is not None:
        post["loss"] = f"{loss:.5f}"
    bar.set_postfix(post, refresh=False)
    bar.update(min(int(100 * frac), 100) - bar.n)  # redraws at most every mininterval

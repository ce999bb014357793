"""How a radiance field is trained (:class:`TrainConfig`), and its settings by view size
(:data:`GRIDS_BY_SIZE`, read through :func:`settings_for_size`).

How the defaults were chosen, with the measurements: docs/design-notes.md.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

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
finer grid's dense per-step work (docs/design-notes.md)."""

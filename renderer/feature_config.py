"""How the feature renderer (:mod:`renderer.features`) renders and trains
(:class:`FeatureConfig`), and its settings by view size (:data:`FEATURES_BY_SIZE`)."""

from __future__ import annotations

from dataclasses import asdict, dataclass

from renderer.train_config import settings_for_size


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
    min_transmittance: float = 0.0
    """Rays of the low-resolution pass end once their transmittance falls below this (early
    ray termination: the samples behind are never evaluated), in [0, 1); 0 marches every
    sample. At or below ``weight_threshold`` the kept samples are the same and only the
    opacity changes, by less than this."""
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
    setup_cpu_seconds: float | None = None
    """Budget of the whole setup in this process's CPU seconds (baking, teacher renders and
    training), > 0, or None for none: training ends when it is spent, whatever
    ``train_steps`` says. CPU time, not wall time: the same budget on a busy machine."""
    bake_density: bool = False
    """Start the first free channel (after the colour's) as the field's opacity per marching
    step at each vertex (:func:`renderer.bake.bake_field`), so the decoder starts with the
    field's geometry as well as its colour; needs ``channels`` above the colour's."""
    sample_colour: bool = False
    """Composite each sample's colour (the sigmoid of its view-dependent logits) as the
    field does, not the logits: at a surface's edge and where the samples of a ray differ
    in colour, compositing logits is not the field's image; the decoder then has less to
    correct."""
    focus: float = 0.0
    """Share of each batch's views drawn in proportion to their teachers' last error
    (the others uniformly), in [0, 1]: distillation spent where the error is."""
    refine_partial: float = 0.0
    """Pixels of a low-resolution pixel whose opacity is in (refine_partial, 1 -
    refine_partial) are rendered again by the field at full resolution after decoding
    (:mod:`renderer.refine`: silhouettes and thin parts), in [0, 0.5); 0 renders none."""
    refine_contrast: float = 1.0
    """Pixels whose decoded 3 x 3 neighbourhood spans more than this in a colour channel are
    rendered again by the field at full resolution (sharp edges), > 0; 1 or more renders
    none."""
    refine_min_transmittance: float = 1e-2
    """The rays rendered again end once their transmittance falls below this, and drop the
    samples whose weight is below a tenth of it, in (0, 1): each pixel rendered again is
    then the full render's to within about this."""
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
        if self.setup_cpu_seconds is not None and not self.setup_cpu_seconds > 0:
            raise ValueError(f"setup_cpu_seconds must be > 0 or None, got {self.setup_cpu_seconds}")
        if not 0 <= self.focus <= 1:
            raise ValueError(f"focus must be in [0, 1], got {self.focus}")
        if not 0 < self.grid_scale <= 1:
            raise ValueError(f"grid_scale must be in (0, 1], got {self.grid_scale}")
        if not self.step_factor >= 1:
            raise ValueError(f"step_factor must be >= 1, got {self.step_factor}")
        if not 0 <= self.min_transmittance < 1:
            raise ValueError(f"min_transmittance must be in [0, 1), got {self.min_transmittance}")
        if not 0 <= self.refine_partial < 0.5:
            raise ValueError(f"refine_partial must be in [0, 0.5), got {self.refine_partial}")
        if not self.refine_contrast > 0:
            raise ValueError(f"refine_contrast must be > 0, got {self.refine_contrast}")
        if not 0 < self.refine_min_transmittance < 1:
            raise ValueError(
                f"refine_min_transmittance must be in (0, 1), got {self.refine_min_transmittance}"
            )
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
    150: {
        "step_factor": 1.5,
        "min_transmittance": 1e-3,
        "extra_views": 200,
        "pool_views": 512,
        "train_steps": None,
        "setup_cpu_seconds": 170.0,
        "bake_density": True,
        "sample_colour": True,
        "focus": 0.5,
        "batch_size": 2,
    },
    300: {
        "min_transmittance": 1e-3,
        "extra_views": 200,
        "pool_views": 512,
        "downsample": 3,
        "grid_scale": 0.75,
        "pass_cache_mb": 256,
        "train_steps": None,
        "setup_cpu_seconds": 540.0,
        "bake_density": True,
        "sample_colour": True,
        "focus": 0.5,
        "batch_size": 2,
    },
}
"""Smallest image width (px) -> :class:`FeatureConfig` settings that differ from the
defaults (:meth:`FeatureConfig.for_resolution`): from 150 px the field baked with its
density, a few hundred teachers all held at once, and a budget of CPU seconds (under three
minutes with the baking and the final trims), batches of two views (twice the steps of four
in the same budget), half of each drawn where the error is, and each sample's colour
composited as the field composites it, at a finer marching step paid for by ending each ray
of the low-resolution pass once it is opaque; from 300 px the same (rays still ended once
opaque), at the default step, within nine CPU-minutes (each teacher a full render at that
size), a third-width pass, a feature grid at three quarters of the field's vertices per axis
and half the pass cache (beside the cache, the grid with its gradient and two Adam moments dominates
setup memory at these sizes). Measured on lego's test path (docs/design-notes.md, "The
renderer")."""

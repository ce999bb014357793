"""Backward warping of a previous frame into the current view by the current depth."""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import Tensor

from renderer.cameras import Intrinsics, camera_rays, project_points


def reproject(
    prev_values: Tensor,
    prev_depth: Tensor,
    prev_pose: Tensor,
    depth: Tensor,
    pose: Tensor,
    intrinsics: Intrinsics,
    depth_tolerance: float = 0.05,
) -> tuple[Tensor, Tensor]:
    """Warp a previous frame into the current camera.

    Each current pixel is lifted to the world point ``X = o + depth * d`` on its ray,
    projected into the previous camera, and the previous frame is sampled there
    (bilinear). The pixel is valid when X is in front of the previous camera, inside
    its image, and the previous frame's own depth there agrees with the distance from
    the previous camera to X within ``depth_tolerance`` (relative): occluded points are
    invalid.

    Args:
        prev_values: [channels, height, width] float32 (e.g. RGB) of the previous frame.
        prev_depth: [height, width] float32 distance along the previous frame's rays (m).
        prev_pose, pose: [4, 4] camera-to-world of the previous and current frames.
        depth: [height, width] float32 distance along the current rays (m).
        intrinsics: shared camera at height x width.
    Returns:
        (warped [channels, height, width] float32 (0 where invalid), valid [height, width]
        float32 in {0, 1}).
    """
    h, w = intrinsics.height, intrinsics.width
    o, d = camera_rays(pose[None], intrinsics)
    points = o[0] + depth[..., None] * d[0]  # [height, width, 3]
    uv, z = project_points(points, prev_pose, intrinsics)
    grid = torch.stack([uv[..., 0] / w * 2.0 - 1.0, uv[..., 1] / h * 2.0 - 1.0], dim=-1)[None]
    warped = F.grid_sample(
        prev_values[None], grid, mode="bilinear", align_corners=False, padding_mode="border"
    )[0]
    seen = F.grid_sample(
        prev_depth[None, None], grid, mode="nearest", align_corners=False, padding_mode="border"
    )[0, 0]
    dist = (points - prev_pose[:3, 3].float()).norm(dim=-1)
    inside = (grid.abs() <= 1.0).all(dim=-1)[0] & (z > 0)
    agree = (seen - dist).abs() <= depth_tolerance * dist.clamp_min(1e-6)
    valid = (inside & agree).float()
    return warped * valid, valid


def surface_points(
    depth: Tensor, opacity: Tensor, pose: Tensor, intrinsics: Intrinsics, min_opacity: float = 0.5
) -> Tensor:
    """World points of a frame's visible surface: ``o + depth * d`` at every pixel whose
    opacity is at least ``min_opacity``.

    Args:
        depth, opacity: [height, width] float32 (distance along the rays, m; [0, 1]).
        pose: [4, 4] camera-to-world.
    Returns:
        [num_points, 3] float32.
    """
    o, d = camera_rays(pose[None], intrinsics)
    keep = (opacity >= min_opacity).reshape(-1)
    return (o[0] + depth[..., None] * d[0]).reshape(-1, 3)[keep]


def splat_depth(points: Tensor, pose: Tensor, intrinsics: Intrinsics) -> Tensor:
    """Forward-project surface points (e.g. :func:`surface_points` of a previous frame)
    into a camera and keep the nearest per pixel (a z-buffer): the depth wherever the
    points land. One-pixel cracks (where the surface is magnified) are filled with the
    nearest of their 3 x 3 neighbours.

    Args:
        points: [num_points, 3] float32 world points.
        pose: [4, 4] camera-to-world.
    Returns:
        [height, width] float32 distance from the camera centre (m, as the depth of
        :func:`camera_rays`' unit rays); inf where no point landed.
    """
    h, w = intrinsics.height, intrinsics.width
    uv, z = project_points(points, pose, intrinsics)
    u, v = uv[:, 0].floor(), uv[:, 1].floor()
    ok = (z > 0) & (u >= 0) & (u < w) & (v >= 0) & (v < h)
    dist = (points[ok] - pose[:3, 3].float()).norm(dim=-1)
    flat = (v[ok] * w + u[ok]).long()
    out = torch.full((h * w,), float("inf")).scatter_reduce(0, flat, dist, reduce="amin")
    out = out.reshape(h, w)
    filled = -F.max_pool2d(-out[None, None], 3, stride=1, padding=1)[0, 0]
    return torch.where(torch.isinf(out), filled, out)


def rotate_pose_about(pose: Tensor, center: Tensor, axis: Tensor, angle_rad: float) -> Tensor:
    """Rotate a camera pose rigidly about the line through ``center`` along ``axis``.

    Args:
        pose: [4, 4]; center, axis: [3].
    Returns:
        [4, 4] float32.
    """
    k = F.normalize(axis.float(), dim=0)
    kx = torch.tensor([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    rot = (
        torch.eye(3)
        + torch.sin(torch.tensor(angle_rad)) * kx
        + (1 - torch.cos(torch.tensor(angle_rad))) * (kx @ kx)
    )
    out = torch.eye(4)
    out[:3, :3] = rot @ pose[:3, :3].float()
    out[:3, 3] = rot @ (pose[:3, 3].float() - center.float()) + center.float()
    return out

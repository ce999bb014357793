"""The cameras the feature renderer's teachers are rendered from: those the field stores
(:func:`stored_cameras`) and jittered copies of the training cameras (:func:`jittered_poses`)."""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import Tensor

from renderer.cameras import Intrinsics, look_at, rotate_pose_about
from renderer.model import RadianceField


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

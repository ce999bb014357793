"""Pinhole cameras in the OpenGL/NeRF convention: rays, projection, camera paths.

Poses are camera-to-world ``[4, 4]`` matrices; the camera's x axis points right, y up, and
it looks along -z. Pixel (row v, column u) has its centre at (u + 0.5, v + 0.5); the ray
through it has camera-frame direction ``((u + 0.5 - cx) / fx, -(v + 0.5 - cy) / fy, -1)``,
normalised to unit length, so distances along rays are metres.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
import torch.nn.functional as F
from torch import Tensor


@dataclass(frozen=True)
class Intrinsics:
    """Pinhole intrinsics in pixels of an image of ``height`` x ``width``."""

    fx: float
    """Focal length along x (pixels), > 0."""
    fy: float
    """Focal length along y (pixels), > 0."""
    cx: float
    """Principal point x (pixels from the left edge)."""
    cy: float
    """Principal point y (pixels from the top edge)."""
    height: int
    """Image height (pixels), >= 1."""
    width: int
    """Image width (pixels), >= 1."""

    def __post_init__(self):
        for name in ("fx", "fy", "cx", "cy"):
            v = getattr(self, name)
            if not math.isfinite(v):
                raise ValueError(f"Intrinsics.{name} must be finite, got {v}")
        if self.fx <= 0 or self.fy <= 0:
            raise ValueError(f"Intrinsics.fx and fy must be > 0, got {self.fx}, {self.fy}")
        if self.height < 1 or self.width < 1:
            raise ValueError(
                f"Intrinsics.height/width must be >= 1, got {self.height}x{self.width}"
            )

    def resized(self, height: int, width: int) -> Intrinsics:
        """The same camera imaged at another resolution (focal lengths and centre scaled)."""
        sx, sy = width / self.width, height / self.height
        return Intrinsics(self.fx * sx, self.fy * sy, self.cx * sx, self.cy * sy, height, width)

    def as_dict(self) -> dict:
        return {
            "fl_x": self.fx,
            "fl_y": self.fy,
            "cx": self.cx,
            "cy": self.cy,
            "h": self.height,
            "w": self.width,
        }


def pose_problem(pose) -> str | None:
    """Why ``pose`` is not a usable camera-to-world matrix, or None when it is.

    Args:
        pose: [4, 4] (or [3, 4]) numbers, numpy or torch.
    Returns:
        e.g. ``"has non-finite entries"``, ``"is singular (its 3x3 rotation part has
        determinant 0)"``; None for a finite pose with an invertible rotation part.
    """
    p = torch.as_tensor(pose, dtype=torch.float64)
    if p.shape not in ((4, 4), (3, 4)):
        return f"has shape {tuple(p.shape)}, expected 4x4"
    if not torch.isfinite(p).all():
        return "has non-finite entries"
    det = float(torch.linalg.det(p[:3, :3]))
    if not abs(det) > 1e-9:
        return (
            f"is singular (its 3x3 rotation part has determinant {det:.3g}; "
            "a pose needs a rotation)"
        )
    return None


def camera_rays(poses: Tensor, intrinsics: Intrinsics) -> tuple[Tensor, Tensor]:
    """Ray origins and unit directions of every pixel of every view.

    Args:
        poses: [num_views, 4, 4] float32 camera-to-world.
    Returns:
        (origins, directions), each [num_views, height, width, 3] float32.
    """
    k = intrinsics
    v, u = torch.meshgrid(
        torch.arange(k.height, dtype=torch.float32),
        torch.arange(k.width, dtype=torch.float32),
        indexing="ij",
    )
    dirs_cam = torch.stack(
        [(u + 0.5 - k.cx) / k.fx, -(v + 0.5 - k.cy) / k.fy, -torch.ones_like(u)], dim=-1
    )  # [height, width, 3]
    rot = poses[:, :3, :3].float()  # [num_views, 3, 3]
    # one batched matmul into a contiguous [num_views, height * width, 3] (an einsum to
    # "nhwi" leaves a strided result that normalises about five times slower)
    dirs = torch.matmul(dirs_cam.reshape(1, -1, 3), rot.transpose(1, 2))
    dirs = F.normalize(dirs, dim=-1).reshape(-1, k.height, k.width, 3)
    origins = poses[:, None, None, :3, 3].float().expand_as(dirs)
    return origins.contiguous(), dirs.contiguous()


def project_points(points: Tensor, pose: Tensor, intrinsics: Intrinsics) -> tuple[Tensor, Tensor]:
    """Project world points into a camera (inverse of :func:`camera_rays`).

    Args:
        points: [..., 3] float32 world coordinates.
        pose: [4, 4] camera-to-world.
    Returns:
        (uv [..., 2] float32 continuous pixel coordinates with pixel centres at k + 0.5,
        depth [...] float32: distance along -z in front of the camera; <= 0 behind it).
    """
    rot, centre = pose[:3, :3].float(), pose[:3, 3].float()
    cam = (points - centre) @ rot  # [..., 3] = R^T (p - c)
    z = -cam[..., 2]
    zs = z.clamp_min(1e-6)
    u = intrinsics.cx + intrinsics.fx * cam[..., 0] / zs
    v = intrinsics.cy - intrinsics.fy * cam[..., 1] / zs
    return torch.stack([u, v], dim=-1), z


def intersect_aabb(origins: Tensor, directions: Tensor, aabb: Tensor) -> tuple[Tensor, Tensor]:
    """Slab test of rays against an axis-aligned box.

    Args:
        origins, directions: [num_rays, 3] float32.
        aabb: [2, 3] float32 (min corner, max corner).
    Returns:
        (t_near [num_rays], t_far [num_rays]) float32, t_near >= 0; a ray misses when
        t_far <= t_near.
    """
    safe = torch.where(directions.abs() < 1e-9, torch.full_like(directions, 1e-9), directions)
    t0 = (aabb[0] - origins) / safe
    t1 = (aabb[1] - origins) / safe
    t_near = torch.minimum(t0, t1).amax(dim=-1).clamp_min(0.0)
    t_far = torch.maximum(t0, t1).amin(dim=-1)
    return t_near, t_far


def look_at(eye: Tensor, target: Tensor, up: Tensor | None = None) -> Tensor:
    """Camera-to-world pose of a camera at ``eye`` looking at ``target``.

    Args:
        eye, target: [3] float32; up: [3] (default +z, the Blender world up).
    Returns:
        [4, 4] float32.
    """
    up = torch.tensor([0.0, 0.0, 1.0]) if up is None else up.float()
    back = F.normalize(eye.float() - target.float(), dim=0)  # camera +z
    right = torch.linalg.cross(up, back)
    if right.norm() < 1e-6:  # looking straight along up
        right = torch.linalg.cross(torch.tensor([0.0, 1.0, 0.0]), back)
    right = F.normalize(right, dim=0)
    true_up = torch.linalg.cross(back, right)
    pose = torch.eye(4)
    pose[:3, 0], pose[:3, 1], pose[:3, 2], pose[:3, 3] = right, true_up, back, eye.float()
    return pose


def orbit_path(
    num_views: int,
    radius_m: float,
    elevation_deg: float = 30.0,
    center: Tensor | None = None,
    start_azimuth_deg: float = 0.0,
    arc_deg: float = 360.0,
    up: Tensor | None = None,
) -> Tensor:
    """Camera poses on a circle around ``center`` in the plane normal to ``up`` (default +z),
    raised by ``elevation_deg``, all looking at the centre. With up = +z, azimuth 0 is +x.

    Returns:
        [num_views, 4, 4] float32.
    """
    if num_views < 1:
        raise ValueError(f"num_views must be >= 1, got {num_views}")
    if not radius_m > 0:
        raise ValueError(f"radius_m must be > 0, got {radius_m}")
    center = torch.zeros(3) if center is None else center.float()
    up = torch.tensor([0.0, 0.0, 1.0]) if up is None else F.normalize(up.float(), dim=0)
    seed = torch.tensor([1.0, 0.0, 0.0]) if abs(up[0]) < 0.9 else torch.tensor([0.0, 1.0, 0.0])
    e1 = F.normalize(seed - (seed @ up) * up, dim=0)
    e2 = torch.linalg.cross(up, e1)
    elev = math.radians(elevation_deg)
    poses = []
    for i in range(num_views):
        az = math.radians(start_azimuth_deg + arc_deg * i / num_views)
        eye = center + radius_m * (
            math.cos(elev) * (math.cos(az) * e1 + math.sin(az) * e2) + math.sin(elev) * up
        )
        poses.append(look_at(eye, center, up))
    return torch.stack(poses)


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

"""Drone cameras: look-at poses, rings around an object, intrinsics, ray generation.

Poses are camera-to-world 4x4 in the OpenGL/NeRF convention (x right, y up, the camera
looks along -z), as in nerfstudio's ``transforms.json``. Mitsuba's sensor matrix is
``pose @ diag(-1, 1, -1, 1)`` (its camera looks along +z with x to the left).
"""

from __future__ import annotations

import numpy as np

from renderer import Intrinsics  # the one pinhole camera

MITSUBA_FROM_GL = np.diag([-1.0, 1.0, -1.0, 1.0])


def intrinsics_from_fov(fov_deg: float, width: int, height: int) -> Intrinsics:
    """Pinhole intrinsics (pixel centres at half-integers) for a horizontal field of view
    ``fov_deg`` (Mitsuba's default axis)."""
    if not 0.0 < fov_deg < 180.0:
        raise ValueError(f"fov_deg must be in (0, 180), got {fov_deg}")
    f = (width / 2.0) / np.tan(np.radians(fov_deg) / 2.0)
    return Intrinsics(float(f), float(f), width / 2.0, height / 2.0, int(height), int(width))


def look_at(origin_m, target_m, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """Camera-to-world [4, 4] float64 (OpenGL axes) at ``origin_m`` looking at ``target_m``."""
    o = np.asarray(origin_m, np.float64)
    z = o - np.asarray(target_m, np.float64)
    z /= np.linalg.norm(z)
    x = np.cross(np.asarray(up, np.float64), z)
    if np.linalg.norm(x) < 1e-9:  # looking straight down: any horizontal x
        x = np.array([1.0, 0.0, 0.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    pose = np.eye(4)
    pose[:3, 0], pose[:3, 1], pose[:3, 2], pose[:3, 3] = x, y, z, o
    return pose


def ring_positions(
    center_m, radius_m: float, elevations_deg, num_views: int, azimuth_offset_deg: float = 0.0
) -> np.ndarray:
    """Positions on rings around ``center_m``: ``num_views`` spread over the elevations.

    Views are dealt round-robin to the elevations, and each ring's azimuths are evenly
    spaced (shifted per ring so the rings interleave).

    Returns:
        [num_views, 3] float64 metres.
    """
    if num_views < 1:
        raise ValueError(f"num_views must be >= 1, got {num_views}")
    elev = np.radians(np.asarray(elevations_deg, np.float64))
    if elev.size == 0 or np.any(elev <= 0) or np.any(elev >= np.pi / 2):
        raise ValueError(f"elevations_deg must be in (0, 90), got {elevations_deg}")
    out = []
    for k, e in enumerate(elev):
        n = len(range(k, num_views, len(elev)))
        if n == 0:
            continue
        az = np.radians(azimuth_offset_deg) + (np.arange(n) + k / len(elev)) * 2 * np.pi / n
        out.append(np.c_[np.cos(e) * np.cos(az), np.cos(e) * np.sin(az), np.full(n, np.sin(e))])
    return np.asarray(center_m, np.float64) + radius_m * np.concatenate(out)


def pixel_rays(pose: np.ndarray, intr: Intrinsics, samples_per_pixel: int = 1, generator=None):
    """World-space rays through the pixels of one camera.

    Args:
        pose: [4, 4] camera-to-world (OpenGL).
        samples_per_pixel: 1 = pixel centres; more = jittered sub-pixel positions.
        generator: numpy Generator for the jitter (required when samples_per_pixel > 1).
    Returns:
        origins [num_rays, 3], directions [num_rays, 3] (unit), num_rays =
        height * width * samples_per_pixel, ordered pixel-major (row, column, sample).
    """
    h, w, s = intr.height, intr.width, int(samples_per_pixel)
    j, i = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    if s == 1:
        du = dv = np.full((h, w, 1), 0.5)
    else:
        if generator is None:
            raise ValueError("pixel_rays needs a numpy generator for samples_per_pixel > 1")
        du, dv = generator.random((h, w, s)), generator.random((h, w, s))
    u = j[..., None] + du  # [height, width, samples]
    v = i[..., None] + dv
    d_cam = np.stack([(u - intr.cx) / intr.fx, -(v - intr.cy) / intr.fy, -np.ones_like(u)], -1)
    d = d_cam.reshape(-1, 3) @ pose[:3, :3].T  # [num_rays, 3]
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    o = np.broadcast_to(pose[:3, 3], d.shape).copy()
    return o, d


def project(points_m: np.ndarray, pose: np.ndarray, intr: Intrinsics) -> np.ndarray:
    """Pixel coordinates (u right, v down) of world points seen by the camera.

    Args:
        points_m: [num_points, 3].
    Returns:
        [num_points, 2] float64; points behind the camera get NaN.
    """
    w2c = np.linalg.inv(pose)
    p = np.c_[points_m, np.ones(len(points_m))] @ w2c.T
    z = -p[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        u = intr.cx + intr.fx * p[:, 0] / z
        v = intr.cy - intr.fy * p[:, 1] / z
    out = np.c_[u, v]
    out[z <= 0] = np.nan
    return out

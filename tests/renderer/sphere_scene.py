"""A synthetic analytic scene: a sphere coloured by its normal, seen by orbiting cameras."""

import math
from pathlib import Path

import cv2
import numpy as np
import torch

from renderer import Intrinsics, camera_rays, orbit_path, write_transforms

RADIUS_M = 0.5
SIZE = 32
CAMERA_DISTANCE_M = 2.5


def sphere_views(poses: torch.Tensor, intrinsics: Intrinsics, background=(1.0, 1.0, 1.0)):
    """Exact renders of the sphere |x| = RADIUS_M with colour 0.5 + 0.5 n (n: outward normal).

    Returns (rgb [n, h, w, 3], alpha [n, h, w], depth [n, h, w] distance along the ray,
    inf where missed).
    """
    o, d = camera_rays(poses, intrinsics)
    b = (o * d).sum(-1)
    c = (o * o).sum(-1) - RADIUS_M**2
    disc = b * b - c
    hit = disc > 0
    t = -b - torch.sqrt(disc.clamp_min(0))
    p = o + t[..., None] * d
    n = p / RADIUS_M
    colour = 0.5 + 0.5 * n
    bg = torch.tensor(background)
    rgb = torch.where(hit[..., None], colour, bg)
    depth = torch.where(hit, t, torch.full_like(t, math.inf))
    return rgb, hit.float(), depth


def sphere_cameras(num_views: int, elevation_deg: float, start_deg: float = 0.0):
    return orbit_path(num_views, CAMERA_DISTANCE_M, elevation_deg, start_azimuth_deg=start_deg)


def write_sphere_dataset(root: Path) -> Path:
    """transforms_train.json (24 views, RGBA, extension-less paths) and transforms_test.json (4)."""
    root.mkdir(parents=True, exist_ok=True)
    fx = 0.5 * SIZE / math.tan(0.5 * 0.9)
    intr = Intrinsics(fx, fx, SIZE / 2, SIZE / 2, SIZE, SIZE)
    splits = {
        "train": torch.cat([sphere_cameras(12, 20.0), sphere_cameras(12, -25.0, 15.0)]),
        "test": sphere_cameras(4, 5.0, 40.0),
    }
    for split, poses in splits.items():
        rgb, alpha, _ = sphere_views(poses, intr, background=(0.0, 0.0, 0.0))
        (root / split).mkdir(exist_ok=True)
        paths = []
        for i in range(poses.shape[0]):
            rgba = torch.cat([rgb[i], alpha[i][..., None]], -1).numpy()
            img = (rgba * 255 + 0.5).astype(np.uint8)[..., [2, 1, 0, 3]]
            cv2.imwrite(str(root / split / f"r_{i}.png"), img)
            paths.append(f"./{split}/r_{i}")
        write_transforms(
            root / f"transforms_{split}.json",
            poses,
            intr,
            paths,
            aabb=torch.tensor([[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]]),
        )
    return root


class one_thread:
    """Context manager: one torch intra-op thread, restored afterwards (see conftest)."""

    def __enter__(self):
        self.before = torch.get_num_threads()
        torch.set_num_threads(1)

    def __exit__(self, *exc):
        torch.set_num_threads(self.before)


def exact_sphere_field(train_set):
    """The exact sphere written into a grid field (no training needed): a
    ``renderer.RadianceField`` over ``train_set``'s box, on its background."""
    from renderer import GridField, OccupancyGrid, RadianceField

    field = GridField(train_set.aabb, resolution=49, step_m=0.04)
    nx, ny, nz = field.resolution
    axes = [torch.linspace(-1, 1, n) for n in (nz, ny, nx)]
    z, y, x = torch.meshgrid(*axes, indexing="ij")
    r = torch.sqrt(x**2 + y**2 + z**2)
    with torch.no_grad():
        field.density_grid[0, 0] = torch.where(r < RADIUS_M, 60.0, -30.0)
        colour = 0.5 + 0.5 * torch.stack([x, y, z]) / r.clamp_min(1e-6)
        field.color_grid[0] = torch.logit(colour.clamp(0.02, 0.98))
    occ = OccupancyGrid.for_grid_field(field)
    occ.update(field.density, 0.04, vertex_density=field.vertex_density())
    spec = {"field": "grid", "resolution": 49, "step_m": 0.04}
    return RadianceField(field, occ, 0.04, train_set.background, spec)

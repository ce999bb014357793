"""The field a training run starts from (:func:`initial_model`: the first coarse-to-fine
stage, with its camera spec), the pixels it is fitted to (:func:`training_targets`), and the
grid moves between stages (:func:`move_grids`: resample onto the occupied box, carve)."""

from __future__ import annotations

import torch

from renderer.dataset import Dataset
from renderer.fields import GridField, MLPField
from renderer.model import RadianceField
from renderer.sampler import OccupancyGrid
from renderer.train_config import TrainConfig


def voxel_m(aabb: torch.Tensor, resolution: int) -> float:
    return (aabb[1] - aabb[0]).max().item() / (resolution - 1)


def training_targets(dataset: Dataset, use_masks: bool) -> torch.Tensor:
    """[num_pixels, 3] training colours: with ``use_masks``, the object on the background
    (images whose masks are their own alpha are that already: compositing them again
    would square the alpha of edge pixels)."""
    images = dataset.images
    if use_masks and dataset.masks is not None and not dataset.composited:
        bg = torch.tensor(dataset.background)
        m = dataset.masks[..., None]
        images = images * m + bg * (1 - m)
    return images.reshape(-1, 3)


def crop_resolution(box: torch.Tensor, aabb: torch.Tensor, resolution: int) -> int:
    """Vertices on ``box``'s longest axis for the voxel size of ``resolution`` over ``aabb``."""
    return max(2, int(round((box[1] - box[0]).max().item() / voxel_m(aabb, resolution))) + 1)


def carve(occupancy: OccupancyGrid, dataset: Dataset, config: TrainConfig) -> None:
    if config.carve and config.use_masks and dataset.masks is not None:
        occupancy.carve(dataset.poses, dataset.intrinsics, dataset.masks)


def move_grids(
    model: RadianceField, resolution: int, aabb: torch.Tensor, dataset: Dataset, config: TrainConfig
) -> None:
    """Resample the grid field at ``resolution`` (voxel size over ``aabb``) onto the box
    around the occupied cells (``config.crop``) or the whole box, with a new occupancy grid
    that keeps the free space already known and is carved again."""
    coarser = model.occupancy
    box = coarser.occupied_box() if config.crop else model.aabb
    model.field.resample(box, crop_resolution(box, aabb, resolution))
    model.occupancy = OccupancyGrid.for_grid_field(model.field)
    model.occupancy.inherit_free(coarser)
    carve(model.occupancy, dataset, config)


def initial_model(dataset: Dataset, config: TrainConfig) -> tuple[RadianceField, float, int]:
    """The untrained field (first coarse-to-fine stage for the grid field) with its camera
    spec for later renders; returns (model, learning rate, rays per step)."""
    aabb = dataset.aabb
    if config.field == "grid":
        res = config.grid_resolutions[0]
        step_m = config.step_voxels * voxel_m(aabb, res)
        field_ = GridField(aabb, resolution=res, alpha_init=config.alpha_init, step_m=step_m)
        occupancy = OccupancyGrid.for_grid_field(field_)
        spec = {
            "field": "grid",
            "resolution": res,
            "step_m": step_m,
            "alpha_init": config.alpha_init,
        }
        lr, batch = config.lr, max(1, config.batch_rays // 2)
    else:
        step_m = config.mlp_step_voxels * (aabb[1] - aabb[0]).max().item() / 96
        field_ = MLPField(aabb, width=config.mlp_width, depth=config.mlp_depth)
        occupancy = OccupancyGrid(aabb, (64, 64, 64))
        spec = {"field": "mlp", "width": config.mlp_width, "depth": config.mlp_depth}
        lr, batch = config.mlp_lr, config.mlp_batch_rays
    centre = aabb.mean(0)
    spec["camera"] = {  # for default camera paths when rendering later
        "intrinsics": dataset.intrinsics.as_dict(),
        "center": centre.tolist(),
        "radius_m": (dataset.poses[:, :3, 3] - centre).norm(dim=-1).mean().item(),
        "up": torch.nn.functional.normalize(dataset.poses[:, :3, 1].mean(0), dim=0).tolist(),
        "poses": dataset.poses.tolist(),  # the lightweight renderer trains around them
    }
    return RadianceField(field_, occupancy, step_m, dataset.background, spec), lr, batch

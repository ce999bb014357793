"""A known analytic scene (a sphere coloured by its normal) is recovered by the grid field;
save/load round trip; the vanilla MLP learns; config validation."""

import pytest
import torch
from sphere_scene import RADIUS_M, one_thread, sphere_views

from renderer import (
    GridField,
    OccupancyGrid,
    RadianceField,
    TrainConfig,
    evaluate,
    load_dataset,
    load_model,
    render_views,
    train,
)

FAST = dict(
    max_seconds=300.0,
    grid_resolutions=(17, 33),
    stage_starts=(0.0, 0.3),
    batch_rays=1024,
    eval_every_seconds=1e6,
    progress=False,
)


def _sphere_train(sphere_dataset, **kwargs):
    train_set = load_dataset(sphere_dataset, "train", resolution=None)
    test_set = load_dataset(sphere_dataset, "test", resolution=None)
    with one_thread():
        result = train(
            train_set,
            TrainConfig(field="grid", max_steps=250, **FAST, **kwargs),
            generator=torch.Generator().manual_seed(0),
            eval_dataset=test_set,
        )
    return result, train_set, test_set


@pytest.fixture(scope="module")
def sphere_run(sphere_dataset):
    """The diffuse field (the sphere's colour does not depend on the view): its geometry
    is checked below. View-dependent colour, the default, can trade some opacity for
    colour while the surface is still soft; see test_view_dependent_colour_*."""
    return _sphere_train(sphere_dataset, sh_degree=0)


def test_view_dependent_colour_fits_better_and_keeps_the_sphere(sphere_run, sphere_dataset):
    result, _, test_set = _sphere_train(sphere_dataset)  # defaults: SH degree 1, last stage
    assert result.model.field.sh_degree == 1
    m = evaluate(result.model, test_set)
    assert m["psnr"] > evaluate(sphere_run[0].model, test_set)["psnr"] + 1.0
    out = render_views(result.model, test_set.poses, test_set.intrinsics)
    _, alpha, depth = sphere_views(test_set.poses, test_set.intrinsics)
    inner = torch.nn.functional.max_pool2d(1 - alpha[:, None], 3, 1, 1)[:, 0] == 0
    assert out["opacity"][inner].quantile(0.05) > 0.85
    assert (out["depth"][inner] - depth[inner]).abs().median() < 0.25


def test_grid_field_recovers_the_sphere(sphere_run):
    result, _, test_set = sphere_run
    assert result.steps == 250
    m = evaluate(result.model, test_set)
    assert m["num_views"] == 4
    assert m["psnr"] > 28.0, m
    assert m["ssim"] > 0.9
    # the curve starts at step 0 and ends at the last step, improving
    assert result.curve[0]["step"] == 0 and result.curve[-1]["step"] == 250
    assert result.curve[-1]["psnr"] > result.curve[0]["psnr"] + 10


def test_geometry_depth_and_empty_space(sphere_run):
    result, _, test_set = sphere_run
    model = result.model
    out = render_views(model, test_set.poses, test_set.intrinsics)
    _, alpha, depth = sphere_views(test_set.poses, test_set.intrinsics)
    pool = torch.nn.functional.max_pool2d
    inner = pool(1 - alpha[:, None], 3, 1, 1)[:, 0] == 0  # away from the rim
    outer = pool(alpha[:, None], 3, 1, 1)[:, 0] == 0
    assert out["opacity"][inner].quantile(0.05) > 0.9
    assert out["opacity"][outer].quantile(0.95) < 0.3
    # after 250 steps the surface is still soft: depth within 0.2 m (0.4 radius)
    assert (out["depth"][inner] - depth[inner]).abs().median() < 0.2
    # empty-space skipping culls part of the box
    assert model.occupancy.fraction_occupied < 0.9


def test_expected_depth_of_a_hard_sphere(sphere_dataset):
    """The exact sphere written into a grid: depth within half a voxel plus a step."""
    test_set = load_dataset(sphere_dataset, "test", resolution=None)
    field = GridField(test_set.aabb, resolution=49, step_m=0.04)
    nx, ny, nz = field.resolution
    z, y, x = torch.meshgrid(*[torch.linspace(-1, 1, n) for n in (nz, ny, nx)], indexing="ij")
    with torch.no_grad():
        field.density_grid[0, 0] = torch.where((x**2 + y**2 + z**2).sqrt() < RADIUS_M, 60.0, -30.0)
    model = RadianceField(field, OccupancyGrid.for_grid_field(field), 0.01, test_set.background, {})
    out = render_views(model, test_set.poses, test_set.intrinsics)
    _, alpha, depth = sphere_views(test_set.poses, test_set.intrinsics)
    inner = torch.nn.functional.max_pool2d(1 - alpha[:, None], 3, 1, 1)[:, 0] == 0
    assert torch.allclose(out["opacity"][inner], torch.ones(1), atol=1e-4)
    assert (out["depth"][inner] - depth[inner]).abs().max() < 1 / 48 + 0.01 + 0.04


def test_save_load_round_trip(sphere_run, tmp_path):
    from renderer import save_model

    result, _, test_set = sphere_run
    path = save_model(result.model, tmp_path / "model.pt")
    loaded = load_model(path)
    a = render_views(result.model, test_set.poses[:1], test_set.intrinsics)
    b = render_views(loaded, test_set.poses[:1], test_set.intrinsics)
    assert torch.equal(a["rgb"], b["rgb"]) and torch.equal(a["depth"], b["depth"])


def test_vanilla_mlp_learns(sphere_dataset):
    train_set = load_dataset(sphere_dataset, "train", resolution=16)
    result = train(
        train_set,
        TrainConfig(field="mlp", max_steps=120, mlp_batch_rays=512, mlp_width=64, **FAST),
        generator=torch.Generator().manual_seed(0),
        eval_dataset=train_set.subset([0, 5]),
    )
    assert result.curve[-1]["psnr"] > result.curve[0]["psnr"] + 2


def test_config_validation():
    with pytest.raises(KeyError, match="grid"):
        TrainConfig(field="hash")
    with pytest.raises(ValueError, match="max_seconds"):
        TrainConfig(max_seconds=0)
    with pytest.raises(ValueError, match="stage_starts"):
        TrainConfig(grid_resolutions=(32, 64), stage_starts=(0.5, 0.1))
    with pytest.raises(KeyError, match="wall"):
        TrainConfig(clock="gpu")


def test_grid_settings_by_image_size():
    """Up to 299 px the defaults (the pipeline's views among them); from 300 px a finer last
    grid with more rays per step."""
    from renderer import TrainConfig

    for px in (64, 100, 128, 200, 299):
        assert TrainConfig.for_resolution(px) == TrainConfig()
    large = TrainConfig.for_resolution(400)
    assert large.grid_resolutions[-1] > TrainConfig().grid_resolutions[-1]
    assert large.batch_rays > TrainConfig().batch_rays
    assert TrainConfig.for_resolution(400, max_seconds=5.0).max_seconds == 5.0

"""The lightweight renderer: starts as bilinear upsampling, learns to beat it on a path."""

import pytest
import torch

from renderer import (
    GridField,
    LightweightConfig,
    OccupancyGrid,
    RadianceField,
    image_metrics,
    load_dataset,
    orbit_path,
    render_views,
    train_lightweight,
)


@pytest.fixture(scope="module")
def sphere_model(sphere_dataset):
    """The exact sphere written into a grid field (no training needed)."""
    from sphere_scene import RADIUS_M

    train_set = load_dataset(sphere_dataset, "train", resolution=None)
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
    model = RadianceField(
        field, occ, 0.04, train_set.background, {"field": "grid", "resolution": 49, "step_m": 0.04}
    )
    return model, train_set


def test_lightweight_learns_and_renders_a_path(sphere_model):
    model, train_set = sphere_model
    cfg = LightweightConfig(
        downsample=4, buffer_frames=2, train_seconds=6, num_sequences=8, progress=False
    )
    lw, stats = train_lightweight(model, train_set, cfg, torch.Generator().manual_seed(0))
    assert stats["steps"] > 5 and stats["final_loss"] < 0.05
    path = orbit_path(6, 2.5, 15.0, start_azimuth_deg=10.0, arc_deg=15.0)
    intr = train_set.intrinsics
    out = lw.render_path(path, intr)
    assert out["rgb"].shape == (6, 32, 32, 3) and out["seconds_per_view"] > 0
    full = render_views(model, path, intr)["rgb"]
    # the untrained decoder (zero last layer) is exactly bilinear upsampling
    lw.decoder.out.weight.data.zero_()
    lw.decoder.out.bias.data.zero_()
    step_m = model.step_m * cfg.low_res_step_factor
    lowres = render_views(model, path, intr, 8, 8, step_m=step_m)["rgb"].permute(0, 3, 1, 2)
    bilinear = torch.nn.functional.interpolate(
        lowres, size=(32, 32), mode="bilinear", align_corners=False
    )
    plain = lw.render_path(path, intr)["rgb"]
    # the first frame is a keyframe (every 16th by default): the full rendering itself
    assert torch.equal(plain[0], full[0].clamp(0, 1)) and torch.equal(out["rgb"][0], plain[0])
    assert torch.allclose(plain[1:], bilinear.permute(0, 2, 3, 1)[1:].clamp(0, 1), atol=1e-5)
    # and training improved on it
    assert (
        image_metrics(out["rgb"][1:], full[1:])["psnr"] > image_metrics(plain[1:], full[1:])["psnr"]
    )


def test_config_validation():
    with pytest.raises(ValueError, match="downsample"):
        LightweightConfig(downsample=0)
    with pytest.raises(ValueError, match="buffer_frames"):
        LightweightConfig(buffer_frames=-1)

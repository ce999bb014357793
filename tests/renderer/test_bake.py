"""Baking the field into the feature grid (its colour and density queried at the grid's
vertices), the break-even view count, and a short baked-then-fine-tuned setup."""

import math

import pytest
import torch
from torch import nn

from renderer import (
    FeatureConfig,
    FeatureRenderer,
    GridField,
    OccupancyGrid,
    RadianceField,
    TeacherPool,
    bake_field,
    break_even_views,
    image_metrics,
    render_views,
    train_features,
)

AABB = torch.tensor([[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]])


def _linear_grid_field(step_m: float = 0.1) -> RadianceField:
    """A grid field whose raw density and colour logits are linear in position (which
    trilinear interpolation reproduces exactly between its vertices)."""
    field = GridField(AABB, resolution=5, step_m=step_m)
    nx, ny, nz = field.resolution
    z, y, x = torch.meshgrid(*(torch.linspace(-1, 1, n) for n in (nz, ny, nx)), indexing="ij")
    with torch.no_grad():
        field.density_grid[0, 0] = 2.0 * x - y + 0.5 * z
        field.color_grid[0] = torch.stack([x, 0.5 * y, -z])
    return RadianceField(field, OccupancyGrid.for_grid_field(field), step_m, (1, 1, 1), {})


class _AnalyticField(nn.Module):
    """sigma = 3 |p|^2, rgb = (0.2, 0.5, 0.7) everywhere: an MLP-like field."""

    def __init__(self):
        super().__init__()
        self.aabb = AABB

    def density(self, points):
        return 3.0 * points.square().sum(-1)

    def forward(self, points, directions=None):
        rgb = torch.tensor([0.2, 0.5, 0.7]).expand(points.shape[0], 3)
        return self.density(points), rgb


def test_baking_reproduces_a_grid_fields_density_and_colour_at_the_vertices():
    model = _linear_grid_field(step_m=0.1)
    bias = float(model.field.density_bias)
    colour, opacity = bake_field(model, (3, 2, 5))  # z, y, x vertices
    assert colour.shape == (30, 3) and opacity.shape == (30,)
    # vertex (iz, iy, ix) sits at x = -1 + ix / 2, y = -1 + 2 iy, z = -1 + iz: by hand
    for iz, iy, ix in [(0, 0, 0), (1, 1, 3), (2, 0, 4), (2, 1, 1)]:
        x, y, z = -1 + ix / 2, -1 + 2 * iy, -1 + iz
        row = (iz * 2 + iy) * 5 + ix
        assert colour[row].tolist() == pytest.approx([x, 0.5 * y, -z], abs=1e-5)
        sigma = math.log1p(math.exp(2 * x - y + 0.5 * z + bias))  # softplus
        assert float(opacity[row]) == pytest.approx(1 - math.exp(-sigma * 0.1), rel=1e-4)


def test_baking_queries_any_field_directly():
    field = _AnalyticField()
    model = RadianceField(field, OccupancyGrid(AABB, (4, 4, 4)), 0.05, (1, 1, 1), {})
    colour, opacity = bake_field(model, (2, 2, 2))  # the box's eight corners
    assert torch.allclose(colour, torch.logit(torch.tensor([0.2, 0.5, 0.7])).expand(8, 3))
    assert torch.allclose(opacity, torch.full((8,), 1 - math.exp(-9.0 * 0.05)))


def test_the_renderer_starts_from_the_baked_field(sphere_model):
    model, _ = sphere_model
    cfg = FeatureConfig(channels=6, bake_density=True, progress=False)
    rend = FeatureRenderer(model, cfg)
    colour, opacity = bake_field(model, rend.grid_shape)
    assert torch.equal(rend.grid[:, :3], colour)
    assert torch.equal(rend.grid[:, 3], opacity)
    assert 0 < float(opacity.mean()) < 0.5 and float(opacity.max()) > 0.9  # the sphere
    assert not rend.grid[:, 4:].any()
    plain = FeatureRenderer(model, FeatureConfig(channels=6, progress=False))
    assert not plain.grid[:, 3:].any()  # without bake_density the free channels start at 0
    with pytest.raises(ValueError, match="bake_density"):
        FeatureRenderer(model, FeatureConfig(channels=3, bake_density=True))


def test_break_even_is_setup_over_the_time_saved_per_view():
    assert break_even_views(60.0, 0.03, 0.15) == 500  # 60 s / 0.12 s
    assert break_even_views(2280.0, 0.029, 0.150) == math.ceil(2280 / 0.121)
    assert break_even_views(10.0, 0.2, 0.15) is None  # slower than the full render: never
    assert break_even_views(10.0, 0.15, 0.15) is None
    assert break_even_views(0.0, 0.2, 0.15) == 0  # no setup


def test_focused_draws_follow_the_teachers_errors(sphere_model):
    model, train_set = sphere_model
    pool = TeacherPool(model, train_set.poses[:4], train_set.intrinsics, 4)
    pool.render_next(4)
    pool.record_errors(torch.tensor([0, 1, 2, 3]), torch.tensor([1e-4, 1e-4, 1e-4, 9.7e-3]))
    g = torch.Generator().manual_seed(0)
    drawn = torch.cat([pool.sample(10, g, focus=1.0) for _ in range(100)])
    assert 0.93 < float((drawn == 3).float().mean()) < 1.0
    uniform = torch.cat([pool.sample(10, g) for _ in range(100)])
    assert 0.18 < float((uniform == 3).float().mean()) < 0.32
    half = pool.sample(10, g, focus=0.5)
    assert half.shape == (10,)


def test_a_short_baked_setup_within_its_cpu_budget_approaches_the_full_render(sphere_model):
    model, train_set = sphere_model
    cfg = FeatureConfig(
        channels=8,
        extra_views=8,
        batch_size=2,
        train_steps=None,
        setup_cpu_seconds=3.0,
        bake_density=True,
        focus=0.5,
        progress=False,
    )
    rend, stats = train_features(model, train_set, cfg, torch.Generator().manual_seed(0))
    assert stats["steps"] > 5 and stats["cpu_budget_seconds"] == 3.0
    assert stats["cpu_seconds"] < 3.0 + 1.5  # the budget, and the step that crossed it
    poses, intr = train_set.poses[:4], train_set.intrinsics
    full = render_views(model, poses, intr)["rgb"]
    start = FeatureRenderer(model, cfg).render_path(poses, intr)["rgb"]
    tuned = rend.render_path(poses, intr)["rgb"]
    before = image_metrics(start, full)["psnr"]
    after = image_metrics(tuned, full)["psnr"]
    assert after > before + 1.0 and after > 25.0

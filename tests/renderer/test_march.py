"""Early ray termination in the feature renderer's low-resolution pass: the same image as
marching every sample, from fewer density evaluations per ray."""

import pytest
import torch

from renderer import FeatureConfig, FeatureRenderer, orbit_path
from renderer.cameras import camera_rays
from renderer.feature_renderer import low_res_intrinsics
from renderer.march import march_until_opaque
from renderer.sampler import sample_along_rays
from renderer.volume import packed_sum


def _rays(model, train_set, downsample=2):
    lo = low_res_intrinsics(train_set.intrinsics, downsample)
    o, d = camera_rays(orbit_path(3, 2.5, 10.0), lo)
    return o.reshape(-1, 3), d.reshape(-1, 3)


def test_early_termination_keeps_the_image_and_drops_samples_per_ray(sphere_model):
    """Ending rays once their transmittance is below 1e-3 changes a rendered image by less
    than 2e-3 (and the opacity by less than 1e-3), keeps the same weighted samples (their weights
    equal up to the rounding of their t), and
    evaluates the density at fewer than 60 % of the samples: never more on any ray,
    fewer on every ray that hits the sphere (segments of four samples)."""
    model, train_set = sphere_model
    poses, intr = orbit_path(3, 2.5, 10.0), train_set.intrinsics
    renders, passes = [], []
    for eps in (0.0, 1e-3):
        cfg = FeatureConfig(channels=5, step_factor=1.3, min_transmittance=eps, progress=False)
        rend = FeatureRenderer(model, cfg)
        with torch.no_grad():
            rend.grid.normal_(generator=torch.Generator().manual_seed(1))
        renders.append(rend.render_path(poses, intr)["rgb"])
        passes.append(rend.low_res_passes(poses, intr))
    assert float((renders[0] - renders[1]).abs().max()) < 2e-3
    for every, ended in zip(*passes):
        assert torch.equal(every.rays, ended.rays)
        assert torch.allclose(every.weights, ended.weights, atol=5e-4)
        assert torch.allclose(every.positions, ended.positions, atol=1e-5)
        assert float((every.opacity - ended.opacity).abs().max()) < 1e-3

    o, d = _rays(model, train_set)
    step = model.step_m * 1.3
    s = sample_along_rays(o, d, model.aabb, step, model.occupancy)
    all_samples = torch.bincount(s.ray_indices, minlength=o.shape[0])
    run = march_until_opaque(
        o, d, model.aabb, step, model.occupancy, model.field.density, 1e-3, 0.0, chunk=4
    )
    hit = run.opacity > 0.999
    assert hit.float().mean() > 0.1
    assert bool((run.evaluated <= all_samples).all())
    assert bool((run.evaluated[hit] < all_samples[hit]).all())
    assert int(run.evaluated.sum()) < 0.6 * int(all_samples.sum())
    # the opacity is the sum of the weights up to where the ray ended
    total = packed_sum(run.weights, run.rays, o.shape[0])
    assert torch.allclose(total, run.opacity, atol=1e-5)


def test_below_150_px_marches_every_sample():
    """The pipeline's small views keep their settings; from 150 px rays end once opaque
    and the step is finer."""
    small, mid = FeatureConfig.for_resolution(80), FeatureConfig.for_resolution(200)
    assert small.min_transmittance == 0.0 and small.step_factor == FeatureConfig().step_factor
    assert 0 < mid.min_transmittance <= mid.weight_threshold
    assert mid.step_factor < small.step_factor


@pytest.mark.parametrize("value", [-0.1, 1.0])
def test_min_transmittance_validation_names_the_field(value):
    with pytest.raises(ValueError, match="min_transmittance"):
        FeatureConfig(min_transmittance=value)


def test_empty_distance_is_the_chebyshev_distance_to_the_nearest_occupied_cell():
    from renderer.sampler import OccupancyGrid

    g = OccupancyGrid(torch.tensor([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]]), (9, 7, 5))
    g.occupied = torch.rand(5, 7, 9, generator=torch.Generator().manual_seed(3)) > 0.97
    dist = g.empty_distance(cap=4)
    occ = g.occupied.nonzero().float()  # [n, 3] (z, y, x)
    cells = torch.stack(torch.meshgrid(*(torch.arange(n) for n in (5, 7, 9)), indexing="ij"), -1)
    brute = (cells.reshape(-1, 1, 3).float() - occ).abs().amax(-1).amin(-1).reshape(5, 7, 9)
    assert torch.equal(dist, brute.clamp(max=4))
    g.occupied = torch.zeros_like(g.occupied)  # the cache follows the grid
    assert bool((g.empty_distance(cap=4) == 4).all())


def test_skipping_empty_cells_evaluates_the_same_samples_from_fewer_candidates(
    sphere_model, monkeypatch
):
    """Jumping ahead by the distance to the nearest occupied cell passes only steps in
    empty cells: the same density evaluations and weights per ray as stepping through
    them, from fewer occupancy lookups (segments of one step, so that both end each ray
    at the same sample)."""
    model, train_set = sphere_model
    o, d = _rays(model, train_set)
    step = model.step_m * 1.3
    occ = model.occupancy
    looked_up = []
    query = occ.query_along

    def counting(origins, directions, rays, t, inside_only):
        looked_up[-1] += t.numel()
        return query(origins, directions, rays, t, inside_only)

    monkeypatch.setattr(occ, "query_along", counting)  # undone even if an assertion fails
    runs = []
    for hops in (0, 2):
        looked_up.append(0)
        runs.append(
            march_until_opaque(o, d, model.aabb, step, occ, model.field.density, 1e-3, 0.0, 1, hops)
        )
    every, skipped = runs
    assert looked_up[1] < 0.8 * looked_up[0]
    assert torch.equal(every.evaluated, skipped.evaluated) and int(every.evaluated.sum()) > 0
    assert torch.equal(every.rays, skipped.rays)
    assert torch.allclose(every.positions, skipped.positions, atol=1e-5)
    assert torch.allclose(every.weights, skipped.weights, atol=1e-6)

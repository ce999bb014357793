"""Eq. 4 by hand: transmittance, alpha, weights, expected depth; packed == dense."""

import math

import torch

from renderer import (
    GridField,
    Intrinsics,
    OccupancyGrid,
    RadianceField,
    alpha_from_density,
    composite,
    expected_depth,
    look_at,
    packed_render,
    render_views,
    render_weights,
    transmittance,
)


def test_two_samples_by_hand():
    sigma = torch.tensor([[1.0, 2.0]])
    delta = torch.tensor([[0.5, 0.5]])
    t = torch.tensor([[1.0, 1.5]])
    a0, a1 = 1 - math.exp(-0.5), 1 - math.exp(-1.0)
    t1 = math.exp(-0.5)
    assert torch.allclose(alpha_from_density(sigma, delta), torch.tensor([[a0, a1]]))
    assert torch.allclose(transmittance(sigma, delta), torch.tensor([[1.0, t1]]))
    w = render_weights(sigma, delta)
    assert torch.allclose(w, torch.tensor([[a0, t1 * a1]]))
    # worked numbers of the module docstring
    assert torch.allclose(w, torch.tensor([[0.3935, 0.3834]]), atol=1e-4)
    assert math.isclose(w.sum().item(), 1 - math.exp(-1.5), rel_tol=1e-6)
    assert torch.allclose(expected_depth(w, t), torch.tensor([a0 * 1.0 + t1 * a1 * 1.5]))
    c = torch.tensor([[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]])
    bg = torch.tensor([0.0, 0.0, 1.0])
    out = composite(w, c, bg)
    assert torch.allclose(out, torch.tensor([[a0, t1 * a1, math.exp(-1.5)]]), atol=1e-6)


def test_opaque_first_sample_hides_the_rest():
    w = render_weights(torch.tensor([[1e4, 5.0, 5.0]]), torch.full((1, 3), 0.1))
    assert torch.allclose(w, torch.tensor([[1.0, 0.0, 0.0]]), atol=1e-6)


def test_weights_sum_at_most_one_and_packed_equals_dense():
    g = torch.Generator().manual_seed(1)
    sigma = torch.rand(5, 7, generator=g) * 10
    sigma[2] = 0.0
    delta = torch.rand(5, 7, generator=g) * 0.3
    t = torch.cumsum(delta, -1)
    rgb = torch.rand(5, 7, 3, generator=g)
    w = render_weights(sigma, delta)
    assert (w.sum(-1) <= 1 + 1e-6).all() and (w >= 0).all()
    # pack, dropping a few zero-density samples as the sampler would
    keep = torch.ones(5, 7, dtype=torch.bool)
    keep[2] = False  # an empty ray
    keep[0, 3] = False
    sigma_k = sigma.clone()
    sigma_k[0, 3] = 0.0
    w_dense = render_weights(sigma_k, delta)
    ray_idx = torch.arange(5)[:, None].expand(5, 7)[keep]
    bg = torch.tensor([0.2, 0.4, 0.6])
    out = packed_render(sigma_k[keep], rgb[keep], t[keep], delta[keep], ray_idx, 5, bg)
    assert torch.allclose(out["opacity"], w_dense.sum(-1), atol=1e-6)
    assert torch.allclose(out["rgb"], composite(w_dense, rgb, bg), atol=1e-6)
    assert torch.allclose(out["depth"], expected_depth(w_dense, t), atol=1e-6)
    assert torch.allclose(out["rgb"][2], bg)


def test_empty_field_renders_the_background():
    aabb = torch.tensor([[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]])
    field = GridField(aabb, resolution=8, step_m=0.1)
    with torch.no_grad():
        field.density_grid.fill_(-100.0)  # softplus(-100 + bias) ~ 0
    occ = OccupancyGrid.for_grid_field(field)
    bg = (0.1, 0.7, 0.3)
    model = RadianceField(field, occ, 0.1, bg, {"field": "grid", "resolution": 8, "step_m": 0.1})
    pose = look_at(torch.tensor([0.0, -3.0, 1.0]), torch.zeros(3))[None]
    out = render_views(model, pose, Intrinsics(20.0, 20.0, 8.0, 8.0, 16, 16))
    assert torch.allclose(out["rgb"], torch.tensor(bg).expand(1, 16, 16, 3), atol=1e-5)
    assert out["opacity"].max() < 1e-5
    # and once the occupancy grid has seen the empty field, nothing is sampled at all
    occ.update(field.density, 0.1, vertex_density=field.vertex_density())
    assert occ.fraction_occupied == 0.0
    out2 = render_views(model, pose, Intrinsics(20.0, 20.0, 8.0, 8.0, 16, 16))
    assert torch.equal(out2["rgb"], torch.tensor(bg).expand(1, 16, 16, 3))


def test_renders_skip_only_the_colour_of_negligible_samples():
    """In training and eval mode a grid field's colour is read only where the weight
    exceeds COLOR_WEIGHT_MIN: the same as eq. 4 with those samples' colours set to zero
    (their weights still count in opacity and depth)."""
    from renderer.model import COLOR_WEIGHT_MIN
    from renderer.sampler import sample_along_rays

    g = torch.Generator().manual_seed(3)
    aabb = torch.tensor([[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]])
    field = GridField(aabb, resolution=8, step_m=0.1)
    with torch.no_grad():
        field.set_sh_degree(1)
        field.density_grid.normal_(generator=g).mul_(4.0)
        field.color_grid.normal_(generator=g)
    occ = OccupancyGrid.for_grid_field(field)
    bg = torch.tensor([0.1, 0.7, 0.3])
    model = RadianceField(field, occ, 0.1, tuple(bg.tolist()), {"field": "grid"})
    origins = torch.tensor([[0.0, -3.0, 0.2]]).expand(16, 3)
    dirs = torch.nn.functional.normalize(
        torch.randn(16, 3, generator=g) * 0.2 + torch.tensor([0, 1.0, 0]), dim=-1
    )
    s = sample_along_rays(origins, dirs, aabb, 0.1, occ)
    sigma, rgb = field(s.positions, s.directions)
    full = packed_render(sigma, rgb, s.t, s.deltas, s.ray_indices, 16, bg)
    small = full["weights"] <= COLOR_WEIGHT_MIN
    assert 0 < int(small.sum()) < small.numel()  # the case is exercised
    expected = packed_render(sigma, rgb * ~small[:, None], s.t, s.deltas, s.ray_indices, 16, bg)
    for mode in (True, False):
        model.train(mode)
        with torch.set_grad_enabled(mode):
            out = model.render_rays(origins, dirs)
        assert torch.allclose(out["rgb"], expected["rgb"], atol=1e-6)
        assert torch.allclose(out["opacity"], full["opacity"], atol=1e-6)
        assert torch.allclose(out["depth"], full["depth"], atol=1e-6)
    assert not torch.allclose(out["rgb"], full["rgb"], atol=1e-6)  # skipping changed it

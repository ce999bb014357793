"""The feature renderer (eq. 5): features composited with the field's own weights, a decoder
that starts as bilinear upsampling and learns to approach the full render."""

import math

import pytest
import torch

from renderer import (
    FeatureConfig,
    FeatureRenderer,
    Intrinsics,
    TeacherPool,
    image_metrics,
    orbit_path,
    render_views,
    train_features,
)
from renderer.feature_renderer import low_res_intrinsics
from renderer.fields import trilinear
from renderer.teacher_cameras import jittered_poses


def test_composite_uses_the_fields_weights(sphere_model):
    """F = sum_i w_i f_i + (1 - sum_i w_i) f_bg with the eq. 4 weights of the low-resolution
    pass: with a constant feature v it is opacity * v + (1 - opacity) * bg, and the opacity
    plane is the field's own low-resolution opacity at the coarse step."""
    model, train_set = sphere_model
    cfg = FeatureConfig(channels=5, downsample=2, step_factor=2.0, weight_threshold=0.0)
    rend = FeatureRenderer(model, cfg)
    v = torch.tensor([0.3, -1.0, 2.0, 0.5, 4.0])
    with torch.no_grad():
        rend.grid.copy_(v.expand_as(rend.grid))
        rend.background.copy_(torch.tensor([1.0, 0.0, -2.0, 0.0, 0.0]))
    pose, intr = train_set.poses[3], train_set.intrinsics
    with torch.no_grad():
        f = rend.features(rend.low_res_pass(pose, intr))[0]  # [6, 16, 16]
    ref = render_views(model, pose[None], intr, 16, 16, step_m=model.step_m * 2.0)["opacity"][0]
    assert torch.allclose(f[5], ref, atol=1e-5)
    assert 0.05 < float((ref > 0.99).float().mean()) < 0.8  # the sphere and the background
    expected = ref[None] * v[:, None, None] + (1 - ref[None]) * rend.background[:, None, None]
    assert torch.allclose(f[:5], expected, atol=1e-4)
    # dropping samples under the threshold loses at most their weight
    rend.config = FeatureConfig(channels=5, downsample=2, step_factor=2.0, weight_threshold=1e-3)
    with torch.no_grad():
        p = rend.low_res_pass(pose, intr)
        g = rend.features(p)[0]
    assert p.weights.min() > 1e-3
    assert torch.allclose(g[5], f[5])
    assert float((g[:5] - f[:5]).abs().max()) <= 0.05 * float(v.abs().max())


def test_starts_as_bilinear_and_learns_toward_the_full_render(sphere_model, capsys):
    model, train_set = sphere_model
    cfg = FeatureConfig(
        channels=8, downsample=2, extra_views=8, train_seconds=4, batch_size=2, progress=False
    )
    rend, stats = train_features(model, train_set, cfg, torch.Generator().manual_seed(0))
    assert stats["steps"] > 5 and stats["teacher_views"] == train_set.num_views + 8
    # the 4 s cap ended it long before the default steps, and it says so
    assert stats["capped_by_seconds"] and stats["steps"] < cfg.train_steps
    assert f"reached after {stats['steps']} of {cfg.train_steps} steps" in capsys.readouterr().err
    path = orbit_path(5, 2.5, 12.0, start_azimuth_deg=7.0, arc_deg=20.0)
    intr = train_set.intrinsics
    out = rend.render_path(path, intr)
    assert out["rgb"].shape == (5, 32, 32, 3) and out["seconds_per_view"] > 0
    full = render_views(model, path, intr)["rgb"].clamp(0, 1)
    start = FeatureRenderer(model, cfg)  # zero last layer: bilinear of the colour logits
    with torch.no_grad():
        planes = torch.cat([start.features(start.low_res_pass(p, intr)) for p in path])
    bilinear = torch.sigmoid(
        torch.nn.functional.interpolate(planes[:, :3], scale_factor=2, mode="bilinear")
    ).permute(0, 2, 3, 1)
    plain = start.render_path(path, intr)["rgb"]
    assert torch.allclose(plain, bilinear, atol=1e-5)
    assert image_metrics(out["rgb"], full)["psnr"] > image_metrics(plain, full)["psnr"] + 1.0


def test_view_dependent_colour_starts_as_the_fields(sphere_model):
    """With an SH degree-1 colour the first 12 channels hold the field's coefficients and
    the decoder's base is their composite times each ray's basis: at full resolution and the
    field's own step, opaque pixels start exactly at the field's view-dependent colour
    (every sample of a ray has the same colour here), seen differently from opposite sides."""
    import copy

    model, train_set = sphere_model
    model = copy.deepcopy(model)
    model.field.set_sh_degree(1)
    with torch.no_grad():
        coef = model.field.color_grid.reshape(3, 4, *model.field.color_grid.shape[2:])
        coef[:, 0] = torch.tensor([0.2, -0.3, 0.5])[:, None, None, None]  # uniform colour
        coef[:, 1:] = torch.tensor([[1.5, 0.0, -1.0], [0.0, 2.0, 0.0], [-1.0, 0.5, 1.0]])[
            :, :, None, None, None
        ]
    cfg = FeatureConfig(channels=14, downsample=1, step_factor=1.0, weight_threshold=0.0)
    rend = FeatureRenderer(model, cfg)
    assert rend.sh_degree == 1
    intr = train_set.intrinsics
    colours = []
    for pose in train_set.poses[[0, 5]]:
        with torch.no_grad():
            p = rend.low_res_pass(pose, intr)
            out = rend.decode([p], intr.height, intr.width)[0]
        ref = render_views(model, pose[None], intr)
        opaque = ref["opacity"][0] > 0.9999  # background logits weigh < 1e-4
        assert int(opaque.sum()) > 20
        assert torch.allclose(out[opaque], ref["rgb"][0][opaque], atol=5e-4)
        colours.append(out[opaque].mean(0))
    assert float((colours[0] - colours[1]).abs().max()) > 0.05
    with pytest.raises(ValueError, match="channels must be >= 12"):
        FeatureRenderer(model, FeatureConfig(channels=8))


def test_sample_colour_starts_as_the_full_render_at_every_pixel(sphere_model):
    """Compositing each sample's colour (``sample_colour``), not its logits, reproduces the
    field's own image at full resolution and its step, the sphere's soft edge and a colour
    that varies along the rays included; composited logits are off at those pixels. The
    decoder's gradient reaches the grid through the per-sample colours."""
    import copy

    model, train_set = sphere_model
    model = copy.deepcopy(model)
    model.field.set_sh_degree(1)
    with torch.no_grad():
        grid = model.field.color_grid
        grid.copy_(2.0 * torch.randn(grid.shape, generator=torch.Generator().manual_seed(3)))
    pose, intr = train_set.poses[2], train_set.intrinsics
    ref = render_views(model, pose[None], intr)["rgb"][0]
    errors = {}
    for sample_colour in (True, False):
        cfg = FeatureConfig(
            channels=13,
            downsample=1,
            step_factor=1.0,
            weight_threshold=0.0,
            sample_colour=sample_colour,
            progress=False,
        )
        out = FeatureRenderer(model, cfg).render_path(pose[None], intr)["rgb"][0]
        errors[sample_colour] = float((out - ref).abs().max())
    assert errors[True] < 2e-3 < 0.05 < errors[False]
    cfg = FeatureConfig(channels=13, sample_colour=True, progress=False)
    rend = FeatureRenderer(model, cfg)
    out = rend.decode([rend.low_res_pass(pose, intr)], intr.height, intr.width)
    (out - ref).square().mean().backward()
    assert float(rend.grid.grad[:, :12].abs().sum()) > 0


def test_reads_are_trilinear_and_their_sparse_gradient_is_the_dense_one(sphere_model):
    """The vertex-major read equals ``F.grid_sample``'s trilinear interpolation of the same
    grid, and its sparse gradient, added into a zeroed ``.grad``, equals autograd's dense
    gradient of that interpolation."""
    model, train_set = sphere_model
    rend = FeatureRenderer(model, FeatureConfig(channels=5, progress=False))
    g = torch.Generator().manual_seed(1)
    pts = model.aabb[0] + (model.aabb[1] - model.aabb[0]) * torch.rand(500, 3, generator=g)
    with torch.no_grad():
        rend.grid.normal_(generator=g)
        fast = rend.read(pts)
    nz, ny, nx = rend.grid_shape
    dense = rend.grid.detach().t().reshape(1, 5, nz, ny, nx).clone().requires_grad_()
    ref = trilinear(dense, model.aabb, pts)
    assert torch.allclose(fast, ref.detach(), atol=1e-5)
    upstream = torch.randn(500, 5, generator=g)
    (ref * upstream).sum().backward()
    rend.grid.grad = torch.zeros_like(rend.grid)
    (rend.read(pts) * upstream).sum().backward()
    expect = dense.grad[0].permute(1, 2, 3, 0).reshape(-1, 5)
    assert not rend.grid.grad.is_sparse
    assert torch.allclose(rend.grid.grad, expect, atol=1e-5)
    assert int((rend.grid.grad.abs().sum(1) > 0).sum()) <= 8 * 500


def test_views_rendered_together_equal_views_rendered_one_by_one(sphere_model):
    """render_batch changes only how many views share an operation, not the images; a
    batch that does not divide the path and a view that sees nothing are handled."""
    model, train_set = sphere_model
    poses = torch.cat([orbit_path(5, 2.5, 10.0), orbit_path(1, 2.5, 10.0)])
    poses[-1, :3, 3] = torch.tensor([0.0, 0.0, 50.0])  # far above, looking away: empty
    poses[-1, :3, :3] = torch.diag(torch.tensor([1.0, -1.0, -1.0])) @ poses[-1, :3, :3]
    g = torch.Generator().manual_seed(3)
    renders = []
    for b in (1, 4):
        rend = FeatureRenderer(model, FeatureConfig(channels=5, render_batch=b, progress=False))
        with torch.no_grad():
            rend.grid.normal_(generator=g.manual_seed(3))
        renders.append(rend.render_path(poses, train_set.intrinsics)["rgb"])
    assert torch.allclose(renders[0], renders[1], atol=1e-5)
    single = rend.low_res_pass(poses[0], train_set.intrinsics)
    together = rend.low_res_passes(poses[:3], train_set.intrinsics)[0]
    assert torch.equal(single.rays, together.rays)
    assert torch.allclose(single.weights, together.weights)
    assert rend.low_res_passes(poses[-2:], train_set.intrinsics)[1].weights.numel() == 0


def test_sizes_the_downsample_does_not_divide(sphere_model):
    model, _ = sphere_model
    intr = Intrinsics(30.0, 30.0, 16.5, 15.5, 33, 31)
    lo = low_res_intrinsics(intr, 2)
    assert (lo.height, lo.width) == (17, 16) and lo.fx == 15.0 and lo.cx == 8.25
    rend = FeatureRenderer(model, FeatureConfig(channels=4, downsample=2, progress=False))
    out = rend.render_path(orbit_path(2, 2.5, 10.0), intr)
    assert out["rgb"].shape == (2, 33, 31, 3)


def test_jittered_cameras_keep_their_distance_and_stay_within_the_jitter(sphere_model):
    _, train_set = sphere_model
    up, center = torch.tensor([0.0, 0.0, 1.0]), torch.zeros(3)
    poses = train_set.poses[:4]
    out = jittered_poses(poses, up, center, 12, 10.0, torch.Generator().manual_seed(0))
    assert out.shape == (12, 4, 4)
    for j, p in enumerate(out):
        src = poses[j % 4]
        assert float((p[:3, 3] - center).norm()) == pytest.approx(
            float((src[:3, 3] - center).norm()), rel=1e-5
        )
        rot = src[:3, :3].t() @ p[:3, :3]  # relative rotation, at most 10 + 5 degrees
        angle = math.degrees(math.acos(max(-1.0, min(1.0, (float(rot.trace()) - 1) / 2))))
        assert angle <= 15.0 + 1e-3


@pytest.mark.parametrize(
    "field, value",
    [
        ("channels", 2),
        ("downsample", 0),
        ("step_factor", 0.5),
        ("weight_threshold", 1.0),
        ("extra_views", -1),
        ("train_seconds", 0.0),
    ],
)
def test_config_validation_names_the_field(field, value):
    with pytest.raises(ValueError, match=field):
        FeatureConfig(**{field: value})


def test_teacher_pool_holds_at_most_its_capacity_and_replaces_the_oldest(sphere_model):
    """Each held image is the 8-bit full render of the camera it is filed under, the pool
    never holds more than its capacity, and the newest renders replace the oldest."""
    model, train_set = sphere_model
    poses, intr = train_set.poses[:7], train_set.intrinsics
    pool = TeacherPool(model, poses, intr, capacity=3)
    assert pool.images.shape == (3, intr.height, intr.width, 3)
    assert pool.images.dtype == torch.uint8
    pool.render_next(2)
    assert (pool.held, pool.rendered, pool.remaining) == (2, 2, 5)
    pool.render_next(3)  # cameras 2, 3, 4: camera 3 and 4 replace 0 and 1
    assert (pool.held, pool.rendered) == (3, 5) and sorted(pool.index.tolist()) == [2, 3, 4]
    pool.render_next(100)  # only what is left
    assert pool.rendered == 7 and pool.remaining == 0
    full = render_views(model, poses, intr)["rgb"].clamp(0, 1)
    for slot, cam in enumerate(pool.index.tolist()):
        assert (pool.images[slot].float() / 255 - full[cam]).abs().max() <= 0.5 / 255 + 1e-6
    slots = pool.sample(16, torch.Generator().manual_seed(0))
    for pose, image in zip(pool.poses_of(slots), pool.images_of(slots)):
        cam = int(((poses - pose).abs().flatten(1).sum(1) < 1e-6).nonzero()[0])
        assert cam in pool.index.tolist()
        assert (image - full[cam]).abs().max() <= 0.5 / 255 + 1e-6


def test_training_streams_every_teacher_through_a_small_pool_in_its_steps(sphere_model):
    model, train_set = sphere_model
    cfg = FeatureConfig(
        channels=5, extra_views=20, pool_views=4, train_steps=12, batch_size=2, progress=False
    )
    rend, stats = train_features(model, train_set, cfg, torch.Generator().manual_seed(0))
    assert stats["steps"] == 12 and not stats["capped_by_seconds"]
    assert stats["teacher_views"] == train_set.num_views + 20  # all rendered, 4 held at once
    assert stats["cpu_seconds"] > 0 and stats["teacher_size"] == [32, 32]
    small = FeatureConfig(channels=5, extra_views=2, train_steps=2, width_px=16, progress=False)
    _, stats = train_features(model, train_set, small, torch.Generator().manual_seed(0))
    assert stats["teacher_size"] == [16, 16]


def test_settings_by_image_size():
    small, mid, large = (FeatureConfig.for_resolution(px) for px in (100, 200, 400))
    assert small == FeatureConfig()
    assert mid.downsample == small.downsample
    # from 150 px the field is baked and fine-tuned on a few hundred teachers within a
    # budget of CPU seconds (no step count), where the error is
    assert mid.bake_density and mid.train_steps is None and mid.setup_cpu_seconds <= 180
    assert mid.extra_views < small.extra_views and mid.focus > 0 == small.focus
    assert large.extra_views < small.extra_views and large.downsample > mid.downsample
    # from 150 px each sample's colour is composited; from 300 px too, baked and within ten
    # CPU-minutes
    assert mid.sample_colour and large.sample_colour and not small.sample_colour
    assert large.bake_density and large.train_steps is None and large.setup_cpu_seconds <= 600
    # the grid (with gradient and two Adam moments) and the pass cache shrink where views are
    # large: their memory, not the teachers', set the 400 px setup peak
    assert large.grid_scale < mid.grid_scale and large.pass_cache_mb < mid.pass_cache_mb
    assert FeatureConfig.for_resolution(400, downsample=2).downsample == 2


def test_kept_passes_equal_recomputed_ones_and_stay_within_their_budget(sphere_model):
    model, train_set = sphere_model
    poses, intr = train_set.poses[:6], train_set.intrinsics
    rend = FeatureRenderer(model, FeatureConfig(channels=5, progress=False))

    def passes(p):
        return rend.low_res_passes(p, intr)

    one = passes(poses[:1])[0].nbytes
    pool = TeacherPool(model, poses, intr, capacity=4, passes=passes, pass_bytes=2 * one + 1)
    pool.render_next(4)
    assert len(pool._passes) <= 2 and pool._held_bytes <= 2 * one + 1
    slots = torch.arange(4)
    for slot, p in zip(slots.tolist(), pool.passes_of(slots)):
        ref = passes(pool.poses_of(torch.tensor([slot])))[0]
        assert torch.equal(p.rays, ref.rays)
        assert torch.allclose(p.weights, ref.weights, atol=1e-4)
    pool.render_next(2)  # replaces slots 0 and 1: their kept passes go with them
    assert pool._held_bytes == sum(p.nbytes for p in pool._passes.values())


def test_distillation_repeats_exactly_from_its_seed(sphere_model):
    """The decoder's first weights come from the generator, not torch's global stream: the
    same seed and steps give the same grid and decoder, whatever ran before."""
    model, train_set = sphere_model
    cfg = FeatureConfig(
        channels=8, downsample=2, extra_views=4, train_steps=20, batch_size=2, progress=False
    )
    runs = []
    for draw in range(2):
        torch.rand(7 + draw)  # move the global stream: it must not matter
        rend, stats = train_features(model, train_set, cfg, torch.Generator().manual_seed(3))
        runs.append((rend, stats["final_loss"]))
    (a, loss_a), (b, loss_b) = runs
    assert loss_a == loss_b and torch.equal(a.grid, b.grid)
    for p, q in zip(a.decoder.parameters(), b.decoder.parameters()):
        assert torch.equal(p, q)
    other, _ = train_features(model, train_set, cfg, torch.Generator().manual_seed(4))
    assert not torch.equal(other.decoder.body[0].weight, a.decoder.body[0].weight)

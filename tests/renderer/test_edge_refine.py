"""Full-resolution rays where the feature renderer's low-resolution pass is unsure: the pixels
picked (edge_mask) and what they are replaced with (the field's own render)."""

import dataclasses

import pytest
import torch

from renderer import FeatureConfig, FeatureRenderer, camera_rays, render_views
from renderer.refine import edge_mask, field_colours, masked_rays


def test_edge_mask_flags_partial_blocks_and_both_sides_of_a_sharp_edge():
    """A low-resolution pixel partly opaque flags its 2 x 2 block (the last block clipped
    to an odd size); a colour step flags the pixels whose 3 x 3 neighbourhood crosses it
    and nothing else; a step below the contrast flags nothing."""
    opacity = torch.tensor([[[0.0, 1.0, 0.5], [0.97, 0.03, 1.0]]])  # [1, 2, 3]
    rgb = torch.zeros(1, 4, 5, 3)  # full resolution 4 x 5: the last column is clipped
    partial = edge_mask(opacity, rgb, 2, partial=0.05, contrast=1.0)
    expected = torch.zeros(1, 4, 5, dtype=torch.bool)
    expected[0, :2, 4] = True  # low-res (0, 2): 0.5, clipped to one column
    assert torch.equal(partial, expected)
    loose = edge_mask(opacity, rgb, 2, partial=0.02, contrast=1.0)
    expected[0, 2:, :4] = True  # (1, 0) at 0.97 and (1, 1) at 0.03 are partial above 0.02
    assert torch.equal(loose, expected)

    step = torch.zeros(1, 4, 5, 3)
    step[0, :, 3:, 1] = 0.4  # green steps up between columns 2 and 3
    sharp = edge_mask(torch.zeros(1, 2, 3), step, 2, partial=0.05, contrast=0.3)
    expected = torch.zeros(1, 4, 5, dtype=torch.bool)
    expected[0, :, 2:4] = True
    assert torch.equal(sharp, expected)
    assert not edge_mask(torch.zeros(1, 2, 3), step, 2, partial=0.05, contrast=0.5).any()
    assert torch.equal(edge_mask(opacity, step, 2, 0.05, 0.3), sharp | partial)


def test_field_colours_are_the_full_render(sphere_model):
    model, train_set = sphere_model
    poses, intr = train_set.poses[:2], train_set.intrinsics
    full = render_views(model, poses, intr)["rgb"]
    o, d = camera_rays(poses, intr)
    rgb = field_colours(model, o.reshape(-1, 3), d.reshape(-1, 3)).reshape(full.shape)
    assert float((rgb - full).abs().max()) < 2e-3


def test_refined_pixels_are_the_full_renders_and_the_others_the_decoders(sphere_model):
    """With refinement on, the flagged pixels (the sphere's silhouette, partly transparent
    at a coarse pass) equal the full render's (to within the refinement's transmittance) and
    every other pixel is the decoded one; with it off (the default) nothing is rendered
    again."""
    model, train_set = sphere_model
    poses, intr = train_set.poses[:3], train_set.intrinsics
    full = render_views(model, poses, intr)["rgb"]
    plain = FeatureRenderer(model, FeatureConfig(channels=5, progress=False))
    cfg = dataclasses.replace(plain.config, refine_partial=0.05, refine_contrast=0.3)
    refined = FeatureRenderer(model, cfg)
    base = plain.render_path(poses, intr)["rgb"]
    out = refined.render_path(poses, intr)["rgb"]
    passes = plain.low_res_passes(poses, intr)
    opacity = torch.stack([p.opacity.reshape(p.size) for p in passes])
    mask = edge_mask(opacity, base, cfg.downsample, 0.05, 0.3)
    assert 0.02 < float(mask.float().mean()) < 0.6
    assert float((out[mask] - full[mask]).abs().max()) < cfg.refine_min_transmittance
    assert torch.equal(out[~mask], base[~mask])
    assert float((out - full).square().mean()) < float((base - full).square().mean())


def test_refined_rays_end_at_the_configured_transmittance(sphere_model):
    """``refine_min_transmittance`` sets where the rays rendered again end: their colours
    are the field's marched to that transmittance, with fewer density evaluations at a
    higher one (the default) than at 1e-4, and within it of each other."""
    model, train_set = sphere_model
    poses, intr = train_set.poses[:2], train_set.intrinsics
    cfg = FeatureConfig(channels=5, progress=False, refine_contrast=0.3, refine_partial=0.05)
    assert cfg.refine_min_transmittance == 1e-2
    runs = {}
    for mt in (1e-4, 0.2):
        rend = FeatureRenderer(model, dataclasses.replace(cfg, refine_min_transmittance=mt))
        passes = rend.low_res_passes(poses, intr)
        rgb = rend.decode(passes, intr.height, intr.width)
        mask = rend.refine_mask(passes, rgb)
        density, calls = model.field.density, []
        model.field.density = lambda p, calls=calls, f=density: calls.append(len(p)) or f(p)
        try:
            out = rend.refine(passes, poses, intr, rgb)
        finally:
            del model.field.density
        o, d = masked_rays(poses, intr, mask)
        expected = field_colours(model, o, d, min_transmittance=mt, weight_threshold=mt / 10)
        assert torch.equal(out[mask], expected)
        runs[mt] = (out, sum(calls))
    (fine, n_fine), (coarse, n_coarse) = runs[1e-4], runs[0.2]
    assert n_coarse < n_fine
    assert 0 < float((fine - coarse).abs().max()) < 0.2


@pytest.mark.parametrize(
    "field, value",
    [
        ("refine_partial", 0.5),
        ("refine_contrast", 0.0),
        ("refine_min_transmittance", 0.0),
    ],
)
def test_refine_settings_are_checked(field, value):
    with pytest.raises(ValueError, match=field):
        FeatureConfig(**{field: value})


def test_distillation_learns_nothing_where_the_field_renders_again(sphere_model):
    """The loss ignores the teachers' colours at the pixels rendered again and counts every
    other pixel; with refinement off it is the plain mean squared error."""
    from renderer.features import distillation_errors

    model, train_set = sphere_model
    poses, intr = train_set.poses[:2], train_set.intrinsics
    teachers = render_views(model, poses, intr)["rgb"]
    plain = FeatureRenderer(model, FeatureConfig(channels=5, progress=False))
    rend = FeatureRenderer(model, dataclasses.replace(plain.config, refine_contrast=0.3))
    passes = rend.low_res_passes(poses, intr)
    out = rend.decode(passes, intr.height, intr.width)
    mask = rend.refine_mask(passes, out)
    assert mask.any() and not mask.all()
    errors = distillation_errors(rend, passes, out, teachers)
    moved = teachers.clone()
    moved[mask] = 1.0 - moved[mask]
    assert torch.equal(distillation_errors(rend, passes, out, moved), errors)
    moved = teachers.clone()
    moved[~mask] = 1.0 - moved[~mask]
    assert (distillation_errors(rend, passes, out, moved) > errors).all()
    expected = (out - teachers).square().mean((1, 2, 3))
    assert torch.equal(distillation_errors(plain, passes, out, teachers), expected)

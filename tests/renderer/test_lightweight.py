"""The lightweight renderer: starts as bilinear upsampling, learns to beat it on a path;
skips what the low-resolution pass shows empty, re-renders what no keyframe explains."""

import pytest
import torch

from renderer import (
    LightweightConfig,
    image_metrics,
    orbit_path,
    render_views,
    train_lightweight,
)


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


def test_reprojection_of_a_known_point():
    """A point 2 m in front of the previous camera, seen by a camera 0.4 m to its right:
    fx * 0.4 / 2 = 2 px to the left, at a pixel centre, at distance 2 * sqrt(1.04)."""
    from renderer import Intrinsics, reproject

    intr = Intrinsics(10.0, 10.0, 4.5, 4.5, 9, 9)
    prev, cur = torch.eye(4), torch.eye(4)
    cur[0, 3] = 0.4
    frame = torch.zeros(3, 9, 9)
    frame[:, 4, 4] = torch.tensor([0.9, 0.5, 0.1])  # the point, at the centre pixel
    prev_depth = torch.full((9, 9), 2.0)
    depth = torch.full((9, 9), 50.0)  # elsewhere: far behind what the previous frame saw
    depth[4, 2] = 2.0 * 1.04**0.5
    warped, valid = reproject(frame, prev_depth, prev, depth, cur, intr)
    assert valid[4, 2] == 1 and valid.sum() == 1
    assert torch.allclose(warped[:, 4, 2], frame[:, 4, 4], atol=1e-6)


@pytest.mark.parametrize("downsample, empty_downsample", [(4, None), (1, 4)])
def test_skipped_pixels_are_exactly_those_the_low_res_pass_shows_empty(
    sphere_model, downsample, empty_downsample
):
    """(4, None): the low-res pass itself decides; (1, 4): a 4x coarser pass decides and a
    full-resolution coarse-step pass marches only the rest."""
    from renderer import LightweightRenderer

    model, train_set = sphere_model
    cfg = LightweightConfig(
        downsample=downsample, empty_downsample=empty_downsample, progress=False
    )
    lw = LightweightRenderer(model, cfg, torch.Generator().manual_seed(0))
    intr = train_set.intrinsics
    pose = orbit_path(1, 2.5, 10.0, start_azimuth_deg=33.0)[0]
    out = lw.render_frame(pose, intr, [])
    # by hand: the 8 x 8 low-res opacity, its max over 3 x 3 neighbours, pixel -> v // 4
    low = render_views(model, pose[None], intr, 8, 8, step_m=model.step_m * 2.0)["opacity"][0]
    expected = torch.zeros(32, 32, dtype=torch.bool)
    for v in range(32):
        for u in range(32):
            lv, lu = v // 4, u // 4
            hood = low[max(lv - 1, 0) : lv + 2, max(lu - 1, 0) : lu + 2]
            expected[v, u] = bool(hood.max() < cfg.empty_opacity)
    assert torch.equal(out["empty"], expected)
    assert 0 < expected.sum() < 32 * 32
    bg = model.background[:, None].expand(3, int(expected.sum()))
    assert torch.equal(out["rgb"][:, expected], bg)
    # and the full render there is the background too
    full = render_views(model, pose[None], intr)["rgb"][0].permute(2, 0, 1)
    assert (full[:, expected] - bg).abs().max() < 0.02
    if downsample == 1:  # the features elsewhere: the full-resolution coarse-step render
        coarse = render_views(model, pose[None], intr, step_m=model.step_m * 2.0)
        feats, _, _ = lw.low_res(pose, intr)
        live = ~expected
        assert torch.allclose(
            feats[:3, live], coarse["rgb"][0].permute(2, 0, 1)[:, live], atol=1e-5
        )


def test_lightweight_output_is_the_full_render_where_it_rerenders(sphere_model):
    from renderer import LightweightRenderer

    model, train_set = sphere_model
    intr = train_set.intrinsics
    cfg = LightweightConfig(downsample=4, rerender=True, progress=False)
    lw = LightweightRenderer(model, cfg, torch.Generator().manual_seed(0))
    poses = orbit_path(2, 2.5, 10.0, start_azimuth_deg=20.0, arc_deg=90.0)  # 45 deg apart
    full = render_views(model, poses, intr)["rgb"].permute(0, 3, 1, 2)
    # nothing buffered: every non-empty pixel is re-rendered
    out = lw.render_frame(poses[1], intr, [])
    assert torch.equal(out["rerendered"], ~out["empty"])
    assert torch.allclose(out["rgb"][:, ~out["empty"]], full[1][:, ~out["empty"]], atol=1e-6)
    # a keyframe 45 degrees away explains part of the view: the rest is re-rendered
    out = lw.render_frame(poses[1], intr, [lw._keyframe(poses[0], intr)])
    r = out["rerendered"]
    assert 0 < r.sum() < (~out["empty"]).sum() and not (r & out["empty"]).any()
    assert torch.allclose(out["rgb"][:, r], full[1][:, r], atol=1e-6)


def test_bidirectional_path_renders_keyframes_in_full(sphere_model):
    model, train_set = sphere_model
    cfg = LightweightConfig(
        downsample=4,
        buffer_frames=2,
        keyframe_every=3,
        bidirectional=True,
        train_seconds=2,
        num_sequences=4,
        progress=False,
    )
    lw, _ = train_lightweight(model, train_set, cfg, torch.Generator().manual_seed(0))
    path = orbit_path(8, 2.5, 15.0, start_azimuth_deg=10.0, arc_deg=24.0)
    out = lw.render_path(path, train_set.intrinsics)
    assert out["keyframes"] == [0, 3, 6, 7]  # and the last frame, so every frame has a next
    full = render_views(model, path, train_set.intrinsics)["rgb"]
    assert torch.equal(out["rgb"][out["keyframes"]], full[out["keyframes"]])
    assert out["rgb"].shape == (8, 32, 32, 3) and 0 < out["empty_fraction"] < 1
    with pytest.raises(ValueError, match="bidirectional"):
        LightweightConfig(bidirectional=True, buffer_frames=1)


def test_decoder_trains_on_the_cameras_the_field_stores(sphere_model):
    from renderer import stored_cameras

    model, train_set = sphere_model
    with pytest.raises(ValueError, match="stores no cameras"):
        stored_cameras(model)
    model.spec["camera"] = {
        "intrinsics": train_set.intrinsics.as_dict(),
        "center": [0.0, 0.0, 0.0],
        "radius_m": 2.5,
        "up": [0.0, 0.0, 1.0],
    }
    try:
        poses, intr = stored_cameras(model, num_views=16)
        assert poses.shape == (16, 4, 4) and intr == train_set.intrinsics
        eyes = poses[:, :3, 3]
        assert torch.allclose(eyes.norm(dim=-1), torch.full((16,), 2.5), atol=1e-5)
        assert (eyes[:, 2] > 0).all()  # above the horizon
        cfg = LightweightConfig(train_seconds=1, num_sequences=2, progress=False)
        lw, stats = train_lightweight(model, None, cfg)
        assert stats["steps"] > 0
    finally:
        del model.spec["camera"]

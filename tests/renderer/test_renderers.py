"""One table of renderers; scoring held-out views with each."""

import pytest
import torch
from sphere_scene import exact_sphere_field

from renderer import (
    RENDERERS,
    FeatureConfig,
    FullRenderer,
    load_dataset,
    make_renderer,
    render_views,
    score_renderers,
)

QUICK = {"features": FeatureConfig(train_steps=6, extra_views=8, progress=False)}


@pytest.mark.parametrize("name", list(RENDERERS))
def test_every_registered_renderer_renders_a_path(name, sphere_dataset):
    train_set = load_dataset(sphere_dataset, "train", resolution=None)
    model = exact_sphere_field(train_set)
    r, _ = make_renderer(name, model, train_set, QUICK.get(name))
    out = r.render_path(train_set.poses[:3], train_set.intrinsics)
    assert out["rgb"].shape == (3, 32, 32, 3) and out["seconds_per_view"] > 0
    assert r.settings()["renderer"] == name
    if name == "full":
        full = render_views(model, train_set.poses[:1], train_set.intrinsics)["rgb"]
        assert torch.equal(out["rgb"][:1], full)


def test_unknown_renderer_lists_the_known_ones(sphere_dataset):
    with pytest.raises(KeyError, match="full"):
        make_renderer("fast", None)


def test_score_renderers_reports_each_against_the_images(sphere_dataset):
    train_set = load_dataset(sphere_dataset, "train", resolution=None)
    test_set = load_dataset(sphere_dataset, "test", resolution=None)
    model = exact_sphere_field(train_set)
    res = score_renderers(model, test_set, train_set, configs=QUICK)
    assert set(res) == set(RENDERERS)
    for r in res.values():
        assert r["num_views"] == 4 and r["seconds_per_view"] > 0 and r["psnr"] > 20
    feat = res["features"]
    assert feat["speedup_vs_full"] == pytest.approx(
        res["full"]["seconds_per_view"] / feat["seconds_per_view"]
    )
    assert feat["setup_stats"]["steps"] == 6 and feat["settings"]["train_steps"] == 6
    assert res["full"]["setup_stats"] == {} and "speedup_vs_full" not in res["full"]


def test_score_renderers_times_the_fastest_of_its_repeats(sphere_dataset, monkeypatch):
    test_set = load_dataset(sphere_dataset, "test", resolution=None)
    model = exact_sphere_field(test_set)
    with pytest.raises(ValueError, match="timing_repeats"):
        score_renderers(model, test_set, names=["full"], timing_repeats=0)
    # a slow first pass (warm-up, the images) and then 3, 1, 2 seconds per view: 1 counts
    calls = iter([9.0, 3.0, 1.0, 2.0])
    real = FullRenderer.render_path

    def render_path(self, poses, intrinsics):
        return {**real(self, poses, intrinsics), "seconds_per_view": next(calls)}

    monkeypatch.setattr(FullRenderer, "render_path", render_path)
    res = score_renderers(model, test_set, names=["full"], timing_repeats=3)
    assert res["full"]["seconds_per_view"] == 1.0 and res["full"]["psnr"] > 20

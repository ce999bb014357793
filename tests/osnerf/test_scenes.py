"""Scenes: renders, exact masks and poses agree; cache; registry; the radio XML of the same
meshes."""

import json

import numpy as np
import pytest
from scipy.ndimage import binary_dilation

from osnerf.scenes import (
    SCENES,
    RenderConfig,
    build_scene_dataset,
    get_scene,
    load_scene_views,
    project,
)

TINY = RenderConfig(resolution_px=32, num_train_views=8, num_test_views=2, spp=8, mask_spp=4)


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    cache = tmp_path_factory.mktemp("cache")
    folder = build_scene_dataset("tiny", ("post",), TINY, cache_dir=cache, progress=False)
    return cache, folder, load_scene_views(folder)


def test_registry_lists_scenes_and_rejects_unknown():
    assert "firefighter" in SCENES and get_scene("firefighter").default_demand == ("hydrant",)
    with pytest.raises(KeyError, match="known: .*firefighter"):
        get_scene("atlantis")


@pytest.mark.parametrize(
    "name",
    [pytest.param(n, marks=pytest.mark.slow) if n == "munich" else n for n in sorted(SCENES)],
)
def test_every_registered_scene_builds_its_objects(name):
    info = get_scene(name)
    geo = info.build()
    assert set(info.objects) <= set(geo.objects)
    for obj in info.objects:
        b = geo.object_bounds_m(obj)
        assert np.all(b[1] > b[0])


def test_transforms_json_is_nerfstudio(tiny):
    _, folder, views = tiny
    meta = json.loads((folder / "transforms.json").read_text())
    for k in (
        "fl_x",
        "fl_y",
        "cx",
        "cy",
        "w",
        "h",
        "aabb",
        "background",
        "frames",
        "ground_station_m",
    ):
        assert k in meta
    assert meta["w"] == meta["h"] == 32
    assert [f["split"] for f in meta["frames"]].count("test") == 2
    train = json.loads((folder / "transforms_train.json").read_text())
    assert len(train["frames"]) == 8
    assert views.images.shape == (10, 32, 32, 3)
    lo, hi = np.asarray(meta["aabb"])
    for obj, (olo, ohi) in meta["object_aabb"].items():
        assert np.all(np.asarray(olo) >= lo) and np.all(np.asarray(ohi) <= hi), obj


def test_poses_look_at_the_target_and_sit_on_the_ring(tiny):
    _, _, views = tiny
    centre = np.asarray(views.meta["trajectory_center_m"])
    r = np.linalg.norm(views.drone_positions_m - centre, axis=1)
    np.testing.assert_allclose(r, views.meta["trajectory_radius_m"], rtol=1e-6)
    for pose in views.poses:
        uv = project(centre[None], pose, views.intrinsics)[0]
        np.testing.assert_allclose(uv, [16.0, 16.0], atol=1e-6)


def test_masks_agree_with_the_render(tiny):
    """Where no ray of a pixel hits anything, the render shows exactly the sky; the post's
    projected axis lies inside its mask; visible masks never exceed the silhouette."""
    _, _, views = tiny
    any_hit = np.stack([views.masks[o] for o in views.objects]).max(0)  # [n, h, w]
    # pixels whose 3x3 neighbourhood has no hit at all (render and mask rays jitter differently)
    sky = ~binary_dilation(any_hit > 0, structure=np.ones((1, 3, 3), bool))
    assert sky.sum() > 50
    np.testing.assert_allclose(
        views.images[sky], np.broadcast_to(views.background, views.images[sky].shape), atol=2 / 255
    )
    hit = any_hit == 1
    assert np.abs(views.images[hit] - views.background).max(-1).mean() > 0.1
    post_axis = np.array([[0.5, 0.0, 0.4]])
    for k, pose in enumerate(views.poses):
        if views.visible_fraction["post"][k] > 0.99:
            u, v = project(post_axis, pose, views.intrinsics)[0]
            assert views.masks["post"][k][int(v), int(u)] > 0.5
    for o in views.objects:
        assert np.all((views.visible_fraction[o] >= 0) & (views.visible_fraction[o] <= 1 + 1e-6))


def test_hidden_object_is_never_visible(tiny):
    _, _, views = tiny
    assert np.all(views.masks["cable"] == 0) and np.all(views.visible_fraction["cable"] == 0)


def test_cache_is_reused(tiny):
    cache, folder, _ = tiny
    stamp = (folder / "transforms.json").stat().st_mtime_ns
    again = build_scene_dataset("tiny", ("post",), TINY, cache_dir=cache, progress=False)
    assert again == folder and (folder / "transforms.json").stat().st_mtime_ns == stamp
    other = build_scene_dataset("tiny", ("crate",), TINY, cache_dir=cache, progress=False)
    assert other != folder  # a different target is a different trajectory


def test_radio_scene_uses_the_same_meshes(tiny):
    _, folder, _ = tiny
    xml = (folder / "radio" / "scene.xml").read_text()
    for part in ("crate", "post", "ground"):
        assert f'value="../meshes/{part}.ply"' in xml
    assert 'type="itu-radio-material"' in xml and '<string name="type" value="metal"/>' in xml

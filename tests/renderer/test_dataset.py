"""transforms.json loading: pose round trip, intrinsics, RGBA compositing, splits, errors."""

import json
import math

import cv2
import numpy as np
import pytest
import torch

from renderer import Intrinsics, default_aabb, load_dataset, orbit_path, write_transforms


def _write_png(path, rgb):
    cv2.imwrite(str(path), (np.asarray(rgb) * 255 + 0.5).astype(np.uint8)[..., ::-1])


def _folder(tmp_path, n=3, size=(8, 12), meta_extra=None, name="transforms.json"):
    """n views of height x width = size; returns (root, poses, intrinsics)."""
    h, w = size
    poses = orbit_path(n, 3.0, 30.0)
    intr = Intrinsics(10.0, 11.0, 6.0, 4.0, h, w)
    paths = []
    for i in range(n):
        _write_png(tmp_path / f"img_{i}.png", np.full((h, w, 3), i / 4))
        paths.append(f"img_{i}.png")
    p = write_transforms(tmp_path / name, poses, intr, paths, extra=meta_extra)
    return tmp_path, poses, intr, p


def test_poses_and_intrinsics_round_trip(tmp_path):
    root, poses, intr, _ = _folder(tmp_path)
    ds = load_dataset(root, split="all", resolution=None)
    assert torch.equal(ds.poses, poses)
    assert ds.intrinsics == intr
    assert ds.images.shape == (3, 8, 12, 3) and ds.masks is None
    assert torch.allclose(ds.images[2], torch.full((8, 12, 3), round(0.5 * 255) / 255))


def test_downscale_scales_intrinsics_and_averages_pixels(tmp_path):
    img = np.zeros((8, 12, 3))
    img[:, ::2] = 1.0  # alternating columns: area interpolation averages them to 0.5
    root, _, intr, _ = _folder(tmp_path)
    _write_png(root / "img_0.png", img)
    ds = load_dataset(root, split="all", resolution=6)
    assert ds.images.shape == (3, 4, 6, 3)
    assert ds.intrinsics == Intrinsics(5.0, 5.5, 3.0, 2.0, 4, 6)
    assert torch.allclose(ds.images[0], torch.full((4, 6, 3), 0.5), atol=1 / 255)


def test_blender_layout_rgba_and_camera_angle(shared_data):
    ds = load_dataset(shared_data / "nerf_synthetic" / "lego", split="val", resolution=50)
    assert ds.images.shape == (100, 50, 50, 3) and ds.masks.shape == (100, 50, 50)
    # camera_angle_x = 0.6911112070083618 at 50 px
    assert math.isclose(ds.intrinsics.fx, 25.0 / math.tan(0.6911112070083618 / 2), rel_tol=1e-6)
    # white background where alpha is 0
    corner = ds.images[:, 0, 0]
    assert torch.allclose(corner[ds.masks[:, 0, 0] == 0], torch.ones(3), atol=1e-6)
    # default bounds from the poses: cameras look at the origin from about 4 m
    assert ds.aabb[0].abs().max() < 1.6 and torch.allclose(
        ds.aabb.mean(0), torch.zeros(3), atol=0.1
    )


def test_rgba_composited_on_chosen_background_and_mask_path(tmp_path):
    root, _, _, p = _folder(tmp_path, n=1)
    rgba = np.zeros((8, 12, 4), np.uint8)
    rgba[:, :6] = (0, 0, 255, 255)  # BGRA: opaque red on the left half
    cv2.imwrite(str(root / "img_0.png"), rgba)
    ds = load_dataset(root, split="all", resolution=None, background=(0.0, 1.0, 0.0))
    assert torch.allclose(ds.images[0, :, :6], torch.tensor([1.0, 0.0, 0.0]))
    assert torch.allclose(ds.images[0, :, 6:], torch.tensor([0.0, 1.0, 0.0]))
    assert torch.equal(ds.masks[0, :, :6], torch.ones(8, 6))
    # an explicit mask_path wins over alpha
    meta = json.loads(p.read_text())
    cv2.imwrite(str(root / "m.png"), np.full((8, 12), 255, np.uint8))
    meta["frames"][0]["mask_path"] = "m"
    p.write_text(json.dumps(meta))
    ds = load_dataset(root, split="all", resolution=None)
    assert torch.equal(ds.masks, torch.ones(1, 8, 12))
    assert not ds.composited  # a separate mask: the object is cut out for training


def test_rgba_is_composited_before_downscaling(tmp_path):
    """A downscaled RGBA pixel half covered by the object is the average of the composited
    pixels (what the camera would see), not the composite of averaged straight colours,
    which would mix the transparent pixels' (black) colour into the edge."""
    root, _, _, _ = _folder(tmp_path, n=1)
    rgba = np.zeros((8, 12, 4), np.uint8)  # transparent black
    rgba[:, 0::2] = (0, 0, 255, 255)  # BGRA: opaque red in every other column
    cv2.imwrite(str(root / "img_0.png"), rgba)
    ds = load_dataset(root, split="all", resolution=6)
    # half red, half the white background: (1, 0.5, 0.5), alpha 0.5; averaging first
    # would give 0.5 * (0.5, 0, 0) + 0.5 * white = (0.75, 0.5, 0.5)
    assert torch.allclose(ds.images[0], torch.tensor([1.0, 0.5, 0.5]).expand(4, 6, 3), atol=1e-6)
    assert torch.allclose(ds.masks[0], torch.full((4, 6), 0.5), atol=1e-6)
    assert ds.composited and ds.subset([0]).composited  # already the object on background


def test_split_field_and_holdout(tmp_path):
    root, _, _, p = _folder(tmp_path, n=10)
    assert load_dataset(root, "test", None).num_views == 2  # frames 0 and 8
    assert load_dataset(root, "train", None).num_views == 8
    meta = json.loads(p.read_text())
    for i, f in enumerate(meta["frames"]):
        f["split"] = "test" if i < 3 else "train"
    p.write_text(json.dumps(meta))
    assert load_dataset(root, "test", None).names == ("img_0.png", "img_1.png", "img_2.png")


def test_aabb_field_is_used(tmp_path):
    root, *_ = _folder(tmp_path, meta_extra={"aabb": [[-1, -2, -3], [1, 2, 3]]})
    ds = load_dataset(root, "all", None)
    assert torch.equal(ds.aabb, torch.tensor([[-1.0, -2, -3], [1, 2, 3]]))


def test_default_aabb_centres_on_the_point_the_cameras_look_at():
    center = torch.tensor([1.0, -2.0, 0.5])
    poses = orbit_path(8, 4.0, 20.0, center=center)
    intr = Intrinsics(50.0, 50.0, 50.0, 50.0, 100, 100)
    box = default_aabb(poses, intr)
    assert torch.allclose(box.mean(0), center, atol=1e-4)
    assert torch.allclose((box[1] - box[0]) / 2, torch.full((3,), 4.0), atol=1e-4)  # 4 m * 50/50


@pytest.mark.parametrize(
    "edit, message",
    [
        (
            lambda m, root: m["frames"][1].update(file_path="missing"),
            ["transforms.json", "frames[1].file_path"],
        ),
        (
            lambda m, root: m["frames"][2]["transform_matrix"][0].__setitem__(3, float("nan")),
            ["transforms.json", "frames[2].transform_matrix", "non-finite"],
        ),
        (
            lambda m, root: [m.pop(k) for k in ("fl_x", "fl_y")],
            ["transforms.json", "no intrinsics", "camera_angle_x"],
        ),
        (
            lambda m, root: _write_png(root / "img_1.png", np.zeros((9, 12, 3))),
            ["transforms.json", "frames[1].file_path", "img_1.png"],
        ),
        (
            lambda m, root: m["frames"][0].pop("transform_matrix"),
            ["transforms.json", "frames[0]", "transform_matrix"],
        ),
        (lambda m, root: m.update(aabb=[[0, 0, 0], [1, -1, 1]]), ["transforms.json", "aabb"]),
    ],
    ids=[
        "missing-image",
        "non-finite-pose",
        "no-intrinsics",
        "inconsistent-size",
        "no-pose",
        "bad-aabb",
    ],
)
def test_bad_input_names_file_and_field(tmp_path, edit, message):
    root, _, _, p = _folder(tmp_path)
    meta = json.loads(p.read_text())
    edit(meta, root)
    p.write_text(json.dumps(meta))
    with pytest.raises((ValueError, FileNotFoundError)) as e:
        load_dataset(root, split="all", resolution=None)
    for part in message:
        assert part in str(e.value)


def test_missing_folder_and_bad_split(tmp_path):
    with pytest.raises(FileNotFoundError, match="transforms"):
        load_dataset(tmp_path, "train")
    with pytest.raises(ValueError, match="split"):
        load_dataset(tmp_path, "everything")

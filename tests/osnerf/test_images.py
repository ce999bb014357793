"""One image loader behind every command: 16-bit images keep their values, a single file is an
image set, sizes are stated truly, nothing is upscaled silently; train-codec's input checks."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
import torch
from PIL import Image

from osnerf.cli import main


@pytest.fixture
def gray16(tmp_path):
    """A 16-bit grayscale PNG (PIL mode I;16) with a ramp from black to 3/4 white."""
    a = np.tile(np.linspace(0, 49151, 64).astype(np.uint16), (64, 1))
    p = tmp_path / "g16.png"
    Image.fromarray(a).save(p)
    return p, a


def test_ota_reads_16_bit_grayscale_as_it_is_not_white(gray16):
    from common import load_square_images as load_images

    path, a = gray16
    names, imgs = load_images(str(path), 64, 1)  # a single file is accepted as --images
    assert names == ["g16.png"] and imgs.shape == (1, 3, 64, 64)
    np.testing.assert_allclose(imgs[0, 0], a / 65535.0, atol=2e-3)
    assert imgs.mean() == pytest.approx((a / 65535.0).mean(), abs=1e-3)


def test_train_codec_reads_16_bit_grayscale_as_it_is(gray16):
    from semcodec.training.data import load_uint8_images

    path, a = gray16
    (img,) = load_uint8_images([path])
    assert img.dtype == torch.uint8 and img.shape == (3, 64, 64)
    assert np.array_equal(img[0].numpy(), np.round(a / 65535.0 * 255).astype(np.uint8))


def test_eval_codec_accepts_one_image_file_and_16_bit(gray16, tmp_path, capsys):
    path, _ = gray16
    out = tmp_path / "r.json"
    argv = ["eval-codec", "--images", str(path), "--snr-db", "10", "--schemes", "jscc"]
    assert main([*argv, "--no-lpips", "--max-images", "1", "--out", str(out)]) == 0
    assert out.exists()


def test_ota_refuses_to_upscale_a_1x1_image(one_line, tmp_path, capsys):
    Image.fromarray(np.zeros((1, 1, 3), np.uint8)).save(tmp_path / "dot.png")
    out = tmp_path / "o.json"
    argv = ["ota", "--schemes", "digital", "--snr-db", "10", "--images", str(tmp_path / "dot.png")]
    assert main([*argv, "--out", str(out)]) == 2
    err = one_line()
    assert "dot.png is 1x1 px, smaller than --size 64" in err and not out.exists()


@pytest.mark.parametrize("w, h", [(8, 8), (64, 8), (10, 64), (11, 10), (10, 11)])
def test_eval_codec_states_its_true_minimum_size(one_line, tmp_path, capsys, w, h):
    from semcodec.links.schemes import EVAL_MIN_SIDE_PX

    d = tmp_path / "img"
    d.mkdir()
    Image.fromarray(np.zeros((h, w, 3), np.uint8)).save(d / "s.png")
    out = tmp_path / "o.json"
    argv = ["eval-codec", "--images", str(d), "--snr-db", "10", "--schemes", "jscc", "--no-lpips"]
    assert main([*argv, "--out", str(out)]) == 2
    err = one_line()
    assert f"s.png is {w}x{h} px; images must be at least 11x11" in err and EVAL_MIN_SIDE_PX == 11
    assert "win_size" not in err and not out.exists()


@pytest.mark.parametrize("cbr", ["1/48", "1/3"])  # the ends of the shipped codec's range
def test_eval_codec_runs_at_its_stated_minimum(tmp_path, capsys, cbr):
    """An 11x11 image (and 11 px on one side) passes every kind of scheme at both ends of
    the codec's bandwidth ratios: the stated minimum is the true one."""
    d = tmp_path / "img"
    d.mkdir()
    rng = np.random.default_rng(0)
    for name, (h, w) in {"s.png": (11, 11), "t.png": (11, 40), "u.png": (29, 11)}.items():
        Image.fromarray(rng.integers(0, 256, (h, w, 3), dtype=np.uint8)).save(d / name)
    schemes = "jscc,jscc_refined,digital,digital_genie,ideal,analog,digital_jpeg"
    argv = ["eval-codec", "--images", str(d), "--snr-db", "-5,10", "--cbr", cbr, "--no-lpips"]
    argv += ["--schemes", schemes, "--refine-steps", "1", "--out", str(tmp_path / "o.json")]
    assert main(argv) == 0
    rows = json.loads((tmp_path / "o.json").read_text())["results"]
    assert len(rows) == 14 and all(np.isfinite([r["psnr"], r["ssim"]]).all() for r in rows)
    capsys.readouterr()
    assert main(["eval-codec", "--help"]) == 0
    assert "each at least 11x11 px" in " ".join(capsys.readouterr().out.split())


def test_eval_codec_failing_mid_run_leaves_its_error_as_the_last_line(
    tmp_path, capsys, monkeypatch
):
    """A scheme that fails at run time: exit 1 with one error line, and the progress bar is
    closed before it, never drawn again after it."""
    from semcodec.links import schemes as evaluation

    def fails(*args, **kwargs):
        raise RuntimeError("the modem caught fire")

    monkeypatch.setattr(evaluation, "transmit_analog", fails)  # what the analog scheme runs
    d = tmp_path / "img"
    d.mkdir()
    Image.fromarray(np.full((16, 16, 3), 128, np.uint8)).save(d / "s.png")
    argv = ["eval-codec", "--images", str(d), "--snr-db", "10", "--schemes", "analog"]
    assert main([*argv, "--no-lpips", "--out", str(tmp_path / "o.json")]) == 1
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]  # \r (a bar redraw) splits too
    assert lines[-1] == "osnerf eval-codec: failed: RuntimeError: the modem caught fire", err
    assert sum("the modem caught fire" in ln for ln in lines) == 1 and "Traceback" not in err


def test_train_codec_with_images_smaller_than_the_crop_writes_nothing(one_line, tmp_path, capsys):
    data = tmp_path / "data"
    data.mkdir()
    Image.fromarray(np.zeros((20, 20, 3), np.uint8)).save(data / "a.png")
    out = tmp_path / "out"
    argv = ["train-codec", "--data", str(data), "--val", str(data), "--crop-px", "32"]
    assert main([*argv, "--out", str(out)]) == 2
    err = one_line()
    assert "--crop-px" in err and "32x32" in err and "high <= 0" not in err
    assert not out.exists()


def test_train_codec_resumed_with_another_model_is_one_line(one_line, tmp_path, capsys):
    import semcodec
    from common.files import write_torch
    from semcodec.training.loop import TrainConfig

    names = sorted(semcodec.jscc.JSCC_ARCHITECTURES)
    trained, other = names[0], names[1]
    data = tmp_path / "data"
    data.mkdir()
    Image.fromarray(np.zeros((32, 32, 3), np.uint8)).save(data / "a.png")
    out = tmp_path / "out"
    state = {
        "config": dataclasses.asdict(TrainConfig(model=trained, crop_px=16)),
        "model": semcodec.jscc.make_model(trained).state_dict(),
        "optimizer": {},
        "step": 1,
        "elapsed_s": 1.0,
        "best": 0.0,
        "rng": np.random.default_rng(0).bit_generator.state,
        "gen": torch.Generator().get_state(),
    }
    write_torch(out / "last_state.pt", state)
    argv = ["train-codec", "--data", str(data), "--val", str(data), "--crop-px", "16"]
    assert main([*argv, "--model", other, "--out", str(out)]) == 2
    err = one_line()
    assert f"changes --model ({trained} -> {other})" in err  # refused before any weights load
    assert sorted(p.name for p in out.iterdir()) == ["last_state.pt"]


def _dataset(tmp_path, meta_extra=None, pose=None, top=None):
    import json

    d = tmp_path / "scene"
    d.mkdir()
    Image.fromarray(np.zeros((16, 16, 3), np.uint8)).save(d / "r_0.png")
    m = np.eye(4)
    m[2, 3] = 3.0
    frame = {"file_path": "r_0.png", "transform_matrix": (pose if pose is not None else m).tolist()}
    meta = {"camera_angle_x": 0.7, "frames": [frame, frame], **(meta_extra or {})}
    (d / "transforms.json").write_text(json.dumps(top if top is not None else meta))
    return d


@pytest.mark.parametrize(
    "kwargs, says",
    [
        (
            {"meta_extra": {"camera_angle_x": 0}},
            "'camera_angle_x' must be a field of view in (0, pi)",
        ),
        ({"meta_extra": {"camera_angle_x": np.pi}}, "'camera_angle_x' must be a field of view"),
        ({"meta_extra": {"camera_angle_x": "wide"}}, "'camera_angle_x' must be a number"),
        ({"top": [1, 2]}, "must hold a JSON object"),
        (
            {"pose": np.diag([1.0, 1.0, 1.0, 1.0]) + np.pad([[0, 0, 0, 1e300]], ((2, 1), (0, 0)))},
            "from the origin",
        ),
    ],
)
def test_transforms_json_errors_name_the_file_and_exit_2(tmp_path, one_line, kwargs, says):
    d = _dataset(tmp_path, **kwargs)
    out = tmp_path / "run"
    assert main(["train-nerf", "--data", str(d), "--out", str(out), "--max-seconds", "1"]) == 2
    err = one_line()
    assert "transforms.json" in err and says in err, err
    assert not out.exists()


def test_a_corrupt_lpips_weights_file_names_file_and_variable(tmp_path, monkeypatch):
    from renderer import lpips_weights

    bad = tmp_path / "w.safetensors"
    bad.write_bytes(b"\x08\x00\x00\x00\x00\x00\x00\x00{garbage")
    monkeypatch.setenv("OSNERF_LPIPS_WEIGHTS", str(bad))
    with pytest.raises(ValueError, match="OSNERF_LPIPS_WEIGHTS") as info:
        lpips_weights(bad)
    assert str(bad) in str(info.value) and "\n" not in str(info.value)

"""`osnerf train-nerf` and `osnerf render` in-process: the result contract and bad input."""

import json

import cv2
import pytest

from osnerf.cli import main


@pytest.fixture(scope="module")
def run_dir(sphere_dataset, tmp_path_factory):
    out = tmp_path_factory.mktemp("run")
    rc = main(
        [
            "train-nerf",
            "--data",
            str(sphere_dataset),
            "--out",
            str(out),
            "--resolution",
            "16",
            "--max-seconds",
            "4",
            "--seed",
            "0",
            "--field",
            "grid",
            "--eval-every-seconds",
            "2",
            "--no-progress",
            "--clock",
            "cpu",
            "--threads",
            "1",
        ]
    )
    assert rc == 0
    return out


def test_train_nerf_writes_the_contract(run_dir):
    m = json.loads((run_dir / "metrics.json").read_text())
    for key in ("config", "seed", "git_commit", "train_seconds", "steps", "test", "curve"):
        assert key in m
    assert m["seed"] == 0 and m["config"]["field"] == "grid" and m["config"]["resolution"] == 16
    assert m["test"]["num_views"] == 4
    assert m["test"]["psnr"] == pytest.approx(sum(m["test"]["psnr_per_view"]) / 4)
    assert 0 < m["test"]["ssim"] <= 1
    assert 3.5 <= m["train_seconds"] < 10 and m["steps"] > 0
    assert all({"seconds", "psnr"} <= set(p) for p in m["curve"])
    assert m["curve"][-1]["psnr"] > m["curve"][0]["psnr"]
    pngs = sorted((run_dir / "test").glob("*.png"))
    assert len(pngs) == 4 and cv2.imread(str(pngs[0])).shape == (16, 16, 3)


@pytest.mark.parametrize("video", ["gif", "mp4"])
def test_render_writes_frames_and_video(run_dir, tmp_path, video):
    out = tmp_path / "path"
    rc = main(
        [
            "render",
            "--run",
            str(run_dir),
            "--out",
            str(out),
            "--num-views",
            "5",
            "--resolution",
            "24",
            "--video",
            video,
            "--fps",
            "10",
            "--threads",
            "1",
        ]
    )
    assert rc == 0
    frames = sorted((out / "frames").glob("*.png"))
    assert len(frames) == 5 and cv2.imread(str(frames[0])).shape == (24, 24, 3)
    assert (out / f"path.{video}").stat().st_size > 0
    r = json.loads((out / "render.json").read_text())
    assert r["num_views"] == 5 and r["seconds_per_view"] > 0


def test_bad_arguments_exit_2(run_dir, sphere_dataset, tmp_path, capsys):
    assert main(["train-nerf", "--data", str(tmp_path / "nope"), "--out", str(tmp_path / "o")]) == 2
    assert "--data" in capsys.readouterr().err
    assert (
        main(
            [
                "train-nerf",
                "--data",
                str(sphere_dataset),
                "--out",
                str(tmp_path / "o"),
                "--field",
                "hash",
            ]
        )
        == 2
    )
    assert "grid, mlp" in capsys.readouterr().err
    assert main(["render", "--run", str(tmp_path), "--out", str(tmp_path / "r")]) == 2
    assert "model.pt" in capsys.readouterr().err
    assert (
        main(["render", "--run", str(run_dir), "--out", str(tmp_path / "r"), "--video", "avi"]) == 2
    )
    assert "mp4, gif, none" in capsys.readouterr().err
    assert not (tmp_path / "o" / "metrics.json").exists()


def test_render_with_the_lightweight_renderer_along_a_path(run_dir, tmp_path):
    from renderer import orbit_path

    path = tmp_path / "path.json"
    poses = orbit_path(4, 2.5, 20.0, start_azimuth_deg=5.0, arc_deg=12.0)
    path.write_text(json.dumps({"frames": [{"transform_matrix": p.tolist()} for p in poses]}))
    out = tmp_path / "lw"
    args = ["render", "--run", str(run_dir), "--out", str(out), "--path", str(path)]
    args += ["--renderer", "lightweight", "--lightweight-seconds", "1", "--video", "none"]
    assert main(args + ["--threads", "1"]) == 0
    assert len(sorted((out / "frames").glob("*.png"))) == 4
    r = json.loads((out / "render.json").read_text())
    assert r["num_views"] == 4 and r["seconds_per_view"] > 0 and r["setup_seconds"] > 0
    assert r["renderer"]["renderer"] == "lightweight" and r["keyframes"] == [0]
    assert r["renderer"]["downsample"] == 4
    out2 = tmp_path / "coarse"
    args[4] = str(out2)
    assert main(args + ["--lightweight-preset", "coarse_step", "--threads", "1"]) == 0
    r = json.loads((out2 / "render.json").read_text())
    assert r["keyframes"] == [] and r["renderer"]["downsample"] == 1


def test_render_bad_input_is_one_line_and_writes_nothing(run_dir, tmp_path, capsys):
    def fails(extra, text):
        out = tmp_path / "never"
        assert main(["render", "--run", str(run_dir), "--out", str(out), *extra]) == 2
        err = capsys.readouterr().err
        assert text in err and len(err.strip().splitlines()) == 1
        assert not out.exists()

    fails(["--renderer", "fast"], "full, lightweight")
    fails(["--renderer", "lightweight", "--lightweight-preset", "x"], "keyframes, coarse_step")
    no_frames = tmp_path / "no_frames.json"
    no_frames.write_text(json.dumps({"camera_angle_x": 0.7}))
    fails(["--path", str(no_frames)], "frames")
    empty = tmp_path / "empty.json"
    empty.write_text(json.dumps({"frames": []}))
    fails(["--path", str(empty)], "frames")
    not_a_field = tmp_path / "model.pt"
    not_a_field.write_bytes(b"this is not a radiance field")
    out = tmp_path / "never"
    assert main(["render", "--run", str(not_a_field), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "not a radiance field" in err and len(err.strip().splitlines()) == 1
    assert not out.exists()

"""`osnerf train-nerf` and `osnerf render` in-process: the result contract and bad input."""

import json
import math

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


def _render(run, out, *extra):
    return main(["render", "--run", str(run), "--out", str(out), "--num-views", "2", *extra])


def _one_line(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    return err


def test_render_names_an_unusable_model_file_and_says_what_to_do(run_dir, tmp_path, capsys):
    """A corrupt model.pt, a torch file with other keys and a field with NaN density are
    each refused in one line naming the file."""
    import torch

    out = tmp_path / "r"
    corrupt = tmp_path / "corrupt.pt"
    corrupt.write_bytes((run_dir / "model.pt").read_bytes()[:300])
    assert _render(corrupt, out) == 2
    err = _one_line(capsys)
    assert "corrupt.pt: not a readable model file" in err and "osnerf train-nerf" in err
    other = tmp_path / "other.pt"
    torch.save({"weights": torch.zeros(3)}, other)
    assert _render(other, out) == 2
    assert "other.pt: not a model saved by save_model (no entry 'aabb')" in _one_line(capsys)
    payload = torch.load(run_dir / "model.pt", weights_only=True)
    payload["state_dict"]["field.density_grid"].fill_(float("nan"))
    nan = tmp_path / "nan.pt"
    torch.save(payload, nan)
    assert _render(nan, out) == 2
    assert "field.density_grid holds NaN or infinite values" in _one_line(capsys)
    assert not out.exists()


def test_render_path_with_a_singular_pose_names_the_frame(run_dir, tmp_path, capsys):
    """An all-zero transform_matrix is refused naming the frame."""
    eye = [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 4], [0, 0, 0, 1]]
    path = tmp_path / "path.json"
    path.write_text(
        json.dumps({"frames": [{"transform_matrix": eye}, {"transform_matrix": [[0] * 4] * 4}]})
    )
    assert _render(run_dir, tmp_path / "r", "--path", str(path)) == 2
    assert "frames[1].transform_matrix is singular" in _one_line(capsys)
    assert not (tmp_path / "r").exists()


def test_dataset_with_an_all_zero_pose_names_the_frame(sphere_dataset, tmp_path, capsys):
    import shutil

    data = tmp_path / "data"
    shutil.copytree(sphere_dataset, data)
    meta = json.loads((data / "transforms_train.json").read_text())
    meta["frames"][2]["transform_matrix"] = [[0.0] * 4] * 4
    (data / "transforms_train.json").write_text(json.dumps(meta))
    argv = ["train-nerf", "--data", str(data), "--out", str(tmp_path / "o"), "--max-seconds", "1"]
    assert main(argv) == 2
    assert "transforms_train.json: frames[2].transform_matrix is singular" in _one_line(capsys)
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize(
    "extra, match",
    [
        (
            ["--resolution", "30000"],
            "argument --resolution: must be an integer of pixels in [16, 512]",
        ),
        (["--threads", "0"], "argument --threads: must be an integer in [1, 256]"),
        (["--seed", "-1"], "argument --seed: must be an integer in [0, "),
    ],
)
def test_train_nerf_refuses_bad_values_at_parse_time(
    sphere_dataset, tmp_path, capsys, monkeypatch, extra, match
):
    """Out-of-range --resolution (30000 px would allocate 14.4 GB), --threads 0 and --seed -1
    are refused while parsing, with one line and exit 2, before the dataset is loaded."""
    import renderer

    def refuse(*a, **k):  # a late check fails the test instead of allocating gigabytes
        raise AssertionError("loaded the dataset before checking the arguments")

    monkeypatch.setattr(renderer, "load_dataset", refuse)
    argv = ["train-nerf", "--data", str(sphere_dataset), "--out", str(tmp_path / "o"), *extra]
    assert main(argv) == 2
    assert match in _one_line(capsys)
    assert list(tmp_path.iterdir()) == []


def test_train_nerf_checks_its_output_folder_before_training(
    sphere_dataset, tmp_path, capsys, monkeypatch
):
    """--out naming an existing file is refused before training starts (exit 2), and the
    file is left as it was."""
    import renderer

    def no_training(*a, **k):
        raise AssertionError("trained before checking --out")

    monkeypatch.setattr(renderer, "train", no_training)
    a_file = tmp_path / "taken"
    a_file.write_text("keep me")
    argv = ["train-nerf", "--data", str(sphere_dataset), "--out", str(a_file)]
    assert main(argv) == 2
    assert "--out" in _one_line(capsys) and a_file.read_text() == "keep me"


def test_render_with_the_feature_renderer(run_dir, tmp_path):
    out = tmp_path / "feat"
    argv = ["--renderer", "features", "--renderer-steps", "4", "--renderer-refine", "0.3"]
    assert _render(run_dir, out, *argv) == 0
    r = json.loads((out / "render.json").read_text())
    assert r["renderer"]["refine_contrast"] == 0.3  # the rendered size's row leaves it off
    assert len(sorted((out / "frames").glob("*.png"))) == 2 == r["num_views"]
    assert r["renderer"]["renderer"] == "features" and r["renderer"]["train_steps"] == 4
    assert r["setup_stats"]["steps"] == 4 and r["setup_cpu_seconds"] > 0
    assert r["seconds_per_view"] > 0 and 0 < r["peak_memory_mb"] < 4096
    # the report prices the setup: views until it has paid for itself against the full
    # render, timed on the same path
    assert r["full_seconds_per_view"] > 0
    saved = r["full_seconds_per_view"] - r["seconds_per_view"]
    if saved > 0:
        assert r["break_even_views"] == math.ceil(r["setup_seconds"] / saved)
    else:
        assert r["break_even_views"] is None


def test_render_with_a_cpu_budget_and_the_full_renders_break_even(run_dir, tmp_path):
    out = tmp_path / "budget"
    # one thread: CPU seconds are the work's, not a thread pool's spinning on a busy machine
    argv = ["--renderer", "features", "--renderer-cpu-seconds", "4", "--threads", "1"]
    assert _render(run_dir, out, *argv) == 0
    r = json.loads((out / "render.json").read_text())
    assert r["renderer"]["setup_cpu_seconds"] == 4.0 and r["renderer"]["train_steps"] is None
    stats = r["setup_stats"]
    # the budget stops the teachers and the training (the bake before them is not budgeted)
    assert stats["steps"] > 0 and stats["cpu_seconds"] < 4.0 + 2.0, stats
    full = tmp_path / "full"
    assert _render(run_dir, full) == 0
    f = json.loads((full / "render.json").read_text())
    assert f["break_even_views"] == 0 and f["full_seconds_per_view"] == f["seconds_per_view"]


def test_render_bad_input_is_one_line_and_writes_nothing(run_dir, tmp_path, capsys):
    def fails(extra, text):
        out = tmp_path / "never"
        assert main(["render", "--run", str(run_dir), "--out", str(out), *extra]) == 2
        err = capsys.readouterr().err
        assert text in err and len(err.strip().splitlines()) == 1
        assert not out.exists()

    fails(["--renderer", "fast"], "full, features")
    fails(["--renderer", "features", "--renderer-steps", "0"], "--renderer-steps")
    fails(["--renderer", "features", "--renderer-cpu-seconds", "0"], "--renderer-cpu-seconds")
    fails(["--renderer-cpu-seconds", "5"], "--renderer-cpu-seconds")
    fails(["--renderer-refine", "0.45"], "--renderer-refine")
    fails(["--renderer", "features", "--renderer-refine", "0"], "--renderer-refine")
    fails(["--renderer", "features", "--renderer-refine", "1.5"], "--renderer-refine")
    no_frames = tmp_path / "no_frames.json"
    no_frames.write_text(json.dumps({"camera_angle_x": 0.7}))
    fails(["--path", str(no_frames)], "frames")
    empty = tmp_path / "empty.json"
    empty.write_text(json.dumps({"frames": []}))
    fails(["--path", str(empty)], "no frames to render")
    not_a_field = tmp_path / "model.pt"
    not_a_field.write_bytes(b"this is not a radiance field")
    out = tmp_path / "never"
    assert main(["render", "--run", str(not_a_field), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "not a readable model file" in err and len(err.strip().splitlines()) == 1
    assert "not an archive written by torch.save" in err  # not PyTorch's own (cut) text
    assert not out.exists()


def test_render_refuses_an_existing_folder_and_overwrite_leaves_no_stale_frame(
    run_dir, tmp_path, capsys
):
    out = tmp_path / "path"
    argv = ["render", "--run", str(run_dir), "--out", str(out), "--resolution", "16"]
    argv += ["--video", "gif", "--threads", "1"]
    assert main([*argv, "--num-views", "3"]) == 0
    before = {p.name: p.read_bytes() for p in (out / "frames").iterdir()}
    assert main([*argv, "--num-views", "1"]) == 2
    assert "--overwrite" in capsys.readouterr().err.strip().splitlines()[-1]
    assert {p.name: p.read_bytes() for p in (out / "frames").iterdir()} == before
    assert main([*argv, "--num-views", "1", "--overwrite"]) == 0
    assert sorted(p.name for p in (out / "frames").iterdir()) == ["000.png"]
    assert json.loads((out / "render.json").read_text())["num_views"] == 1


def test_train_nerf_on_a_full_disk_names_the_file_and_leaves_nothing_half_written(
    sphere_dataset, tmp_path, capsys, monkeypatch
):
    import errno

    import common.files

    def full_disk(path, data):
        with open(path, "wb") as f:
            f.write(data[: len(data) // 2])
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(common.files, "_write_file", full_disk)
    out = tmp_path / "run"
    argv = ["train-nerf", "--data", str(sphere_dataset), "--out", str(out), "--resolution", "16"]
    argv += ["--max-seconds", "1", "--eval-every-seconds", "1", "--no-progress", "--clock", "cpu"]
    assert main([*argv, "--threads", "1"]) == 1
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert "No space left on device" in err and str(out) in err, err
    assert "inline_container" not in err
    left = [p for p in out.rglob("*") if p.is_file()]
    assert not [p for p in left if ".tmp" in p.name or p.stat().st_size == 0], left


def test_render_a_budget_that_trains_nothing_is_refused_naming_it(run_dir, tmp_path, capsys):
    out = tmp_path / "none"
    argv = ["--renderer", "features", "--renderer-cpu-seconds", "0.01", "--threads", "1"]
    assert _render(run_dir, out, *argv) == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]  # after the setup's progress bar
    assert "--renderer-cpu-seconds 0.01 ran out before the first distillation step" in err
    assert not (out / "render.json").exists()

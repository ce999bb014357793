"""Bad input and faults across commands: one-line errors with exit 2, raised before any
heavy work, leaving no partial output; loaders that name the file and say what to do."""

from __future__ import annotations

import pytest

import semcodec.training.loop
from osnerf.cli import build_parser, main

REAL_TRAIN = semcodec.training.loop.train


def _one_line(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    return err


@pytest.fixture(autouse=True)
def no_heavy_work(monkeypatch):
    """Every command's work refuses to start: a check that comes too late fails the test
    (exit 1) instead of running a pipeline, a training or a 14 GB allocation."""
    import osnerf.commands.ber
    import osnerf.run
    import semcodec.training.loop

    def refuse(*a, **k):
        raise AssertionError("the work started before the input was checked")

    monkeypatch.setattr(osnerf.commands.ber, "simulate", refuse)
    monkeypatch.setattr(osnerf.run, "run_pipeline", refuse)
    monkeypatch.setattr(semcodec.training.loop, "train", refuse)


def _ber(*extra) -> int:
    return main(["ber", "--snr-db", "0", "--num-bits", "10000", *extra])


def test_ber_out_and_plot_naming_one_file_is_refused(tmp_path, capsys):
    """--plot naming the --out file is refused: the JSON would overwrite the plot."""
    same = tmp_path / "same.png"
    assert _ber("--out", str(same), "--plot", str(same)) == 2
    assert "--out and --plot are the same file" in _one_line(capsys)
    assert list(tmp_path.iterdir()) == []


def test_ber_output_paths_are_checked_before_computing(tmp_path, capsys):
    """--out naming a folder and --plot under a file are refused before any work."""
    assert _ber("--out", str(tmp_path)) == 2
    assert "is a folder; give a file path" in _one_line(capsys)
    a_file = tmp_path / "file"
    a_file.write_text("")
    assert _ber("--out", str(tmp_path / "b.json"), "--plot", str(a_file / "p.png")) == 2
    assert f"{str(a_file)!r} is a file, not a folder" in _one_line(capsys)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file"]


@pytest.mark.parametrize(
    "command, extra",
    [
        ("ber", ["--snr-db", "0,,5"]),
        ("ber", ["--seed", "1e23"]),
        ("ber", ["--seed", "-1"]),
        ("eval-codec", ["--images", "x", "--threads", "0"]),
        ("eval-codec", ["--images", "x", "--snr-db", "nan"]),
        ("train-codec", ["--threads", "0"]),
        ("run", ["--snr-db", "inf"]),
        ("run", ["--seed", "-1"]),
        ("run", ["--refine-steps", "-3"]),
    ],
)
def test_bad_values_are_refused_while_parsing(tmp_path, capsys, command, extra):
    """--snr-db 0,,5, --seed -1, --threads 0 and --seed 1e23 are refused naming the flag and
    its range."""
    out = tmp_path / ("o.json" if command in ("ber", "eval-codec") else "o")
    assert main([command, *extra, "--out", str(out)]) == 2
    err = _one_line(capsys)
    assert err.startswith(f"osnerf {command}: error: argument {extra[-2]}: must be"), err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    "extra, match",
    [
        (["--mcs", "foo"], "argument --mcs: invalid choice: 'foo'"),
        (["--image-codec", "bmp"], "argument --image-codec: invalid choice: 'bmp'"),
        (["--resolution", "30000"], "argument --resolution: must be an integer in [16, 512] px"),
    ],
)
def test_run_refuses_bad_flags_before_any_stage(tmp_path, capsys, extra, match):
    """--mcs foo and --image-codec bmp are refused before the scene and jscc stages: no run
    folder is left."""
    out = tmp_path / "run"
    assert main(["run", "--out", str(out), *extra]) == 2
    assert match in _one_line(capsys)
    assert not out.exists()


def test_run_names_a_corrupt_cached_stage_and_how_to_clear_it(tmp_path, capsys):
    """A truncated cache .npz is named, with what to do about it."""
    import numpy as np

    from osnerf.commands.run import run_config

    out = tmp_path / "run"
    argv = ["run", "--out", str(out), "--resolution", "32"]
    folder = out / "cache" / run_config(build_parser("run").parse_args(argv)).key()
    folder.mkdir(parents=True)
    np.savez_compressed(folder / "scene.npz", x=np.arange(1000))
    data = (folder / "scene.npz").read_bytes()
    (folder / "scene.npz").write_bytes(data[: len(data) // 2])
    (folder / "scene.json").write_text("{}")
    assert main(argv) == 2
    err = _one_line(capsys)
    assert f"cached stage {folder / 'scene.npz'} is corrupt or truncated" in err
    assert "delete it" in err


def test_train_codec_names_a_corrupt_resume_state_and_no_resume(tmp_path, capsys):
    """A corrupt last_state.pt is named, with what to do about it."""
    out = tmp_path / "run"
    out.mkdir()
    (out / "last_state.pt").write_bytes(b"\x80\x02garbage")
    data = tmp_path / "data"
    data.mkdir()
    argv = ["train-codec", "--data", str(data), "--val", str(data), "--out", str(out)]
    assert main(argv) == 2
    err = _one_line(capsys)
    assert "last_state.pt: cannot resume from it" in err and "--no-resume" in err


def test_train_codec_corrupt_image_is_bad_input(tmp_path, capsys, monkeypatch):
    """A corrupt image exits 2 in train-codec as in eval-codec."""
    import semcodec.training.loop

    monkeypatch.setattr(semcodec.training.loop, "train", REAL_TRAIN)  # it reads the images
    monkeypatch.setattr(semcodec.training.loop, "make_model", None)  # but never gets further
    data = tmp_path / "data"
    data.mkdir()
    (data / "x.png").write_bytes(b"\x89PNG\r\n\x1a\n broken")
    argv = ["train-codec", "--data", str(data), "--val", str(data), "--out", str(tmp_path / "o")]
    assert main(argv) == 2
    assert "x.png: not a readable image" in _one_line(capsys)

"""One argument layer: finite numbers, bounded counts and times, messages in the flag's name.
A refusal exits 2 with one line naming the option, before any work, writing nothing."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from osnerf.cli import main

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture
def images(tmp_path):
    d = tmp_path / "img"
    d.mkdir()
    Image.fromarray(np.zeros((64, 64, 3), np.uint8)).save(d / "a.png")
    return d


@pytest.fixture
def model(tmp_path):
    p = tmp_path / "model.pt"
    p.write_bytes(b"not used: parsing refuses first")
    return p


@pytest.mark.parametrize(
    "argv, flag",
    [
        (["render", "--run", "{model}", "--arc-deg", "nan"], "--arc-deg"),
        (["render", "--run", "{model}", "--radius-m", "inf"], "--radius-m"),
        (["render", "--run", "{model}", "--fps", "inf"], "--fps"),
        (["render", "--run", "{model}", "--elevation-deg", "100"], "--elevation-deg"),
        (["render", "--run", "{model}", "--seed", "-1"], "--seed"),
        (["render", "--run", "{model}", "--seed", "1e23"], "--seed"),
        (["render", "--run", "{model}", "--num-views", "100000000"], "--num-views"),
        (["train-codec", "--save-every-s", "nan"], "--save-every-s"),
        (["train-nerf", "--data", "{images}", "--max-seconds", "1e12"], "--max-seconds"),
        (["eval-codec", "--images", "{images}", "--draws", "100000000"], "--draws"),
        (["run", "--demand", ""], "--demand"),
        (["run", "--views", "1"], "--views"),
        (["run", "--nerf-steps", "1e30"], "--nerf-steps"),
        (["run", "--schemes", "jscc,jscc"], "--schemes"),
        (["run", "--schemes", "jscc,"], "--schemes"),
        (["eval-codec", "--images", "{images}", "--schemes", "jscc,jscc"], "--schemes"),
        (["eval-codec", "--images", "{images}", "--schemes", "jscc,"], "--schemes"),
        (
            ["ota", "--schemes", "jscc", "--images", "{images}", "--max-papr-db", "nan"],
            "--max-papr-db",
        ),
        (["sweep", "spec.yaml", "--workers", "100000"], "--workers"),
    ],
)
def test_nonsense_is_refused_naming_the_flag(one_line, tmp_path, capsys, images, model, argv, flag):
    fill = {"{images}": str(images), "{model}": str(model)}
    out = tmp_path / ("o.json" if argv[0] in ("eval-codec", "ota") else "o")
    assert main([fill.get(a, a) for a in argv] + ["--out", str(out)]) == 2
    err = one_line()
    assert flag in err, err
    assert not out.exists()


@pytest.mark.parametrize(
    "argv, flag",
    [
        (["train-codec", "--crop-px", "18"], "--crop-px must be a multiple of 4"),
        (["train-codec", "--batch-size", "0"], "--batch-size"),
        (["run", "--max-seconds", "0"], "--max-seconds"),
        (["run", "--renderer-steps", "-1"], "--renderer-steps"),
    ],
)
def test_messages_name_the_flags_not_the_config_fields(one_line, tmp_path, capsys, argv, flag):
    assert main([*argv, "--out", str(tmp_path / "o")]) == 2
    err = one_line()
    assert flag in err, err
    for field in ("crop_px", "batch_size", "max_seconds", "num_train_views", "renderer_steps"):
        assert field not in err, err


def test_a_config_error_is_renamed_to_the_flag():
    from osnerf.commands.args import flag_error

    e = flag_error(
        ValueError("num_train_views must be in [2, 512], got 1"), {"num_train_views": "--views"}
    )
    assert str(e) == "--views must be in [2, 512], got 1"
    e = flag_error(ValueError("snr_min_db must be < snr_max_db, both in [-30, 60]"))
    assert str(e) == "--snr-min-db must be < snr_max_db, both in [-30, 60]"


def test_a_config_error_keeps_the_paths_it_names():
    """A field's name inside a path is part of the path, not the field: only the word is
    renamed."""
    from osnerf.commands.args import flag_error

    msg = (
        "data folder /work/data/train and C:\\data\\val hold no images; data.png, ./data; see data."
    )
    e = flag_error(ValueError(msg), {"data": "--data"})
    assert str(e) == msg.replace("data folder", "--data folder").replace("see data.", "see --data.")


def test_ota_refuses_an_snr_outside_the_checkpoint_card(one_line, tmp_path, capsys, images):
    from semcodec import load_codec

    lo, hi = load_codec(None).snr_range_db
    out = tmp_path / "o.json"
    argv = ["ota", "--schemes", "jscc", "--snr-db", f"{hi + 5:g}", "--images", str(images)]
    assert main([*argv, "--out", str(out)]) == 2
    err = one_line()
    assert "--snr-db" in err and "not covered by checkpoint" in err
    assert not out.exists()


def test_a_negative_fraction_reaches_the_option_check(one_line, tmp_path, capsys, images):
    out = tmp_path / "o.json"
    assert main(["eval-codec", "--images", str(images), "--cbr", "-1/16", "--out", str(out)]) == 2
    err = one_line()
    assert "expected one argument" not in err and "--cbr" in err, err


def test_tiny_cbr_names_the_flag(one_line, tmp_path, capsys, images):
    out = tmp_path / "o.json"
    argv = ["eval-codec", "--images", str(images), "--schemes", "digital,ideal", "--cbr", "1e-9"]
    assert main([*argv, "--snr-db", "10", "--no-lpips", "--out", str(out)]) == 2
    err = one_line()
    assert "--cbr" in err, err
    assert not out.exists()


def test_malloc_tune_must_be_0_or_1(one_line, capsys, monkeypatch):
    monkeypatch.setenv("OSNERF_MALLOC_TUNE", "banana")
    assert main(["scenes"]) == 2
    assert "$OSNERF_MALLOC_TUNE must be 0 or 1" in one_line()


def test_scenes_with_stdout_closed_fails():
    r = subprocess.run(
        [
            sys.executable,
            "-c",
            "import sys; from osnerf.cli import main; sys.exit(main(['scenes']))",
        ],
        cwd=ROOT,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=lambda: os.close(1),  # as `osnerf scenes >&-`
    )
    assert r.returncode == 2, r.stderr
    assert "standard output is closed" in r.stderr


def test_hil_info_with_no_board_fails_on_stderr(capsys):
    assert main(["hil", "info", "--emulate", "--serial", "zzzz"]) == 1
    cap = capsys.readouterr()
    assert cap.out == "" and "no HackRF board found" in cap.err
    assert len(cap.err.strip().splitlines()) == 1


def test_train_codec_without_shared_data_names_osnerf_data(one_line, tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("OSNERF_DATA", str(tmp_path / "nowhere"))
    assert main(["train-codec", "--out", str(tmp_path / "o")]) == 2
    err = one_line()
    assert "$OSNERF_DATA" in err and "--data folder not found" not in err


def test_run_help_shows_each_default_once_from_the_config():
    import contextlib
    import dataclasses
    import io

    from osnerf.commands.run import CONFIG_FIELDS
    from osnerf.run import RunConfig

    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert main(["run", "--help"]) == 0
    text = " ".join(buf.getvalue().split())
    assert text.count("(default:") == len(CONFIG_FIELDS)
    defaults = {f.name: f.default for f in dataclasses.fields(RunConfig)}
    assert f"(default: {defaults['refine_steps']})" in text
    assert f"(default: {defaults['num_train_views']})" in text

"""The eval-codec and train-codec contracts, in-process, on a few small images."""

import json
import os

import numpy as np
import pytest
from PIL import Image

from osnerf.cli import main
from renderer import lpips_weights_path

# LPIPS needs the weights `make lpips` converts; without them (and unless required) skip it.
WITH_LPIPS = lpips_weights_path().is_file() or bool(os.environ.get("OSNERF_REQUIRE_LPIPS"))


@pytest.fixture(scope="module")
def image_dir(tmp_path_factory, shared_data):
    d = tmp_path_factory.mktemp("imgs")
    for i, name in enumerate(sorted((shared_data / "kodak").iterdir())[:2]):
        Image.open(name).convert("RGB").crop((100, 100, 164, 148)).save(d / f"im{i}.png")
    return d


def test_eval_codec_contract(image_dir, tmp_path):
    out = tmp_path / "eval.json"
    rc = main(
        [
            "eval-codec",
            "--images",
            str(image_dir),
            "--channel",
            "awgn",
            "--snr-db",
            "4,10",
            "--cbr",
            "1/16",
            "--schemes",
            "jscc,digital,ideal",
            "--seed",
            "0",
            "--out",
            str(out),
            "--plot",
            str(tmp_path / "eval.png"),
            *([] if WITH_LPIPS else ["--no-lpips"]),
        ]
    )
    assert rc == 0
    doc = json.loads(out.read_text())
    assert doc["seed"] == 0 and doc["git_commit"] and doc["config"]["cbr"] == 0.0625
    assert len(doc["checkpoint"]["sha256"]) == 64 and doc["checkpoint"]["name"]
    assert [(r["scheme"], r["snr_db"]) for r in doc["results"]] == [
        (s, v) for s in ("jscc", "digital", "ideal") for v in (4.0, 10.0)
    ]
    for r in doc["results"]:
        assert r["cbr"] == 0.0625 and r["num_images"] == 2
        assert r["psnr"] == pytest.approx(np.mean(r["psnr_per_image"]))
        assert 0 < r["ssim"] <= 1 and 5 < r["psnr"] < 60
        # a lost image (mid-grey) scores about 1; LPIPS-AlexNet stays below ~1.5 in practice
        assert (0 < r["lpips"] < 1.5) if WITH_LPIPS else r["lpips"] is None
    assert doc["config"]["lpips"] == WITH_LPIPS
    if WITH_LPIPS:  # better links look better: at 10 dB each scheme beats itself at 4 dB
        by = {(r["scheme"], r["snr_db"]): r["lpips"] for r in doc["results"]}
        assert all(by[s, 10.0] <= by[s, 4.0] for s in ("jscc", "digital", "ideal")), by
    assert (tmp_path / "eval.png").stat().st_size > 1000


def _bad(tmp_path, *extra, images=None):
    out = tmp_path / "bad.json"
    argv = ["eval-codec", "--images", str(images), "--snr-db", "4", "--out", str(out), *extra]
    rc = main(argv)
    assert rc == 2
    assert not out.exists() and not list(tmp_path.glob(".bad.json*"))


def test_bad_input_one_line_errors(image_dir, tmp_path, capsys):
    d = tmp_path / "broken"
    d.mkdir()
    (d / "x.png").write_bytes(b"not an image")
    _bad(tmp_path, images=d)
    assert "x.png: not a readable image" in capsys.readouterr().err
    g = tmp_path / "grey"
    g.mkdir()
    Image.fromarray(np.zeros((32, 32), np.uint8)).save(g / "g.png")
    _bad(tmp_path, images=g)
    assert "not RGB" in capsys.readouterr().err
    s = tmp_path / "small"
    s.mkdir()
    Image.fromarray(np.zeros((4, 4, 3), np.uint8)).save(s / "s.png")
    _bad(tmp_path, images=s)
    assert "at least" in capsys.readouterr().err
    _bad(tmp_path, "--schemes", "jscc,magic", images=image_dir)
    assert "unknown scheme 'magic'" in capsys.readouterr().err
    _bad(tmp_path, "--cbr", "1/2", "--schemes", "jscc", images=image_dir)
    assert "outside the codec's range" in capsys.readouterr().err
    ck = tmp_path / "corrupt.safetensors"
    ck.write_bytes(b"\x01" * 64)
    _bad(tmp_path, "--checkpoint", str(ck), "--schemes", "jscc", images=image_dir)
    err = capsys.readouterr().err
    assert "corrupt" in err and err.count("\n") == 1
    _bad(tmp_path, "--channel", "mars", images=image_dir)
    assert "--channel" in capsys.readouterr().err


def test_train_codec_resumes(image_dir, tmp_path):
    out = tmp_path / "run"
    argv = [
        "train-codec",
        "--data",
        str(image_dir),
        "--val",
        str(image_dir),
        "--out",
        str(out),
        "--model",
        "adjscc_s4_w64",
        "--crop-px",
        "32",
        "--batch-size",
        "2",
        "--max-minutes",
        "0.03",
        "--threads",
        "1",
    ]
    assert main(argv) == 0
    first = json.loads((out / "summary.json").read_text())
    assert first["steps"] >= 1 and (out / "best.safetensors").exists()
    argv[argv.index("0.03")] = "0.06"
    assert main(argv) == 0
    second = json.loads((out / "summary.json").read_text())
    assert second["steps"] > first["steps"]  # continued, not restarted
    from semcodec import load_codec

    assert load_codec(out / "last.safetensors").card["training"]["steps"] == second["steps"]

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
    s = tmp_path / "small"
    s.mkdir()
    Image.fromarray(np.zeros((4, 4, 3), np.uint8)).save(s / "s.png")
    _bad(tmp_path, images=s)
    assert "at least" in capsys.readouterr().err
    _bad(tmp_path, "--schemes", "jscc,magic", images=image_dir)
    assert "unknown 'magic'" in capsys.readouterr().err
    _bad(tmp_path, "--cbr", "1/2", "--schemes", "jscc", images=image_dir)
    assert "outside the codec's range" in capsys.readouterr().err
    ck = tmp_path / "corrupt.safetensors"
    ck.write_bytes(b"\x01" * 64)
    _bad(tmp_path, "--codec", str(ck), "--schemes", "jscc", images=image_dir)
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


def test_draws_give_mean_and_interval_and_the_genie_is_a_bound(image_dir, tmp_path, tiny_ckpt):
    out = tmp_path / "draws.json"
    argv = ["eval-codec", "--images", str(image_dir), "--channel", "rayleigh", "--draws", "3"]
    argv += ["--snr-db", "4", "--schemes", "jscc,digital,digital_genie", "--no-lpips"]
    argv += ["--codec", str(tiny_ckpt), "--out", str(out)]
    assert main(argv) == 0
    doc = json.loads(out.read_text())
    assert doc["config"]["draws"] == 3 and "bootstrap" in doc["config"]["interval"]
    assert "perfect CSI" in doc["config"]["receiver"]
    rows = {r["scheme"]: r for r in doc["results"]}
    for r in rows.values():
        flat = [v for row in r["psnr_per_draw"] for v in row]
        assert len(r["psnr_per_draw"]) == 2 and len(flat) == 6
        assert r["psnr"] == pytest.approx(np.mean(flat))
        lo, hi = r["psnr_ci95"]
        assert lo <= r["psnr"] <= hi
    assert rows["digital_genie"]["bound"] and "digital_genie" in doc["config"]["bounds"]
    assert rows["digital"]["mcs_choice"] == "auto" and "rayleigh" in rows["digital"]["calibration"]
    assert set(rows["digital"]["views_lost"]) == {"budget", "channel"}
    assert len(rows["digital"]["mcs_used"]) == 1  # one MCS for every draw at one SNR
    honest = np.array(rows["digital"]["psnr_per_draw"])
    genie = np.array(rows["digital_genie"]["psnr_per_draw"])
    assert (genie >= honest - 1e-9).all()  # same draws (common random numbers)


def test_zero_draws_refused_before_any_work(image_dir, tmp_path, capsys, monkeypatch):
    import semcodec.jscc.codec
    import semcodec.links.schemes

    def boom(*a, **k):
        raise AssertionError("work started")

    monkeypatch.setattr(semcodec.jscc.codec, "load_codec", boom)
    monkeypatch.setattr(semcodec.links.schemes, "load_image_folder", boom)
    for n in ("0", "-2"):
        _bad(tmp_path, "--draws", n, images=image_dir)
        assert f"argument --draws: must be an integer in [1, 10000], got {n!r}" in (
            capsys.readouterr().err
        )
    for n in ("-1", "1.5", "20000"):
        _bad(tmp_path, "--refine-steps", n, images=image_dir)
        err = capsys.readouterr().err
        assert "--refine-steps" in err and "[0, 10000]" in err and err.count("\n") == 1


def test_unknown_channel_lists_the_known_ones(image_dir, tmp_path, capsys):
    _bad(tmp_path, "--channel", "mars", images=image_dir)
    err = capsys.readouterr().err
    assert "unknown channel 'mars'" in err and "rayleigh_fast" in err and "tdl" in err


def test_checkpoint_for_another_snr_range_is_refused_naming_both(image_dir, tmp_path, capsys):
    import dataclasses

    from semcodec import save_checkpoint
    from semcodec.jscc import JSCCModel, make_model

    cfg = dataclasses.replace(make_model("adjscc_s4_w64").cfg, snr_min_db=5.0, snr_max_db=20.0)
    ck = tmp_path / "high.safetensors"
    save_checkpoint(ck, JSCCModel(cfg), {"name": "high-snr"})
    out = tmp_path / "bad.json"
    argv = ["eval-codec", "--images", str(image_dir), "--snr-db", "1,10", "--schemes", "jscc"]
    rc = main([*argv, "--codec", str(ck), "--out", str(out)])
    err = capsys.readouterr().err
    assert rc == 2 and not out.exists()
    assert "[1, 10] dB" in err and "[5, 20] dB" in err and "high-snr" in err


def test_refined_jscc_runs_alone_and_records_its_steps(image_dir, tmp_path):
    """jscc_refined loads the codec by its kind (it failed alone: no codec loaded), and the
    result records how many steps the transmitter took."""
    out = tmp_path / "refined.json"
    argv = ["eval-codec", "--images", str(image_dir), "--snr-db", "4", "--no-lpips"]
    argv += ["--schemes", "jscc_refined", "--refine-steps", "2", "--out", str(out)]
    assert main(argv) == 0
    doc = json.loads(out.read_text())
    assert doc["config"]["refine_steps"] == 2
    assert [r["scheme"] for r in doc["results"]] == ["jscc_refined"]


def test_an_interrupted_evaluation_resumes_from_its_finished_points(tmp_path, monkeypatch):
    """The first point finishes, the second is interrupted: OUT.partial holds the first; the
    same command again computes only the second and writes the same first row."""
    from osnerf.commands import eval_codec

    img = tmp_path / "img"
    img.mkdir()
    rng = np.random.default_rng(0)
    Image.fromarray((rng.random((32, 32, 3)) * 255).astype(np.uint8)).save(img / "a.png")
    out = tmp_path / "r.json"
    argv = ["eval-codec", "--images", str(img), "--snr-db", "1,10", "--schemes", "analog"]
    argv += ["--no-lpips", "--out", str(out)]
    real = eval_codec._point
    calls = []

    def interrupted(ctx, scheme, ki, snr, *a):
        calls.append(snr)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return real(ctx, scheme, ki, snr, *a)

    monkeypatch.setattr(eval_codec, "_point", interrupted)
    assert main(argv) == 130  # Ctrl-C: "interrupted"
    partial = eval_codec.partial_path(out)
    assert not out.exists() and partial.is_file()
    first = json.loads(partial.read_text())["results"]
    assert [r["snr_db"] for r in first] == [1.0]
    calls.clear()
    monkeypatch.setattr(eval_codec, "_point", lambda *a: calls.append(a[3]) or real(*a))
    assert main(argv) == 0
    assert calls == [10.0] and not partial.exists()
    rows = json.loads(out.read_text())["results"]
    assert [r["snr_db"] for r in rows] == [1.0, 10.0] and rows[0] == first[0]


def test_every_scheme_plans_from_the_same_seeded_estimate(image_dir, tmp_path):
    """--snr-error-db: each image's estimate is the truth plus a seeded Gaussian error, the
    same for every scheme and recorded beside the truth; the error has its spread."""
    from osnerf.commands.eval_codec import snr_belief

    assert snr_belief(4.0, None, 0.0, 0, 0, 0, 0) is None  # exact knowledge: as before
    assert snr_belief(10.0, 4.0, 0.0, 0, 0, 0, 0) == 4.0
    errs = np.array([snr_belief(4.0, None, 2.0, 5, 0, i, 0) - 4.0 for i in range(4000)])
    assert errs.std() == pytest.approx(2.0, rel=0.05) and abs(errs.mean()) < 0.13
    out = tmp_path / "est.json"
    argv = ["eval-codec", "--images", str(image_dir), "--snr-db", "4", "--snr-error-db", "2"]
    argv += ["--schemes", "jscc,digital,digital_naive,softcast", "--no-lpips", "--out", str(out)]
    assert main(argv) == 0
    doc = json.loads(out.read_text())
    believed = {r["scheme"]: r["snr_believed_db"] for r in doc["results"]}
    assert len({json.dumps(v) for v in believed.values()}) == 1, believed
    assert all(v != 4.0 for row in believed["digital"] for v in row)
    assert doc["config"]["snr_error_db"] == 2.0 and all(r["snr_db"] == 4.0 for r in doc["results"])

"""`osnerf run` end to end on the tiny scene, its bad-input errors, the knowledge-base refusal
and resuming from cached stages. The codec is whatever checkpoint exists: the shipped
default if present, else an untrained registered architecture (the pipeline must not
depend on the weights)."""

import base64
import json

import numpy as np
import pytest

from osnerf.cli import main

SMALL = ["--resolution", "32", "--views", "4", "--test-views", "2", "--nerf-steps", "60"]
SMALL += ["--renderer-steps", "0"]  # scored in the report-structure test only


def _run(env, out, *extra):
    return main(
        [
            "run",
            "--scene",
            "tiny",
            "--codec",
            env["codec"],
            "--cache-dir",
            env["cache"],
            "--out",
            str(out),
            *SMALL,
            *extra,
        ]
    )


@pytest.mark.parametrize(
    "args, message",
    [
        (["--scene", "atlantis"], "unknown scene 'atlantis'; known: firefighter"),
        (["--demand", "crate,piano"], "known objects: crate, post, cable"),
        (["--channel", "carrier-pigeon"], "invalid choice: 'carrier-pigeon'"),
        (["--schemes", "jscc,telepathy"], "argument --schemes: must be a comma-separated subset"),
        (["--channel", "tdl", "--mcs", "foo"], "invalid choice: 'foo'"),
        (["--image-codec", "bmp"], "invalid choice: 'bmp'"),
        (["--snr-db", "55"], "outside the codec's range"),
        (["--nerf-steps", "0"], "argument --nerf-steps: must be an integer in [1, "),
        (
            ["--renderer-steps", "-1"],
            "argument --renderer-steps: must be an integer in [0,",
        ),
    ],
)
def test_bad_input_is_one_clear_line_and_no_report(env, tmp_path, capsys, args, message):
    out = tmp_path / "bad"
    assert _run(env, out, *args) == 2  # a later --scene/--channel/... overrides the default
    err = capsys.readouterr().err.strip().splitlines()
    assert message in err[-1]
    assert not (out / "report.json").exists()
    assert not (out / "cache").exists() or not any((out / "cache").rglob("*.npz"))  # no heavy work


def test_demand_no_camera_sees(env, tmp_path, capsys):
    out = tmp_path / "hidden"
    assert _run(env, out, "--demand", "cable") == 2
    assert "no drone camera sees the demanded object(s) cable" in capsys.readouterr().err
    assert not (out / "report.json").exists()


def test_knowledge_base_mismatch_is_refused(env, tmp_path, capsys):
    out = tmp_path / "kb"
    assert _run(env, out, "--receiver-codec", env["other"]) == 2
    assert "knowledge-base mismatch" in capsys.readouterr().err
    assert not (out / "report.json").exists()


def test_pipeline_report_structure_ranges_and_resume(env, tmp_path):
    out = tmp_path / "tiny"
    schemes = "jscc,digital,digital_genie,full,gt"
    args = ["--channel", "awgn", "--snr-db", "10", "--schemes", schemes, "--seed", "3"]
    args += ["--renderer-steps", "5"]
    assert _run(env, out, *args) == 0
    report = json.loads((out / "report.json").read_text())
    for key in (
        "config",
        "seed",
        "git_commit",
        "versions",
        "schemes",
        "scu_decisions",
        "views",
        "link",
    ):
        assert key in report
    assert report["seed"] == 3 and report["config"]["scene"] == "tiny"
    assert list(report["schemes"]) == schemes.split(",")
    views = report["views"]
    sent = set(views["sent_on_demand"])
    assert sent and sent <= set(views["candidates"])
    assert not sent & {int(k) for k in views["not_sent"]}  # skipped views were never sent
    # AWGN at 10 dB: what arrived is close to what was sent; the ceiling sent it untouched
    rx = {n: s["psnr_received_object"] for n, s in report["schemes"].items()}
    assert rx["gt"] is None and report["schemes"]["gt"]["symbols_sent"] == 0
    assert rx["jscc"] > 15.0 and rx["digital_genie"] >= rx["digital"] - 1e-9, rx  # 19.6 measured
    for name, s in report["schemes"].items():
        assert -1 <= s["ssim"] <= 1, name
        assert set(s["seconds"]) >= {"encode", "air", "decode", "nerf"}
        assert s["seconds"]["air"] == pytest.approx(s["symbols_sent"] / 1e6)
        # the PSNR-vs-time curve on the held-out views: from step 0 to the end of the budget
        curve = s["nerf_curve"]
        assert curve[0]["step"] == 0 and curve[-1]["step"] == s["nerf_steps"]
        assert [c["seconds"] for c in curve] == sorted(c["seconds"] for c in curve)
        assert curve[-1]["seconds"] == pytest.approx(s["seconds"]["nerf"], abs=1e-3)
        if s["psnr_object"] is not None:
            assert curve[-1]["psnr_object"] == pytest.approx(s["psnr_object"], abs=1e-3)
        # both renderers on the held-out views: the full one is the render scored above
        assert set(s["renderers"]) == {"full", "features"}
        full, light = s["renderers"]["full"], s["renderers"]["features"]
        if s["psnr_object"] is not None:
            assert full["psnr_object"] == pytest.approx(s["psnr_object"], abs=1e-4), name
        if s["training_bounds"] == "whole scene":
            assert full["psnr"] == pytest.approx(s["psnr"], abs=1e-4), name
        else:
            assert "psnr" not in full
        assert full["seconds_per_view"] > 0 and light["seconds_per_view"] > 0
        assert light["speedup_vs_full"] == pytest.approx(
            full["seconds_per_view"] / light["seconds_per_view"]
        )
        assert light["settings"]["train_steps"] == 5 and light["setup_stats"]["steps"] == 5
        assert light["setup_cpu_seconds"] > 0 and not full["setup_stats"]
    sch = report["schemes"]
    assert sch["gt"]["symbols_sent"] == 0 and sch["gt"]["views_sent"] == len(sent)
    assert sch["jscc"]["views_sent"] == len(sent) and sch["full"]["views_sent"] == len(
        views["candidates"]
    )
    assert sch["jscc"]["symbols_sent"] < sch["full"]["symbols_sent"]
    # every object-routed scheme gets the SCU's on-demand budget per view; jscc may use less
    budget = sum(p["focus"]["symbols"] for p in views["plan"] if p["focus"] is not None)
    assert sch["digital"]["symbols_sent"] == budget >= sch["jscc"]["symbols_sent"] > 0
    assert sch["digital"]["views_lost"]["budget"] + sch["digital"]["views_lost"]["channel"] <= len(
        sent
    )
    stages = {d["stage"] for d in report["scu_decisions"]}
    assert {"collector", "knowledge_base", "rate", "encoder", "renderer"} <= stages
    html = (out / "report.html").read_text()
    assert html.count("data:image/png;base64,") >= 3
    png = html.split("data:image/png;base64,")[1].split('"')[0]
    assert base64.b64decode(png)[:8] == b"\x89PNG\r\n\x1a\n"
    # the received views the on-demand NeRF trained on are exactly the sent ones
    rx = json.loads((out / "received" / "jscc" / "transforms.json").read_text())
    assert len(rx["frames"]) == len(sent)

    # resume: the same command reuses every cached stage and reports the same numbers
    caches = sorted((out / "cache").rglob("*.npz"))
    stamps = [p.stat().st_mtime_ns for p in caches]
    assert _run(env, out, *args) == 0
    again = json.loads((out / "report.json").read_text())
    assert [p.stat().st_mtime_ns for p in caches] == stamps
    assert again["scu_decisions"] == report["scu_decisions"]  # the cached plan's too
    for name in sch:
        assert again["schemes"][name]["psnr"] == sch[name]["psnr"]
        assert np.isclose(again["schemes"][name]["seconds"]["nerf"], sch[name]["seconds"]["nerf"])


def test_a_field_trains_only_on_the_views_that_arrived(env, tmp_path):
    """The digital receiver knows which views were lost (a codeword that failed its
    checksum, or a budget that fitted nothing): its field trains on the views that arrived,
    not on their mid-grey placeholders. With none arrived the field is empty: the background
    on every held-out view, after no steps. (Block Rayleigh, seed 3: 2 of the 3 views lost
    at 0 dB, all 3 at -10 dB.)"""
    lost, sent = {}, {}
    for snr in ("0", "-10"):
        out = tmp_path / f"snr{snr}"
        args = ["--channel", "rayleigh", "--snr-db", snr, "--schemes", "digital", "--seed", "3"]
        assert _run(env, out, *args) == 0
        report = json.loads((out / "report.json").read_text())
        s = report["schemes"]["digital"]
        lost[snr], sent[snr] = sum(s["views_lost"].values()), s["views_sent"]
        frames = json.loads((out / "received" / "digital" / "transforms.json").read_text())
        assert len(frames["frames"]) == sent[snr] - lost[snr]
        trained = [d["decision"] for d in report["scu_decisions"] if d["stage"] == "renderer"]
        assert trained == [f"digital: train on {sent[snr] - lost[snr]} decoded views"]
        if lost[snr] == sent[snr]:
            assert s["nerf_steps"] == 0 and s["nerf_curve"] == [] and s["mask_iou"] == 0.0
        else:
            assert s["nerf_steps"] == 60
            # which views arrived is cached with the transmission: a field trained again
            # from the cached stage leaves the same views out
            for f in (out / "cache").glob("*/digital_nerf.*"):
                f.unlink()
            assert _run(env, out, *args) == 0
            again = json.loads((out / "report.json").read_text())["schemes"]["digital"]
            assert again["psnr_object"] == pytest.approx(s["psnr_object"], abs=1e-6)
    assert 0 < lost["0"] < sent["0"] and lost["-10"] == sent["-10"] > 0


def test_cache_key_does_not_depend_on_how_a_number_is_written():
    """The API takes 60 or 60.0 (the CLI always passes floats): one run, one cache folder,
    so a run started from the CLI resumes from Python and back; a real change still moves it."""
    from osnerf.run import RunConfig

    a = RunConfig(snr_db=0, max_seconds=60, renderer_steps=0, symbol_rate_hz=1_000_000)
    b = RunConfig(snr_db=0.0, max_seconds=60.0, renderer_steps=0, symbol_rate_hz=1e6)
    assert a.key() == b.key()
    assert RunConfig(snr_db=1.0).key() != b.key()
    assert RunConfig(schemes=("jscc",)).key() == RunConfig(schemes=("gt", "jscc")).key()


def test_cache_key_follows_the_codec_weights_not_the_path(tmp_path):
    """A checkpoint replaced under the same path (a new shipped default, a retrained file) is
    another run: its jscc stages are not reused from the old weights' cache folder."""
    import shutil

    import semcodec
    from osnerf.run import RunConfig

    ckpts = semcodec.DEFAULT_CHECKPOINT.parent
    path = tmp_path / "codec.safetensors"
    shutil.copy(ckpts / "default.safetensors", path)
    tx, rx = RunConfig(codec=f"jscc:{path}").key(), RunConfig(receiver_codec=f"jscc:{path}").key()
    assert RunConfig(codec=f"jscc:{path}").key() == tx
    shutil.copy(ckpts / "mix-v2.2.safetensors", path)
    assert RunConfig(codec=f"jscc:{path}").key() != tx
    assert RunConfig(receiver_codec=f"jscc:{path}").key() != rx


def _scheme(psnr_object, symbols, processing, curve=(), encode=0.0, decode=0.0):
    from osnerf.report import SchemeReport

    return SchemeReport(
        psnr=0.0,
        ssim=0.0,
        lpips=None,
        psnr_object=psnr_object,
        mask_iou=None,
        symbols_sent=symbols,
        views_sent=1,
        seconds={"encode": encode, "decode": decode},
        processing_seconds=processing,
        nerf_curve=[{"seconds": t, "psnr_object": p} for t, p in curve],
    )


def test_comparisons_by_hand():
    """jscc (headline) against full (the first whole-view scheme) and gt, numbers by hand:
    jscc's curve first reaches full's 20 dB at 30 s of NeRF, plus 2 s encode and 1 s
    decode = 33 s, over full's 50 s of processing = 0.66."""
    from osnerf.run.pipeline import comparisons
    from osnerf.schemes import SCHEMES

    schemes = {n: SCHEMES[n]() for n in ("jscc", "full", "gt")}
    results = {
        "jscc": _scheme(21.5, 300, 40.0, [(10, 15.0), (30, 20.5), (37, 21.5)], 2.0, 1.0),
        "full": _scheme(20.0, 1200, 50.0),
        "gt": _scheme(23.0, 0, 30.0),
    }
    comp = comparisons(results, schemes)
    assert comp["jscc_minus_full_psnr_object_db"] == pytest.approx(1.5)
    assert comp["jscc_minus_gt_psnr_object_db"] == pytest.approx(-1.5)
    assert comp["symbols_jscc_over_full"] == pytest.approx(0.25)
    assert comp["processing_jscc_over_full"] == pytest.approx(0.8)
    assert comp["jscc_processing_seconds_to_full_psnr_object"] == pytest.approx(33.0)
    assert comp["processing_jscc_over_full_at_equal_psnr_object"] == pytest.approx(0.66)
    results["jscc"] = _scheme(19.0, 300, 40.0, [(10, 15.0), (37, 19.0)], 2.0, 1.0)
    never = comparisons(results, schemes)
    assert never["jscc_processing_seconds_to_full_psnr_object"] is None
    assert never["processing_jscc_over_full_at_equal_psnr_object"] is None
    assert never["unequal_budgets"] == []  # no steps recorded: nothing to compare


def test_unequal_nerf_budgets_are_flagged():
    """44 against 3 steps (a wall-clock budget on a busy machine) is flagged; 6000 against
    6500 (8 %) is within the 10 % tolerance."""
    from osnerf.run.pipeline import unequal_budgets

    a, b, c = _scheme(20.0, 1, 1.0), _scheme(7.2, 0, 1.0), _scheme(21.0, 1, 1.0)
    a.nerf_steps, b.nerf_steps, c.nerf_steps = 44, 3, 44
    flags = unequal_budgets({"jscc": a, "gt": b, "digital": c})
    assert len(flags) == 2 and all("gt (3 NeRF steps)" in f for f in flags), flags
    a.nerf_steps, b.nerf_steps, c.nerf_steps = 6000, 6500, 6000
    assert unequal_budgets({"jscc": a, "gt": b, "digital": c}) == []


def test_the_ceiling_gets_the_same_steps_on_a_busy_machine(env, tmp_path):
    """By default every scheme's field takes the same optimiser steps, so another process
    hogging the CPU cannot starve one scheme's field: gt (the undistorted views) gets
    exactly jscc's steps and ends at least as good, and nothing is flagged."""
    import subprocess
    import sys

    hog = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    try:
        out = tmp_path / "busy"
        args = ["--schemes", "jscc,gt", "--nerf-steps", "400", "--seed", "0", "--refine-steps", "0"]
        assert _run(env, out, "--channel", "rayleigh", "--snr-db", "0", *args) == 0
    finally:
        hog.kill()
        hog.wait()
    report = json.loads((out / "report.json").read_text())
    sch = report["schemes"]
    assert sch["gt"]["nerf_steps"] == sch["jscc"]["nerf_steps"] == 400
    assert sch["gt"]["psnr_object"] >= sch["jscc"]["psnr_object"], sch
    assert report["comparisons"]["unequal_budgets"] == []

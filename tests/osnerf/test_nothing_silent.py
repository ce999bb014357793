"""Runs, digital, view selection, radio maps, renders and resumes: a refusal leaves nothing,
a flag that does not apply is refused, and what cannot be compared or ranked says so."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from osnerf.cli import main


def _scheme(name, psnr_object, views_sent=4, views_lost=None, seconds=None):
    from osnerf.report import SchemeReport

    return SchemeReport(
        psnr=0.0,
        ssim=0.0,
        lpips=None,
        psnr_object=psnr_object,
        mask_iou=None,
        symbols_sent=100,
        views_sent=views_sent,
        seconds=seconds or {"encode": 0.0, "decode": 0.0},
        processing_seconds=0.0,
        views_lost=views_lost,
    )


# --- M1: a refused or failed run leaves nothing ----------------------------------------------


def test_the_stage_cache_folder_is_made_with_the_first_stage(tmp_path):
    from osnerf.run.cache import StageCache

    cache = StageCache(tmp_path / "out" / "cache" / "abc")
    assert not (tmp_path / "out").exists()  # a run that fails before its first stage
    assert cache.load("x") is None
    cache.save("x", {"a": np.zeros(2)}, {"k": 1})
    assert (tmp_path / "out" / "cache" / "abc" / "x.npz").is_file()


def test_a_folder_of_empty_folders_is_not_files(tmp_path):
    from osnerf.commands.args import UsageError, output_dir

    out = tmp_path / "out"
    (out / "cache" / "0123abcd").mkdir(parents=True)  # what an earlier refusal left
    assert output_dir(out, "--out") == out
    (out / "cache" / "0123abcd" / "x.npz").write_bytes(b"x")
    with pytest.raises(UsageError, match="holds files"):
        output_dir(out, "--out")


# --- D1: a scheme none of whose views arrived is compared with nothing ----------------------


def test_a_scheme_that_received_nothing_is_not_compared():
    from osnerf.run.pipeline import comparisons
    from osnerf.schemes import SCHEMES

    schemes = {n: SCHEMES[n]() for n in ("jscc", "digital", "gt")}
    results = {
        "jscc": _scheme("jscc", 20.0),
        "digital": _scheme("digital", 8.0, views_lost={"budget": 4, "channel": 0}),
        "gt": _scheme("gt", 25.0),
    }
    out = comparisons(results, schemes)
    assert out["jscc_minus_digital_psnr_object_db"] is None
    assert out["jscc_minus_gt_psnr_object_db"] == pytest.approx(-5.0)
    (line,) = out["nothing_arrived"]
    assert line.startswith("digital: none of its 4 views arrived (4 to the budget)")


# --- D2, D3: flags that do not apply ---------------------------------------------------------


@pytest.mark.parametrize(
    "extra,flag",
    [
        (["--schemes", "jscc,gt", "--mcs", "qpsk-1/2"], "--mcs"),
        (["--schemes", "jscc,full,gt", "--image-codec", "jpeg"], "--image-codec"),
    ],
)
def test_run_refuses_digital_flags_without_a_digital_scheme(tmp_path, capsys, extra, flag):
    out = tmp_path / "run"
    assert main(["run", "--out", str(out), *extra]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"{flag} applies to the digital schemes" in err[0]
    assert not out.exists()


@pytest.fixture
def image_dir(tmp_path):
    from PIL import Image

    d = tmp_path / "img"
    d.mkdir()
    Image.fromarray(np.full((48, 48, 3), 90, np.uint8)).save(d / "a.png")
    return d


@pytest.mark.parametrize(
    "extra,says",
    [
        (["--schemes", "digital", "--mcs", "qpsk-1/2"], "--mcs applies to the fixed-MCS schemes"),
        (["--schemes", "digital_fixed", "--mcs", ""], "--mcs must be one of"),
    ],
)
def test_eval_codec_refuses_an_mcs_that_is_not_used(image_dir, tmp_path, capsys, extra, says):
    out = tmp_path / "r.json"
    argv = ["eval-codec", "--images", str(image_dir), "--snr-db", "10", "--out", str(out)]
    assert main([*argv, *extra]) == 2
    assert says in capsys.readouterr().err
    assert not out.exists()


def test_the_log_names_the_nerf_budget_that_applies():
    from osnerf.run import RunConfig

    assert RunConfig(nerf_steps=50).nerf_budget().describe() == "50 steps"
    assert RunConfig(nerf_steps=None, max_seconds=600.0).nerf_budget().describe() == "600 s"


# --- M2: a ground station where no antenna can be ------------------------------------------


def test_a_ground_station_inside_an_object_or_under_the_terrain_is_named():
    from osnerf.run.links import ground_station_warning

    meta = {
        "object_aabb": {"ground": [[-9, -9, -0.1], [9, 9, 0.0]], "crate": [[0, 0, 0], [1, 1, 1]]}
    }
    assert ground_station_warning(meta, (5.0, 3.0, 1.5)) is None
    inside = ground_station_warning(meta, (0.5, 0.5, 0.5))
    assert "inside the box of object 'crate'" in inside
    under = ground_station_warning(meta, (5.0, 3.0, -2.0))
    assert "below the scene's lowest surface" in under


# --- M3: radio has nothing to rank where every view expects the same SNR --------------------


def test_radio_selection_on_one_snr_for_every_view_says_it_ranks_nothing():
    from osnerf.scu.selection import choose_views, radio_tie

    assert radio_tie("radio", [5.0, 5.0, 5.0]) is not None
    assert radio_tie("radio", [5.0, 6.0]) is None and radio_tie("sight", [5.0, 5.0]) is None
    logged = []
    col = SimpleNamespace(indices=np.array([0, 1, 2]), subset=lambda keep: keep)
    dirs = {v: np.array([np.cos(v), np.sin(v), 0.5]) for v in range(3)}
    choose_views(
        lambda *a, **k: logged.append((a, k)), col, {0: 5.0, 1: 5.0, 2: 5.0}, dirs, "radio", 2
    )
    assert any("ranks nothing" in a[1] and k.get("tie") for a, k in logged)


# --- M4: Pluto discovery names what every command can do -----------------------------------


def test_no_pluto_found_names_iiod_remote_not_a_flag(monkeypatch):
    import hil
    from hil.pluto import driver

    monkeypatch.delenv("IIOD_REMOTE", raising=False)
    monkeypatch.setattr(driver, "import_iio", lambda: object())
    monkeypatch.setattr(driver, "find_plutos", lambda: [])
    with pytest.raises(hil.HilError) as e:
        driver.Pluto.open()
    assert "IIOD_REMOTE=ADDRESS" in str(e.value) and "URI" not in str(e.value)


# --- M5, M6: radiomap flags -----------------------------------------------------------------


def test_radiomap_samples_as_its_help_writes_them():
    from osnerf.commands.radiomap import samples_count

    assert (
        samples_count("1e4") == 10_000
        and samples_count("1e3") == 1000
        and samples_count("20000") == 20000
    )
    for bad in ("1500.5", "1e2", "x", "1e10"):
        with pytest.raises(Exception, match=r"must be an integer in \[1000, 1000000000\]"):
            samples_count(bad)


def test_radiomap_too_fine_a_cell_is_refused_naming_the_flag(tmp_path, capsys):
    out = tmp_path / "map"
    argv = ["radiomap", "--scene", "tiny", "--cell-size-m", "0.0001", "--samples", "1e3"]
    assert main([*argv, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].count("--cell-size-m") >= 1 and "cell_size_m" not in err[0]
    assert not (out / "radiomap.json").exists()


# --- P1: every second a scheme spends is drawn ----------------------------------------------


def test_the_time_chart_draws_every_second_under_one_set_of_names():
    from osnerf.report_figures import TIME_PARTS, time_parts

    digital = {"encode": 0.0, "decode": 0.0, "nerf": 6.5, "codec_and_ldpc": 7.4, "air": 0.1}
    jscc = {"encode": 0.3, "decode": 0.2, "nerf": 6.4, "air": 0.1}
    for seconds in (digital, jscc):
        parts = time_parts(seconds)
        assert tuple(parts) == TIME_PARTS
        processing = seconds["encode"] + seconds["decode"] + seconds["nerf"]
        processing += seconds.get("codec_and_ldpc", 0.0)
        assert parts["encode + decode"] + parts["nerf"] == pytest.approx(processing)
    assert time_parts(digital)["encode + decode"] == pytest.approx(7.4)


# --- E1: an interval a PSNR can be in -------------------------------------------------------


def test_psnr_interval_stays_within_the_values_and_is_none_for_too_few():
    from osnerf.commands.eval_codec import mean_ci95

    m, lo, hi = mean_ci95([8.0, 41.8])  # two images: no interval
    assert m == pytest.approx(24.9) and lo is None and hi is None
    vals = [8.0, 41.8, 9.0, 40.0, 12.0, 38.0]
    m, lo, hi = mean_ci95(vals)
    assert min(vals) <= lo <= m <= hi <= max(vals)
    assert mean_ci95(vals) == (m, lo, hi)  # the same values, the same interval


# --- R1: a changed --data names the folders ------------------------------------------------


def test_a_changed_data_folder_on_resume_names_the_folders():
    from semcodec import TrainConfig
    from semcodec.training.state import ResumeRefused, check_resume

    cfg = TrainConfig()
    import dataclasses

    state = {
        "config": dataclasses.asdict(cfg),
        "step": 3,
        "elapsed_s": 1.0,
        "inputs": {"data": "a" * 64, "data_dirs": ["bsds/train"], "init": None},
    }
    new = {"data": "b" * 64, "data_dirs": ["kodak"], "init": None}
    with pytest.raises(ResumeRefused) as e:
        check_resume(state, cfg, new, Path("run/last_state.pt"))
    msg = str(e.value)
    assert "bsds/train" in msg and "kodak" in msg
    # the same files under another path are the same training
    same = {**new, "data": "a" * 64}
    assert check_resume(state, cfg, same, Path("run/last_state.pt")) == {}

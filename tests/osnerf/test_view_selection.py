"""The SCU's view selection: sight (unchanged without a count), radio (highest expected SNR)
and joint (coverage gain times link quality), on hand-made numbers, and its flags."""

from __future__ import annotations

import math

import numpy as np
import pytest

from osnerf.cli import main
from osnerf.collect import Collection
from osnerf.run import RunConfig
from osnerf.scu import VIEW_SELECTIONS, SemanticControlUnit, select_views
from osnerf.scu.selection import coverage, link_quality


def _ring(num: int) -> np.ndarray:
    a = 2 * np.pi * np.arange(num) / num
    return np.c_[np.cos(a), np.sin(a), np.zeros(num)]


def _collection(views) -> Collection:
    n = len(views)
    rng = np.random.default_rng(0)
    return Collection(
        np.asarray(views, np.int64),
        rng.random((n, 4, 4, 3), dtype=np.float32),
        rng.random((n, 4, 4), dtype=np.float32),
        np.arange(max(views) + 2),
        {max(views) + 1: "not visible"},
        rng.random((n, 1, 4, 4), dtype=np.float32),
    )


def test_the_table_holds_the_three_rules_and_sight_is_the_default():
    assert list(VIEW_SELECTIONS) == ["sight", "radio", "joint"]
    cfg = RunConfig()
    assert cfg.view_selection == "sight" and cfg.max_views is None


def test_sight_without_a_count_sends_every_visible_view_unchanged():
    """Without --max-views, sight keeps the collector's views exactly (the same arrays)."""
    views = [1, 3, 4, 7, 9]
    col = _collection(views)
    scu = SemanticControlUnit.__new__(SemanticControlUnit)
    scu.decisions = []
    snr = {v: s for v, s in zip(views, (5.0, -20.0, 3.0, 9.0, 0.0))}
    dirs = dict(zip(views, _ring(5)))
    out = scu.choose_views(col, snr, dirs, "sight", None)
    assert out.indices.tolist() == views
    np.testing.assert_array_equal(out.images, col.images)
    np.testing.assert_array_equal(out.object_masks, col.object_masks)
    assert out.reasons == col.reasons
    assert {
        c.view for c in select_views("sight", views, list(snr.values()), _ring(5), None)
    } == set(views)


def test_radio_picks_the_highest_expected_snr():
    views = [10, 11, 12, 13, 14, 15, 16, 17]
    snr = [3.0, -12.0, 14.0, 7.5, 14.0, -1.0, 9.0, 2.0]
    got = select_views("radio", views, snr, _ring(8), 4)
    assert [c.view for c in got] == [12, 14, 16, 13]  # the 14 dB tie goes to the lower index
    assert [c.expected_snr_db for c in got] == [14.0, 14.0, 9.0, 7.5]


def test_coverage_and_link_quality_by_hand():
    d = np.array([[1.0, 0, 0], [0.5, math.sqrt(3) / 2, 0], [-1.0, 0, 0]])
    assert coverage(d, []) == 0.0
    assert coverage(d, [0]) == pytest.approx((1 + 0.5 + 0) / 3)
    assert coverage(d, [0, 2]) == pytest.approx((1 + 0.5 + 1) / 3)
    q = link_quality([12.0, 0.0, -10.0])
    assert q[0] == 1.0
    assert q[1] == pytest.approx(1 / math.log2(1 + 10**1.2))
    assert q[2] == pytest.approx(math.log2(1.1) / math.log2(1 + 10**1.2))


@pytest.mark.parametrize("snr_c_db, second", [(3.0, 0), (6.0, 2)])
def test_joint_trades_coverage_against_snr_as_stated(snr_c_db, second):
    """Directions A (60 degrees, 11 dB), B (0 degrees, 12 dB), C (180 degrees). A or B alone
    covers (1 + 0.5 + 0) / 3 = 1/2: joint takes B (the better link), sight takes A (the tie's
    lower index). After B, A adds 1/6 at quality q_A = log2(1 + 10**1.1) / log2(1 + 10**1.2)
    and C adds 1/3 at q_C: joint takes C only when q_C / 3 > q_A / 6 (snr_C above 4.33 dB),
    sight takes C whatever its SNR."""
    d = np.array([[0.5, math.sqrt(3) / 2, 0], [1.0, 0, 0], [-1.0, 0, 0]])  # A, B, C
    snr = [11.0, 12.0, snr_c_db]
    best = math.log2(1 + 10**1.2)
    q_a, q_c = math.log2(1 + 10**1.1) / best, math.log2(1 + 10 ** (snr_c_db / 10)) / best
    joint = select_views("joint", [0, 1, 2], snr, d, 2)
    sight = select_views("sight", [0, 1, 2], snr, d, 2)
    assert [c.view for c in sight] == [0, 2]
    assert joint[0].view == 1 and joint[0].coverage_gain == pytest.approx(0.5)
    assert joint[0].score == pytest.approx(0.5)
    assert joint[1].view == second
    want = {0: (1 / 6, q_a), 2: (1 / 3, q_c)}[second]
    assert joint[1].coverage_gain == pytest.approx(want[0])
    assert joint[1].link_quality == pytest.approx(want[1])
    assert joint[1].score == pytest.approx(want[0] * want[1], abs=1e-8)
    assert max(q_a / 6, q_c / 3) == pytest.approx(joint[1].score, abs=1e-8)


def test_choose_views_logs_why_each_view_was_chosen():
    views = [2, 5, 8, 11]
    col = _collection(views)
    scu = SemanticControlUnit.__new__(SemanticControlUnit)
    scu.decisions = []
    snr = dict(zip(views, (10.0, -10.0, 8.0, 0.0)))
    out = scu.choose_views(col, snr, dict(zip(views, _ring(4))), "joint", 2)
    assert out.num_sent == 2
    log = [d for d in scu.decisions if d["stage"] == "selection"]
    assert log[0]["rule"] == "joint" and log[0]["views"] == sorted(
        log[0]["views"], key=log[0]["views"].index
    )
    per_view = log[1:]
    assert [d["view"] for d in per_view] == log[0]["views"]
    assert set(out.indices.tolist()) == set(log[0]["views"])
    for d in per_view:
        assert {"expected_snr_db", "coverage_gain", "link_quality", "score"} <= set(d)
        assert d["score"] == pytest.approx(d["coverage_gain"] * d["link_quality"], abs=1e-9)
        assert f"expected {d['expected_snr_db']:.1f} dB" in d["decision"]


@pytest.mark.parametrize(
    "extra, message",
    [
        (
            ["--view-selection", "joint"],
            "--view-selection 'joint' chooses among the visible views: give --max-views",
        ),
        (["--view-selection", "radio"], "give --max-views"),
        (
            ["--view-selection", "nope", "--max-views", "3"],
            "argument --view-selection: invalid choice",
        ),
        (["--max-views", "0"], "argument --max-views: must be an integer in [1, 512]"),
        (["--max-views", "2.5"], "argument --max-views"),
    ],
)
def test_bad_selection_flags_are_one_line_errors(tmp_path, capsys, extra, message):
    out = tmp_path / "run"
    assert main(["run", "--out", str(out), *extra]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and message in err, err
    assert not out.exists()


@pytest.mark.raytracing
def test_a_raytraced_run_sends_the_views_the_rule_chose(tmp_path):
    """End to end on the tiny scene over ray-traced links: ``radio`` sends the visible views
    with the highest link SNR, the default (sight) every visible view; the report names the
    rule and each chosen view's reasons."""
    import json

    small = ["--scene", "tiny", "--channel", "raytraced", "--snr-db", "5", "--schemes", "gt"]
    small += ["--resolution", "24", "--views", "8", "--test-views", "1", "--nerf-steps", "5"]
    small += ["--renderer-steps", "0", "--cache-dir", str(tmp_path / "cache")]
    assert main(["run", *small, "--out", str(tmp_path / "sight")]) == 0
    by_radio = ["--view-selection", "radio", "--max-views", "2", "--out", str(tmp_path / "radio")]
    assert main(["run", *small, *by_radio]) == 0
    sight = json.loads((tmp_path / "sight" / "report.json").read_text())
    radio = json.loads((tmp_path / "radio" / "report.json").read_text())
    visible = [v for v in sight["views"]["candidates"] if str(v) not in sight["views"]["not_sent"]]
    visible = [v for v in visible if v not in sight["views"]["outage"]]
    assert sight["views"]["sent_on_demand"] == visible and len(visible) > 2
    assert not [d for d in sight["scu_decisions"] if d["stage"] == "selection"]
    snr = {int(k): v for k, v in radio["views"]["link_snr_db"].items()}
    best = sorted(visible, key=lambda v: (-snr[v], v))[:2]
    assert sorted(radio["views"]["sent_on_demand"]) == sorted(best)
    assert radio["config"]["view_selection"] == "radio" and radio["config"]["max_views"] == 2
    log = [d for d in radio["scu_decisions"] if d["stage"] == "selection"]
    assert log[0]["views"] == best and [d["view"] for d in log[1:]] == best
    assert [d["expected_snr_db"] for d in log[1:]] == pytest.approx([snr[v] for v in best])

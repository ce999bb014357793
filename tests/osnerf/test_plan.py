"""The SCU's typed plan and the report's per-view summary: a view's plan has a whole-view
part and an optional on-demand part of the same type, a scheme carries out one of them, and
view ids are ints everywhere but in JSON."""

import json

from osnerf.link_report import LinkReport
from osnerf.plan import Allocation, RunPlan, ViewLink, ViewPlan, ViewSend
from osnerf.report import Report, SchemeReport, ViewsSummary

WHOLE = Allocation(cbr=1 / 12, repetitions=2, encoder_snr_db=3.0, symbols=600)
FOCUS = Allocation(cbr=0.05, repetitions=1, encoder_snr_db=0.0, symbols=400)
PLAN = RunPlan(
    (
        ViewPlan(3, ViewLink(0.0, 0.0), WHOLE, FOCUS),
        ViewPlan(4, ViewLink(1.0, 0.5), WHOLE),
    ),
    outage=(5,),
    oversampling=2,
    height=10,
    width=10,
    static_link=True,
)


def test_a_scheme_carries_out_one_part_of_each_view():
    assert PLAN.for_scheme(object_routed=True) == [ViewSend(3, 0.0, FOCUS, 0.0)]
    assert PLAN.for_scheme(object_routed=False) == [
        ViewSend(3, 0.0, WHOLE, 0.0),
        ViewSend(4, 1.0, WHOLE, 0.5),  # the truth and what the transmitter believes
    ]
    assert [p.view for p in PLAN.on_demand()] == [3] and PLAN.outage == (5,)
    assert PLAN.full_scene_symbols == 1200


def test_plan_json_round_trip_and_the_flat_plan_of_older_reports():
    assert RunPlan.from_dict(json.loads(json.dumps(PLAN.to_dict()))) == PLAN
    flat = {
        "view": 3,
        "snr_db": 0.0,
        "measured_snr_db": 0.0,
        "encoder_snr_db": 3.0,
        "cbr": 1 / 12,
        "repetitions": 2,
        "on_demand": True,
        "focus_cbr": 0.05,
        "budget_symbols": 400,
        "full_symbols": 600,
        "outage": False,
        "focus_repetitions": 1,
        "focus_encoder_snr_db": 0.0,
    }
    assert ViewPlan.from_dict(flat) == PLAN.views[0]
    outage = dict(flat, view=5, outage=True, on_demand=False)  # no plan now
    views = ViewsSummary.from_dict({"outage": [5], "plan": [flat, outage]})
    assert views.plan == [PLAN.views[0]] and views.outage == [5]


def test_report_views_have_int_keys_and_json_string_keys():
    views = ViewsSummary(
        candidates=[3, 4, 5],
        sent_on_demand=[3],
        not_sent={4: "too small"},
        outage=[5],
        link_snr_db={3: 0.0, 4: 1.0},
        measured_snr_db={3: 0.0, 4: 0.5},
        cbr={3: 1 / 12, 4: 1 / 12},
        cbr_on_demand={3: 0.05},
        repetitions={3: 2, 4: 2},
        repetitions_on_demand={3: 1},
        object_oversampling=2,
        full_scene_symbols=1200,
        plan=list(PLAN.views),
    )
    seconds = {"encode": 0.1, "air": 0.2, "decode": 0.1, "nerf": 1.0}
    report = Report(
        scene={"name": "tiny"},
        demand={"objects": ["crate"]},
        link=LinkReport("awgn"),
        snr_db=0.0,
        symbol_rate_hz=1e6,
        codec=None,
        views=views,
        schemes={"jscc": SchemeReport(20.0, 0.5, None, 21.0, None, 400, 1, seconds, 1.2)},
        comparisons={},
        scu_decisions=[],
        metric_notes="",
        seconds_total=2.0,
        scene_seconds=0.5,
    )
    d = json.loads(json.dumps(report.to_dict()))
    assert d["views"]["cbr_on_demand"] == {"3": 0.05} and d["views"]["not_sent"] == {
        "4": "too small"
    }
    assert d["views"]["plan"][0]["focus"]["symbols"] == 400
    assert Report.from_dict({"seed": 0, **d}) == report


def test_the_transmitters_estimate_is_the_measurement_plan_or_both_with_a_seeded_error():
    """Unchanged with exact knowledge; a fixed plan replaces every view's measurement; the
    error is zero-mean with the asked spread, the same for the same seed, and a config with
    exact knowledge keeps the cache key it always had."""
    import numpy as np
    import pytest

    from osnerf.run.config import RunConfig
    from osnerf.scu.unit import transmitter_estimate

    measured = np.linspace(-5.0, 10.0, 4000)
    assert np.array_equal(transmitter_estimate(measured, None, 0.0, 7), measured)
    assert np.array_equal(transmitter_estimate(measured, 4.0, 0.0, 7), np.full(4000, 4.0))
    err = transmitter_estimate(measured, None, 2.0, 7) - measured
    assert abs(err.mean()) < 4 * 2.0 / np.sqrt(4000)
    assert err.std() == pytest.approx(2.0, rel=0.05)
    assert np.array_equal(transmitter_estimate(measured, None, 2.0, 7) - measured, err)
    assert not np.array_equal(transmitter_estimate(measured, None, 2.0, 8) - measured, err)
    assert RunConfig(snr_error_db=0.0, plan_snr_db=None).key() == RunConfig().key()
    assert RunConfig(snr_error_db=2.0).key() != RunConfig().key()
    assert RunConfig(plan_snr_db=4.0).key() != RunConfig().key()
    assert not RunConfig().transmitter_estimates and RunConfig(snr_error_db=1).transmitter_estimates

"""The report's link: typed sections in memory (per-view maps keyed by int), flat in
report.json with string keys, in the order reports have always had; read back to the same
text."""

import json
from pathlib import Path

import pytest

from osnerf.link_report import (
    AirSnr,
    FrameCounts,
    LinkReport,
    Motion,
    Positions,
    Radios,
    Receiver,
    Trace,
    TracedAir,
)

RESULTS = Path(__file__).resolve().parents[2] / "bench-results"


def _radios(**kw) -> Radios:
    return Radios("hackrf", "phy OFDM frames", 2e6, 2.45e9, 2048, **kw)


def _roundtrip(link: LinkReport) -> dict:
    d = json.loads(json.dumps(link.to_dict()))
    back = LinkReport.from_dict(d)
    assert back == link  # per-view keys are ints again
    assert json.dumps(back.to_dict()) == json.dumps(d)
    return d


def test_simulated_channel_order():
    link = LinkReport("tdl", receiver=Receiver("ls (pilots)", ofdm=True), channel_params={"a": 1})
    d = _roundtrip(link)
    assert list(d) == ["channel", "csi", "ofdm", "equalizer", "channel_params"]
    assert list(_roundtrip(LinkReport("awgn", receiver=Receiver("perfect")))) == [
        "channel",
        "csi",
        "equalizer",
    ]


def test_over_the_air_emulated_and_real_boards():
    emulated = LinkReport(
        "ota",
        radios=_radios(ppm=[0.0, 20.0], multipath=[[0, "1"]], delay_s=5e-6),
        air=AirSnr(-5.0),
        counts=FrameCounts(476, 0, -4.2),
    )
    d = _roundtrip(emulated)
    assert list(d) == [
        "channel",
        "device",
        "frames",
        "sample_rate_hz",
        "center_freq_hz",
        "symbols_per_frame",
        "ppm",
        "multipath",
        "delay_s",
        "air_snr_db",
        "frames_sent",
        "frames_lost",
        "snr_db_measured",
    ]
    assert emulated.frames_lost == 0 and LinkReport("awgn").frames_lost is None
    real = LinkReport("ota", radios=_radios(), air=AirSnr(None, 3.0, "not set"))
    real.counts = FrameCounts(10, 2, None)  # no frame measured: None is a value here
    d = _roundtrip(real)
    assert d["air_snr_db"] is None and d["snr_db_measured"] is None
    assert list(d)[5:] == ["symbols_per_frame", "air_snr_db", "snr_db_assumed", "note"] + [
        "frames_sent",
        "frames_lost",
        "snr_db_measured",
    ]


def test_raytraced_per_view_maps_are_int_keyed_in_memory_strings_in_json():
    link = LinkReport(
        "raytraced",
        receiver=Receiver("perfect"),
        trace=Trace({3: -80.0, 7: -82.5}, -81.0, [5], 64, 3.5e9, {"paths": 4}, {"seed": 42}),
        motion=Motion(15.0, 175.0, {3: 2.0, 7: 0.5}, 1.25, "drones fly"),
        positions=Positions(
            [0.0, 0.0, 1.5], "scene", None, {"radius_m": 4.0}, {3: [1.0, 2.0, 3.0]}, {3: 4.5}
        ),
        channel_params={"channel": "raytraced"},
    )
    d = _roundtrip(link)
    assert list(d["path_gain_db"]) == ["3", "7"] and list(d["rms_doppler_spread_hz"]) == ["3", "7"]
    assert d["drone_positions_m"] == {"3": [1.0, 2.0, 3.0]} and d["ground_station_warning"] is None
    assert list(d)[:3] == ["channel", "csi", "equalizer"] and list(d)[-1] == "channel_params"
    assert list(d).index("ray_solver") < list(d).index("drone_speed_m_s")


def test_over_the_air_on_traced_air_keeps_the_view_maps_as_ints():
    air = TracedAir("tiny", "radio/scene.xml", 3.5e9, 5.0, 58.0, None, -80.0, [], {0: {}}, {}, "n")
    link = LinkReport("ota", radios=_radios(ppm=[0.0, 20.0], delay_s=5e-6), traced_air=air)
    link.air = AirSnr(0.0)
    d = _roundtrip(link)
    assert list(d)[6:10] == ["ppm", "delay_s", "ota_air", "scene"]
    assert list(d)[-1] == "air_snr_db" and d["air_views"] == {"0": {}}


def test_a_field_no_section_has_is_named():
    with pytest.raises(ValueError, match="unknown field.*colour"):
        LinkReport.from_dict({"channel": "awgn", "csi": "perfect", "colour": "red"})


@pytest.mark.parametrize("name", ["pipeline_demo", "pipeline_tiny_ota_0dB_seed2"])
def test_tracked_reports_read_and_written_are_the_same_text(name):
    d = json.loads((RESULTS / name / "report.json").read_text())["link"]
    assert json.dumps(LinkReport.from_dict(d).to_dict()) == json.dumps(d)

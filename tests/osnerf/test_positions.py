"""Where the radio ends are as a run setting and a sweep axis: ``--ground-station`` moves the
ground station (the views stay), ``--ring-scale`` the drones' ring (views and channels
together); a sweep over channel, speed and position expands and runs, and each run's
report and sweep point say where the ends were."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from osnerf.cli import main
from osnerf.commands.run import run_config
from osnerf.run import RunConfig
from osnerf.run.links import build_links
from osnerf.scenes import RenderConfig
from osnerf.sweeps import read_results
from osnerf.sweeps.spec import command_parser, expand, spec_from_dict

FAR = [-6.0, 1.0, 1.5]  # the tiny plot's station is at (5, 3, 1.5)
C = 299_792_458.0


def _configs(spec: dict) -> list[RunConfig]:
    parser = command_parser("run")
    return [run_config(parser.parse_args([*p.argv, "--out", "x"])) for p in expand(spec)]


def test_a_sweep_over_position_expands_to_distinct_configs():
    spec = spec_from_dict(
        {
            "command": "run",
            "fixed": {"scene": "tiny", "channel": "raytraced"},
            "axes": {"ground_station": ["scene", FAR, "5,3,1.5"], "ring_scale": [1.25, 2]},
        }
    )
    cfgs = _configs(spec)
    assert len(cfgs) == 6 and len({c.key() for c in cfgs}) == 6
    assert [c.ground_station_m for c in cfgs[::2]] == [None, tuple(FAR), (5.0, 3.0, 1.5)]
    assert [c.ring_scale for c in cfgs[:2]] == [1.25, 2.0]
    assert [c.render_config().radius_scale for c in cfgs[:2]] == [1.25, 2.0]


def test_channel_speed_and_position_sweep_leaves_out_what_only_moving_drones_have(tmp_path, capsys):
    axes = {
        "channel": ["awgn", "rayleigh", "tdla30-10", "raytraced"],
        "drone_speed": [0, 15],
        "ground_station": ["scene", FAR],
    }
    others = ["awgn", "rayleigh", "tdla30-10"]
    d = {"command": "run", "fixed": {"scene": "tiny", "snr_db": 5}, "axes": axes}
    with pytest.raises(ValueError, match=r"refused by `osnerf run`: --ground-station .*'exclude'"):
        expand(spec_from_dict(d))  # awgn with a ground station: refused before any point
    path, out = tmp_path / "s.yaml", tmp_path / "r.jsonl"
    path.write_text(yaml.safe_dump(d))
    assert main(["sweep", str(path), "--out", str(out), "--no-progress"]) == 2
    assert "'exclude' entry" in capsys.readouterr().err and not out.exists()
    d["exclude"] = [
        {"channel": others, "drone_speed": 15},
        {"channel": others, "ground_station": ",".join(map(str, FAR))},
    ]
    cfgs = _configs(spec_from_dict(d))
    assert [c.channel for c in cfgs] == [*others, *["raytraced"] * 4]
    moved = {(c.drone_speed_m_s, c.ground_station_m) for c in cfgs if c.channel == "raytraced"}
    assert moved == {(v, g) for v in (0.0, 15.0) for g in (None, tuple(FAR))}
    with pytest.raises(ValueError, match="matches no point"):
        unused = {"channel": "awgn", "drone_speed": 30}  # a typo would silently keep points
        expand(spec_from_dict({**d, "exclude": [*d["exclude"], unused]}))
    with pytest.raises(ValueError, match="'seed', which is not an axis"):
        spec_from_dict({**d, "exclude": [{"seed": 0}]})


@pytest.mark.raytracing
def test_two_ground_stations_give_different_channels_and_the_link_says_where(tiny_views):
    idx = tiny_views.indices("train")
    pos = tiny_views.drone_positions_m[idx]
    own = build_links(RunConfig(scene="tiny", channel="raytraced"), tiny_views, idx)
    cfg = RunConfig(scene="tiny", channel="raytraced", ground_station_m=tuple(FAR))
    far = build_links(cfg, tiny_views, idx)
    for links, gs, source in ((own, [5.0, 3.0, 1.5], "scene"), (far, FAR, "--ground-station")):
        info = links.report.to_dict()
        assert info["ground_station_m"] == gs and info["ground_station_from"] == source
        dist = np.linalg.norm(pos - np.asarray(gs), axis=1)
        np.testing.assert_allclose(list(info["distance_to_ground_station_m"].values()), dist)
        at = links.report.positions
        assert at is not None
        assert at.drone_positions_m == {int(i): list(p) for i, p in zip(idx, pos)}
        assert info["drone_ring"]["radius_m"] == pytest.approx(
            tiny_views.meta["trajectory_radius_m"]
        )
        params = info["channel_params"]
        assert params["ground_station_m"] == gs and params["median_distance_m"] == np.median(dist)
    # the same drones, pictures untouched, the station moved: the tiny plot's drones see it
    # in line of sight (most also by the ground's reflection), so each view's direct path, the
    # strongest (power G K / (1 + K) of the traced paths), has Friis's gain at its new distance
    lam = C / float(tiny_views.meta["carrier_frequency_hz"])
    for links in (own, far):
        st = links.report.to_dict()["stats"]
        k = 10 ** (np.array(st["k_factor_db"]) / 10)
        assert all(st["los"]) and max(st["num_paths"]) >= 2
        direct_db = np.array(st["path_gain_db"]) - 10 * np.log10(1 + 1 / k)
        dist = np.array(list(links.report.to_dict()["distance_to_ground_station_m"].values()))
        np.testing.assert_allclose(direct_db, 20 * np.log10(lam / (4 * np.pi * dist)), atol=0.05)
    gains = [np.array(list(x.report.to_dict()["path_gain_db"].values())) for x in (own, far)]
    assert np.abs(gains[0] - gains[1]).min() > 0.5  # every view's link moved
    for links, gain in zip((own, far), gains):  # each view's SNR follows its own gain
        snr = np.array([links.snr_db[int(i)] for i in idx])
        np.testing.assert_allclose(snr, gain - np.median(gain), atol=1e-4)


@pytest.mark.raytracing
def test_a_sweep_over_position_and_speed_runs_and_each_point_says_where(tmp_path):
    spec = tmp_path / "positions.yaml"
    fixed = {
        "scene": "tiny",
        "channel": "raytraced",
        "snr_db": 10,
        "schemes": "digital",
        "resolution": 16,
        "views": 2,
        "test_views": 1,
        "nerf_steps": 2,
        "renderer_steps": 0,
        "cache_dir": str(tmp_path / "cache"),
    }
    axes = {"ground_station": ["scene", FAR], "drone_speed": [0, 15]}
    spec.write_text(yaml.safe_dump({"command": "run", "fixed": fixed, "axes": axes}))
    out = tmp_path / "points.jsonl"
    keep = tmp_path / "runs"
    argv = ["sweep", str(spec), "--out", str(out), "--executor", "serial", "--no-progress"]
    assert main([*argv, "--keep-outputs", str(keep)]) == 0
    rows = read_results(out)
    assert len(rows) == 4
    for r in rows:
        ch = r["channel"]
        want = [5.0, 3.0, 1.5] if r["point"]["ground_station"] == "scene" else FAR
        assert ch["ground_station_m"] == want
        assert ch["drone_speed_m_s"] == float(r["point"]["drone_speed"])
        report = json.loads((Path(r["output"]) / "report.json").read_text())
        assert report["link"]["ground_station_m"] == want
        assert report["scene"]["ground_station_m"] == want
        assert len(report["link"]["drone_positions_m"]) == 2
        page = (Path(r["output"]) / "report.html").read_text()
        where = ", ".join(f"{v:g}" for v in want)
        assert f"ground station at ({where}) m" in page


@pytest.mark.parametrize(
    "flag, value, allowed",
    [
        ("--ground-station", "1,2", "X,Y,Z metres, each in [-10000, 10000]"),
        ("--ground-station", "nan,0,1", "X,Y,Z metres, each in [-10000, 10000]"),
        ("--ground-station", "20000,0,1", "X,Y,Z metres, each in [-10000, 10000]"),
        ("--ground-station", "here", "X,Y,Z metres, each in [-10000, 10000]"),
        ("--ring-scale", "0.5", "[1, 10]"),
        ("--ring-scale", "11", "[1, 10]"),
    ],
)
def test_bad_positions_are_one_line_naming_the_flag_and_range(
    tmp_path, capsys, flag, value, allowed
):
    out = tmp_path / "run"
    assert main(["run", "--channel", "raytraced", f"{flag}={value}", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and flag in err and allowed in err
    assert not out.exists()


def test_a_ground_station_on_a_channel_without_one_is_refused(tmp_path, capsys):
    out = tmp_path / "run"
    argv = ["run", "--channel", "tdl", "--ground-station=1,2,3", "--out", str(out)]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--ground-station" in err and "raytraced" in err
    assert not out.exists()
    with pytest.raises(ValueError, match=r"ground_station_m must be \(x, y, z\) metres"):
        RunConfig(channel="raytraced", ground_station_m=(0.0, 0.0))
    with pytest.raises(ValueError, match=r"ring_scale must be a number in \[1, 10\]"):
        RunConfig(ring_scale=0.9)
    with pytest.raises(ValueError, match=r"radius_scale must be a number in \[1, 10\]"):
        RenderConfig(radius_scale=10.5)
    assert RunConfig().render_config().radius_scale == RenderConfig().radius_scale
    same = RunConfig(channel="raytraced", ground_station_m=(8, -6, 1.5))
    assert same.ground_station_m == (8.0, -6.0, 1.5)
    assert same.key() == RunConfig(channel="raytraced", ground_station_m=(8.0, -6.0, 1.5)).key()


@pytest.mark.raytracing
def test_radiomap_draws_the_map_of_a_moved_ground_station(tmp_path, tiny_views):
    out = tmp_path / "map"
    argv = ["radiomap", "--scene", "tiny", "--views", "4", "--samples", "100000"]
    argv += ["--cell-size-m", "0.5", f"--ground-station={','.join(map(str, FAR))}"]
    assert main([*argv, "--out", str(out)]) == 0
    doc = json.loads((out / "radiomap.json").read_text())
    assert doc["ground_station_m"] == FAR and doc["config"]["ground_station"] == FAR
    # the candidates are the run's drones; their traced gains are the run's links' gains
    idx = tiny_views.indices("train")
    cand = np.array([c["position_m"] for c in doc["candidates"]])
    np.testing.assert_allclose(cand, tiny_views.drone_positions_m[idx], atol=1e-6)
    cfg = RunConfig(scene="tiny", channel="raytraced", ground_station_m=tuple(FAR))
    run_gain = list(build_links(cfg, tiny_views, idx).report.to_dict()["path_gain_db"].values())
    traced = [c["traced_path_gain_db"] for c in doc["candidates"]]
    np.testing.assert_allclose(traced, run_gain, atol=0.01)


@pytest.mark.parametrize(
    "extra, message",
    [
        (["--ground-station", "1,2"], "argument --ground-station: must be X,Y,Z metres"),
        (["--ring-scale", "0.5"], "argument --ring-scale: must be a number in [1, 10]"),
    ],
)
def test_bad_radiomap_positions_are_one_line_errors(tmp_path, capsys, extra, message):
    out = tmp_path / "map"
    assert main(["radiomap", "--scene", "tiny", "--out", str(out), *extra]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and message in err, err
    assert not out.exists()

"""``osnerf radiomap`` and the shadowed scene: the map agrees with the path solver at the
candidate positions, the shed shadows the -y drones, and bad flags are one-line errors."""

from __future__ import annotations

import json

import numpy as np
import pytest

from osnerf.cli import main


@pytest.mark.raytracing
def test_radiomap_writes_picture_numbers_and_provenance(tmp_path, capsys):
    out = tmp_path / "map"
    argv = ["radiomap", "--scene", "tiny", "--out", str(out), "--views", "4"]
    argv += ["--samples", "1000000", "--cell-size-m", "0.3", "--seed", "3"]
    assert main(argv) == 0
    assert sorted(p.name for p in out.iterdir()) == [
        "radiomap.json",
        "radiomap.npz",
        "radiomap.png",
    ]
    assert (out / "radiomap.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    doc = json.loads((out / "radiomap.json").read_text())
    assert doc["seed"] == 3 and doc["config"]["samples_per_tx"] == 1_000_000
    assert doc["config"]["cell_size_m"] == 0.3 and "sionna" in doc["versions"] and doc["git_commit"]
    assert doc["ground_station_m"] == [5.0, 3.0, 1.5] and "reciprocity" in doc["transmitter"]
    with np.load(out / "radiomap.npz") as z:
        pg, x, y, alt = z["path_gain_db"], z["x_m"], z["y_m"], z["altitudes_m"]
        cand, traced, on_map = z["candidates_m"], z["traced_path_gain_db"], z["map_path_gain_db"]
    assert pg.shape == (len(alt), len(y), len(x)) and len(alt) == 2  # two ring elevations
    assert np.allclose(np.diff(x), 0.3, atol=1e-4) and np.allclose(np.diff(y), 0.3, atol=1e-4)
    assert cand.shape == (4, 3) and len(doc["candidates"]) == 4
    assert np.isfinite(traced).all() and np.isfinite(on_map).all()
    # two solvers, one physics: the map's cell at each candidate within 3 dB of its paths
    assert np.max(np.abs(on_map - traced)) < 3.0, (on_map, traced)
    # the offsets --channel raytraced applies: traced gain minus the median
    offs = [c["raytraced_snr_offset_db"] for c in doc["candidates"]]
    assert np.allclose(offs, traced - np.median(traced))
    assert "radio map" in capsys.readouterr().err


def _crosses(p, q, lo, hi) -> bool:
    """Whether the segment p -> q (xy) passes through the box [lo, hi] (slab method)."""
    t0, t1 = 0.0, 1.0
    for k in range(2):
        d = q[k] - p[k]
        if abs(d) < 1e-12:
            if not lo[k] <= p[k] <= hi[k]:
                return False
            continue
        a, b = sorted(((lo[k] - p[k]) / d, (hi[k] - p[k]) / d))
        t0, t1 = max(t0, a), min(t1, b)
    return t0 <= t1


@pytest.mark.raytracing
def test_the_shed_shadows_the_drones_whose_line_to_the_station_crosses_it():
    """The same drone ring on firefighter and firefighter_shadow: the drones whose straight
    line to the ground station crosses the shed (3 m tall, above every drone and the
    station) have no line of sight and lose more than 10 dB; the others keep their line of
    sight (or its absence behind the building) and their gain within 3 dB (the shed may block
    their ground reflection, or add one off its wall, each well below the direct path)."""
    from osnerf.scenes.compact import SHED_CENTER_M, SHED_SIZE_M
    from osnerf.scenes.radiomap import scene_radio_map
    from phy.raytrace import RadioMapConfig

    cfg = RadioMapConfig(samples_per_tx=1000)
    open_, shadow = (
        scene_radio_map(s, None, None, cfg, 2.0) for s in ("firefighter", "firefighter_shadow")
    )
    np.testing.assert_allclose(open_.candidates_m, shadow.candidates_m)
    c, half = np.asarray(SHED_CENTER_M[:2]), np.asarray(SHED_SIZE_M[:2]) / 2
    gs = shadow.map.tx_position_m
    behind = np.array([_crosses(p, gs, c - half, c + half) for p in shadow.candidates_m])
    assert 4 <= behind.sum() <= 12, behind
    drop = open_.traced_path_gain_db - shadow.traced_path_gain_db
    clear = ~behind & np.isfinite(open_.traced_path_gain_db)
    assert (drop[behind] > 10.0).all(), drop
    assert not shadow.los[behind].any()
    assert (shadow.los[clear] == open_.los[clear]).all() and (np.abs(drop[clear]) < 3.0).all()


@pytest.mark.parametrize(
    "extra, message",
    [
        (["--scene", "nope"], "--scene: unknown scene 'nope'"),
        (["--demand", "unicorn"], "--demand: unknown object 'unicorn'"),
        (["--samples", "10"], "argument --samples: must be an integer in [1000, 1000000000]"),
        (["--cell-size-m", "0"], "argument --cell-size-m"),
        (["--max-depth", "11"], "argument --max-depth"),
        (["--views", "1"], "argument --views"),
    ],
)
def test_bad_radiomap_flags_are_one_line_errors_that_create_nothing(
    tmp_path, capsys, extra, message
):
    out = tmp_path / "map"
    assert main(["radiomap", "--scene", "tiny", "--out", str(out), *extra]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and message in err, err
    assert not out.exists()


def test_radiomap_refuses_an_out_that_is_a_file_or_holds_files(tmp_path, capsys):
    f = tmp_path / "f"
    f.write_text("x")
    assert main(["radiomap", "--scene", "tiny", "--out", str(f)]) == 2
    assert "is a file; give a folder path" in capsys.readouterr().err
    (tmp_path / "d").mkdir()
    (tmp_path / "d" / "keep").write_text("x")
    assert main(["radiomap", "--scene", "tiny", "--out", str(tmp_path / "d")]) == 2
    assert "give --overwrite" in capsys.readouterr().err
    assert sorted(p.name for p in (tmp_path / "d").iterdir()) == ["keep"]

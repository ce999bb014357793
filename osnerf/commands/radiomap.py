"""`osnerf radiomap`: sionna-rt's radio map of a scene, with the candidate drone positions.

    osnerf radiomap --scene NAME --out DIR [--demand OBJECT[,...]] [--views N]
                    [--samples N] [--cell-size-m M] [--max-depth D] [--seed S]
                    [--ground-station X,Y,Z] [--ring-scale S]

The ground station transmits and the map is measured on horizontal planes at the drone
rings' altitudes: by reciprocity a cell's path gain is that of a drone transmitting from it
to the ground station. Each candidate drone position is also traced with the path solver of
``--channel raytraced``. Writes DIR/radiomap.png (the map over the scene's floor plan, the
candidates marked), DIR/radiomap.npz (the map's numbers) and DIR/radiomap.json (config,
seed, commit, versions and each candidate's gains).
"""

from __future__ import annotations

import argparse
import io
import sys
from pathlib import Path

import numpy as np

import phy.raytrace as prt
from common import InputError, to_json, write_files
from osnerf.cli import inputs_checked
from osnerf.collect import Demand
from osnerf.commands import args as checks
from osnerf.provenance import result_header
from osnerf.scenes import DEFAULT_SCENE, RADIUS_SCALE_RANGE, RenderConfig, check_demand, get_scene
from osnerf.scenes.radiomap import plot_radio_map, scene_radio_map


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--scene", default=None, help="built-in scene (default: the default scene)")
    p.add_argument(
        "--demand",
        default=None,
        help="OBJECT[,OBJECT...] the drone rings circle, as in osnerf run (default: the "
        "scene's default demand)",
    )
    p.add_argument(
        "--views",
        type=checks.count(2, 512),
        default=24,
        help="candidate drone positions (osnerf run --views) (default: 24)",
    )
    p.add_argument(
        "--samples",
        type=samples_count,
        default=10_000_000,
        help="rays shot from the ground station, an integer in [1e3, 1e9] such as 1e4 or "
        "10000 (default: 1e7)",
    )
    p.add_argument(
        "--cell-size-m",
        type=checks.number(0.0, 1e4, "m", low_open=True),
        default=None,
        help="side of a map cell in metres (default: the map's larger side / 60)",
    )
    p.add_argument(
        "--max-depth",
        type=checks.count(0, 10),
        default=2,
        help="most interactions per path, in [0, 10] (default: 2, as --channel raytraced)",
    )
    p.add_argument(
        "--ground-station",
        type=checks.ground_station,
        default=None,
        metavar="X,Y,Z",
        help="the ground station at X,Y,Z metres in the scene's frame (osnerf run "
        "--ground-station), or 'scene' (default: the scene's own)",
    )
    p.add_argument(
        "--ring-scale",
        type=checks.number(*RADIUS_SCALE_RANGE),
        default=RenderConfig.radius_scale,
        help="the drones' ring radius over the radius that just fits the demanded objects in "
        "view, in [{:g}, {:g}] (osnerf run --ring-scale) (default: {:g})".format(
            *RADIUS_SCALE_RANGE, RenderConfig.radius_scale
        ),
    )
    p.add_argument("--seed", type=checks.seed, default=42, help="ray sampler seed (default: 42)")
    p.add_argument("--out", required=True, help="DIR for radiomap.png, .npz and .json")
    checks.add_overwrite(p, "radiomap files in a --out folder that holds files")


def _target(scene: str, text: str | None) -> tuple[str, ...] | None:
    if text is None:
        return None
    try:
        objects = Demand.parse(text).objects
    except ValueError as e:
        raise checks.UsageError(f"--demand: {e}") from None
    try:
        return check_demand(scene, objects)
    except KeyError as e:
        raise checks.UsageError(f"--demand: {e.args[0]}") from None


def _finite_or_none(a: np.ndarray) -> list:
    return [float(x) if np.isfinite(x) else None for x in np.asarray(a, np.float64)]


def _result(rm, args: argparse.Namespace) -> dict:
    """radiomap.json: provenance, the map's settings and each candidate's gains."""
    m = rm.map
    config = {
        "scene": rm.scene,
        "target": list(rm.target),
        "views": args.views,
        "samples_per_tx": args.samples,
        "cell_size_m": m.cell_size_m,
        "max_depth": args.max_depth,
        "seed": args.seed,
        "ground_station": None if args.ground_station is None else list(args.ground_station),
        "ring_scale": args.ring_scale,
    }
    relative = rm.relative_snr_db
    body = {
        **result_header(config, args.seed),
        "transmitter": "ground station: by reciprocity a cell's path gain is that of a drone "
        "transmitting from it to the ground station",
        "ground_station_m": m.tx_position_m.tolist(),
        "carrier_frequency_hz": rm.carrier_frequency_hz,
        "altitudes_m": m.altitudes_m.tolist(),
        "map_shape": list(m.path_gain_db.shape),
        "cells_without_rays": float(np.mean(~np.isfinite(m.path_gain_db))),
        "candidates": [
            {
                "view": k,
                "position_m": rm.candidates_m[k].tolist(),
                "map_path_gain_db": _finite_or_none(rm.map_path_gain_db[k : k + 1])[0],
                "traced_path_gain_db": _finite_or_none(rm.traced_path_gain_db[k : k + 1])[0],
                "los": bool(rm.los[k]),
                "raytraced_snr_offset_db": _finite_or_none(relative[k : k + 1])[0],
            }
            for k in range(len(rm.candidates_m))
        ],
        "notes": "raytraced_snr_offset_db: what --channel raytraced adds to --snr-db at the "
        "candidate (traced gain minus the median over candidates not in outage); "
        "map_path_gain_db: the map's cell holding the candidate on the plane at its altitude",
    }
    return body


def samples_count(text: str) -> int:
    """``--samples``: a whole number in [1e3, 1e9], written as help writes it (``1e4``) or
    in digits."""
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not (1e3 <= value <= 1e9 and value == int(value)):
        raise argparse.ArgumentTypeError(
            f"must be an integer in [1000, 1000000000] (1e3 to 1e9, such as 1e4 or 10000), "
            f"got {text!r}"
        )
    return int(value)


def run(args: argparse.Namespace) -> int:
    scene = args.scene or DEFAULT_SCENE
    try:
        get_scene(scene)
    except KeyError as e:
        raise checks.UsageError(f"--scene: {e.args[0]}") from None
    target = _target(scene, args.demand)
    out = checks.output_dir(args.out, "--out", overwrite=args.overwrite)
    map_config = prt.RadioMapConfig(
        samples_per_tx=args.samples, max_depth=args.max_depth, seed=args.seed
    )
    render = RenderConfig(num_train_views=args.views, radius_scale=args.ring_scale)
    inputs_checked()
    try:
        rm = scene_radio_map(
            scene, target, render, map_config, args.cell_size_m, args.ground_station
        )
    except InputError as e:  # the cell size, known once the map's extent is
        raise checks.flag_error(e, {"cell_size_m": "--cell-size-m"}) from None
    m = rm.map
    body = _result(rm, args)
    npz = io.BytesIO()
    np.savez(
        npz,
        path_gain_db=m.path_gain_db,
        x_m=m.x_m,
        y_m=m.y_m,
        altitudes_m=m.altitudes_m,
        ground_station_m=m.tx_position_m,
        candidates_m=rm.candidates_m,
        map_path_gain_db=rm.map_path_gain_db,
        traced_path_gain_db=rm.traced_path_gain_db,
    )
    png = io.BytesIO()
    plot_radio_map(rm).savefig(png, format="png", dpi=110, bbox_inches="tight")
    out = Path(out)
    write_files(
        {
            out / "radiomap.png": png.getvalue(),
            out / "radiomap.npz": npz.getvalue(),
            out / "radiomap.json": (to_json(body) + "\n").encode(),
        }
    )
    shadowed = [c["view"] for c in body["candidates"] if not c["los"]]
    print(
        f"radio map {m.path_gain_db.shape} at z = "
        f"{', '.join(f'{z:.2f}' for z in m.altitudes_m)} m; "
        f"{len(shadowed)} of {len(rm.candidates_m)} candidates without line of sight "
        f"{shadowed}; wrote {out}/radiomap.png, .npz, .json",
        file=sys.stderr,
    )
    return 0

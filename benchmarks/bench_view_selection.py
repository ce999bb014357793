"""Views chosen by sight against views chosen by sight and radio, at an equal number of views.

On ``firefighter_shadow`` (a shed blocks the radio paths of the drones on the hydrant's -y
side; their cameras still see it) with ``--channel raytraced`` (the SNR is set at the
median drone position, so a shadowed drone receives less), ``osnerf run`` sends
``MAX_VIEWS`` on-demand views chosen by ``--view-selection sight`` (greedy coverage of the
viewing directions) and by ``joint`` (coverage gain times link quality), for each seed,
at two SNRs (at the median position).
Records each scheme's object PSNR, the views each selection chose with their expected SNR,
and draws the scene's radio map with both selections marked (``radiomap.png``).
Small settings (48 px, 500 NeRF steps, no learned renderer): minutes per run.

    /work/res/heavy python -m benchmarks view_selection --out bench-results
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from common import write_figure
from osnerf.cli import main
from osnerf.scenes import RenderConfig
from osnerf.scenes.radiomap import plot_radio_map, scene_radio_map

SCENE = "firefighter_shadow"
SNRS_DB = (10.0, 0.0)
MAX_VIEWS = 6
SEEDS = (0, 1, 2)
SELECTIONS = ("sight", "joint")
SCHEMES = "jscc,digital,gt"
SMALL = ["--resolution", "48", "--nerf-steps", "500", "--renderer-steps", "0"]


def _argv(selection: str, seed: int, snr_db: float) -> list[str]:
    return [
        "run",
        "--scene",
        SCENE,
        "--channel",
        "raytraced",
        "--snr-db",
        str(snr_db),
        "--schemes",
        SCHEMES,
        "--seed",
        str(seed),
        "--view-selection",
        selection,
        "--max-views",
        str(MAX_VIEWS),
        *SMALL,
    ]


def _one(run_dir: Path, selection: str, seed: int, snr_db: float) -> dict:
    argv = _argv(selection, seed, snr_db)
    t = time.perf_counter()
    if main([*argv, "--out", str(run_dir), "--overwrite"]) != 0:
        raise RuntimeError(f"osnerf {' '.join(argv)} failed")
    doc = json.loads((run_dir / "report.json").read_text())
    chosen = [d for d in doc["scu_decisions"] if d["stage"] == "selection" and "rank" in d]
    snr = doc["views"]["link_snr_db"]
    sent = doc["views"]["sent_on_demand"]
    return {
        "selection": selection,
        "seed": seed,
        "snr_db_at_median_position": snr_db,
        "command": "osnerf " + " ".join(argv),
        "wall_seconds": time.perf_counter() - t,
        "views": sent,
        "chosen": [
            {k: c[k] for k in ("view", "rank", "expected_snr_db", "coverage_gain", "score")}
            for c in chosen
        ],
        "mean_expected_snr_db": float(np.mean([snr[str(v)] for v in sent])),
        "psnr_object": {n: s["psnr_object"] for n, s in doc["schemes"].items()},
        "views_lost": {n: s.get("views_lost") for n, s in doc["schemes"].items()},
    }


def _picture(out: Path, rows: list[dict]) -> str:
    rm = scene_radio_map(SCENE, None, RenderConfig())
    marked = {s: next(r["views"] for r in rows if r["selection"] == s) for s in SELECTIONS}
    fig = plot_radio_map(rm, {f"{s} ({MAX_VIEWS} views)": v for s, v in marked.items()})
    return str(write_figure(out / "radiomap.png", fig, dpi=110, bbox_inches="tight"))


def _summary(rows: list[dict]) -> dict:
    """Per selection and scheme: mean and std of object PSNR over seeds; joint minus sight."""
    by = {sel: [r for r in rows if r["selection"] == sel] for sel in SELECTIONS}
    schemes = list(rows[0]["psnr_object"])
    return {
        "psnr_object_mean_std": {
            sel: {
                n: {
                    "mean": float(np.mean([r["psnr_object"][n] for r in mine])),
                    "std": float(np.std([r["psnr_object"][n] for r in mine])),
                }
                for n in schemes
            }
            for sel, mine in by.items()
        },
        "joint_minus_sight_psnr_object_db": {
            n: float(
                np.mean(
                    [
                        a["psnr_object"][n] - b["psnr_object"][n]
                        for a, b in zip(by["joint"], by["sight"])
                    ]
                )
            )
            for n in schemes
        },
    }


def run(out_dir: Path) -> dict:
    out = Path(out_dir) / "view_selection"
    rows = [
        _one(out / f"{sel}_{snr:g}dB_seed{seed}", sel, seed, snr)
        for snr in SNRS_DB
        for seed in SEEDS
        for sel in SELECTIONS
    ]
    return {
        "scene": SCENE,
        "snrs_db_at_median_position": list(SNRS_DB),
        "max_views": MAX_VIEWS,
        "seeds": list(SEEDS),
        "runs": rows,
        "by_snr_db": {
            f"{snr:g}": _summary([r for r in rows if r["snr_db_at_median_position"] == snr])
            for snr in SNRS_DB
        },
        "picture": _picture(out, [r for r in rows if r["snr_db_at_median_position"] == SNRS_DB[0]]),
        "notes": "psnr_object: mean over held-out views; gt sends undistorted views (bound): "
        "its difference is the views' geometry alone; jscc/digital add the links; a rerun "
        "resumes each run from its cached stages",
    }

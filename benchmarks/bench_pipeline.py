"""The end-to-end pipeline on its default (what `make demo` runs): per-stage time and quality.

Runs `osnerf run` on the default scene and demand, Rayleigh block fading at 0 dB, all four
schemes, and records per scheme the object PSNR, symbols, and seconds per stage (encode,
air at 1 MS/s, decode, NeRF), the headline comparisons (jscc vs the gt ceiling and vs
digital, symbols jscc / full, processing time jscc / full), the total wall time (the
demo's budget is 10 minutes on 2 cores) and the machine load (timings on a shared machine
are pessimistic).

Then over the air: `osnerf run --scene tiny --channel ota --snr-db S` (emulated HackRFs at
their defaults) at S = 0, -5 and -10 dB for seeds 0-2 with jscc, digital and gt: each seed's
jscc - gt in object PSNR against the goal of at most 3 dB under gt (at 0 dB), and jscc -
digital against the goal of jscc at least digital's on every seed (every field takes the
same NeRF steps, so a seed's numbers repeat). Each run's folder is
``pipeline_tiny_ota_<S>dB_seed<N>``; a report already there from the same clean commit and
config is reused, anything else is run again (``--overwrite``).

Then the demo again where the link is not known exactly and where digital is framed like jscc:
seeds 0-2 with each view's SNR estimate off by a 2 dB Gaussian error (``--snr-error-db 2``),
with exact knowledge, and with digital sending the demanded objects' box
(``--digital-box true``); and the tiny scene over the air with the box. Folders
``pipeline_demo_<variant>_seed<N>`` and ``pipeline_tiny_ota_box_<S>dB_seed<N>`` (seed 0 of the
exact demo is ``pipeline_demo``). ``OSNERF_BENCH_PIPELINE_PARTS``: a comma-separated subset of
``demo,ota,variants,ota_box`` (default all); ``OSNERF_BENCH_PIPELINE_REUSE=any``: reuse a report
with the same arguments whatever commit made it (each keeps its own ``git_commit``).
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

from common import write_text
from osnerf.cli import main
from osnerf.provenance import git_commit
from osnerf.report import Report

OTA_SEEDS = (0, 1, 2)
OTA_SNRS_DB = (0, -5, -10)
OTA_GOAL_DB = 3.0
OTA_GOAL_SNR_DB = 0
DEMO_ARGV = ["run", "--channel", "rayleigh", "--snr-db", "0"]
VARIANTS = {"exact": [], "err2": ["--snr-error-db", "2"], "box": ["--digital-box", "true"]}
"""The demo's variants: the flags each adds to the demo's command."""
PARTS = ("demo", "ota", "variants", "ota_box")


def _reusable(run_dir: Path, argv: list[str]) -> bool:
    """A report in ``run_dir`` that this clean commit made with these arguments."""
    path = run_dir / "report.json"
    if not path.is_file():
        return False
    doc = json.loads(path.read_text())
    commit = git_commit()
    clean = commit != "unknown" and not commit.endswith("-dirty")
    same = clean and doc.get("git_commit") == commit
    same = same or os.environ.get("OSNERF_BENCH_PIPELINE_REUSE") == "any"
    return same and doc.get("argv") == argv


def _run(run_dir: Path, argv: list[str]) -> float:
    """``osnerf run`` into ``run_dir`` (reused when :func:`_reusable`); wall seconds."""
    if _reusable(run_dir, argv):
        return 0.0
    t = time.perf_counter()
    if main([*argv, "--out", str(run_dir), "--overwrite"]) != 0:
        raise RuntimeError(f"osnerf {' '.join(argv)} failed")
    path = run_dir / "report.json"
    doc = json.loads(path.read_text())
    doc["argv"] = argv
    write_text(path, json.dumps(doc, indent=1))
    return time.perf_counter() - t


def _over_the_air(out_dir: Path, box: bool = False) -> dict:
    """The tiny scene over the air (with digital sending the box when ``box``)."""
    rows = []
    for snr, seed in ((s, n) for s in OTA_SNRS_DB for n in OTA_SEEDS):
        tag = "ota_box" if box else "ota"
        run_dir = Path(out_dir) / f"pipeline_tiny_{tag}_{snr}dB_seed{seed}"
        args = ["run", "--scene", "tiny", "--channel", "ota", "--snr-db", str(snr)]
        args += ["--schemes", "jscc,digital,gt", "--renderer-steps", "0", "--seed", str(seed)]
        args += VARIANTS["box"] if box else []
        wall = _run(run_dir, args)
        report = Report.from_dict(json.loads((run_dir / "report.json").read_text()))
        sch = report.schemes
        gap = sch["jscc"].psnr_object - sch["gt"].psnr_object
        # None when no digital view arrived: a field that saw nothing is no comparison
        compared = report.comparisons.get("jscc_minus_digital_psnr_object_db", 0.0) is not None
        over_digital = sch["jscc"].psnr_object - sch["digital"].psnr_object if compared else None
        rows.append(
            {
                "snr_db": snr,
                "seed": seed,
                "wall_seconds": wall,
                "psnr_object": {n: r.psnr_object for n, r in sch.items()},
                "psnr_received_object": {n: r.psnr_received_object for n, r in sch.items()},
                "jscc_minus_gt_db": gap,
                "jscc_minus_digital_db": over_digital,
                "frames_lost": report.link.frames_lost,
                "object_oversampling": report.views.object_oversampling,
                "repetitions_on_demand": sorted(set(report.views.repetitions_on_demand.values())),
                "met": gap >= -OTA_GOAL_DB if snr == OTA_GOAL_SNR_DB else None,
                "jscc_at_least_digital": None if over_digital is None else over_digital >= 0,
            }
        )
    return {
        "command": "osnerf run --scene tiny --channel ota --snr-db S --schemes jscc,digital,gt "
        "--renderer-steps 0 --seed N" + (" --digital-box true" if box else ""),
        "goal": f"jscc within {OTA_GOAL_DB:g} dB of gt (object PSNR) at {OTA_GOAL_SNR_DB} dB",
        "goal_over_digital": "jscc's object PSNR at least digital's on every seed",
        "rows": rows,
        "goal_met_every_seed": all(r["met"] for r in rows if r["met"] is not None),
        "jscc_at_least_digital_every_seed": all(r["jscc_at_least_digital"] for r in rows),
    }


def _variants(out_dir: Path) -> dict:
    """The demo at seeds 0-2 with exact knowledge, a 2 dB estimate error and digital's box."""
    rows = []
    for variant, flags in VARIANTS.items():
        for seed in OTA_SEEDS:
            name = "pipeline_demo" if (variant, seed) == ("exact", 0) else None
            run_dir = Path(out_dir) / (name or f"pipeline_demo_{variant}_seed{seed}")
            wall = _run(run_dir, [*DEMO_ARGV, "--seed", str(seed), *flags])
            report = Report.from_dict(json.loads((run_dir / "report.json").read_text()))
            rows.append(
                {
                    "variant": variant,
                    "seed": seed,
                    "wall_seconds": wall or None,
                    "psnr_object": {n: r.psnr_object for n, r in report.schemes.items()},
                    "jscc_minus_digital_db": report.comparisons.get(
                        "jscc_minus_digital_psnr_object_db"
                    ),
                }
            )
    return {
        "command": " ".join(["osnerf", *DEMO_ARGV, "--seed N"]) + " [flags]",
        "flags": {k: " ".join(v) for k, v in VARIANTS.items()},
        "rows": rows,
    }


def _demo(out_dir: Path) -> dict:
    """The default run (what `make demo` does), timed."""
    from dataclasses import asdict

    run_dir = Path(out_dir) / "pipeline_demo"
    load_before = os.getloadavg()
    wall = _run(run_dir, [*DEMO_ARGV, "--seed", "0"])
    report = Report.from_dict(json.loads((run_dir / "report.json").read_text()))
    return {
        "command": "osnerf run --channel rayleigh --snr-db 0 --seed 0 (default scene and demand)",
        "wall_seconds": wall or None,
        "demo_budget_seconds": 600,
        "within_budget": wall < 600 if wall else None,
        "loadavg_before": load_before,
        "loadavg_after": os.getloadavg(),
        "cpu_count": os.cpu_count(),
        "scene_seconds": report.scene_seconds,
        "schemes": {
            name: {k: s.get(k) for k in SCHEME_KEYS}
            for name, s in ((n, asdict(r)) for n, r in report.schemes.items())
        },
        "comparisons": report.comparisons,
        "report": str(run_dir / "report.json"),
    }


SCHEME_KEYS = (
    "psnr",
    "psnr_object",
    "ssim",
    "lpips",
    "mask_iou",
    "views_lost",
    "bound",
    "symbols_sent",
    "views_sent",
    "seconds",
    "processing_seconds",
    "nerf_steps",
)


def run(out_dir: Path) -> dict:
    parts = os.environ.get("OSNERF_BENCH_PIPELINE_PARTS", ",".join(PARTS)).split(",")
    unknown = sorted(set(parts) - set(PARTS))
    if unknown:
        raise ValueError(f"OSNERF_BENCH_PIPELINE_PARTS: unknown {unknown}; known: {PARTS}")
    out: dict = _demo(out_dir) if "demo" in parts else {}
    if "ota" in parts:
        out["over_the_air_tiny"] = _over_the_air(out_dir)
    if "variants" in parts:
        out["demo_variants"] = _variants(out_dir)
    if "ota_box" in parts:
        out["over_the_air_tiny_box"] = _over_the_air(out_dir, box=True)
    out["note"] = "wall_seconds is null where a report was reused"
    return out

"""Moving drones end to end: jscc against digital on the ray-traced link at 0 and 15 m/s.

Runs ``osnerf run --channel raytraced --drone-speed V`` on the default scene at 5 dB (at the
median drone position) with jscc and digital, small settings (300 NeRF steps, no learned
renderer), one seed, with three receivers: perfect CSI of h at each symbol's time (the
default), and ``--csi ls`` / ``--csi lmmse``: the symbols on the run's OFDM grid with pilots
(``osnerf.run.links.RAYTRACED_GRID``), h estimated from them. Records per speed and
receiver each scheme's object PSNR, symbols sent and views lost, and the report's drone
speed, maximum Doppler, median and largest RMS Doppler spread over the views, how many
views have a spread (more than one traced path), the grid's pilot pattern, and the median
SNR the SCU measured through the links with its pilots (what it plans rates and copies on). Each
run's folder is ``moving_<V>ms`` (perfect CSI) or ``moving_<V>ms_<CSI>``; a report from the same
clean commit and arguments is reused.

    OMP_NUM_THREADS=1 /work/res/heavy python -m benchmarks moving --out bench-results
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from benchmarks.bench_pipeline import _run
from osnerf.report import Report

SPEEDS_M_S = (0, 15)
CSI = ("perfect", "ls", "lmmse")
SNR_DB = 5
SCHEMES = "jscc,digital"
SMALL = ["--nerf-steps", "300", "--renderer-steps", "0", "--seed", "0"]
LINK_KEYS = (
    "carrier_frequency_hz",
    "drone_speed_m_s",
    "max_doppler_hz",
    "median_rms_doppler_spread_hz",
)
SPREAD_FLOOR_HZ = 0.1  # a view's RMS Doppler spread below this is one path's rounding


def _argv(speed: float, csi: str) -> list[str]:
    receiver = [] if csi == "perfect" else ["--csi", csi]  # perfect: the run's default
    return [
        "run",
        "--channel",
        "raytraced",
        "--drone-speed",
        str(speed),
        "--snr-db",
        str(SNR_DB),
        "--schemes",
        SCHEMES,
        *receiver,
        *SMALL,
    ]


def _one(out: Path, speed: float, csi: str) -> dict:
    run_dir = out / (f"moving_{speed:g}ms" + ("" if csi == "perfect" else f"_{csi}"))
    argv = _argv(speed, csi)
    wall = _run(run_dir, argv)
    report = Report.from_dict(json.loads((run_dir / "report.json").read_text()))
    link = report.link.to_dict()
    spreads = list(report.link.motion.rms_doppler_spread_hz.values()) if report.link.motion else []
    measured = report.views.measured_snr_db  # the SCU's pilot measurement through the link
    return {
        "drone_speed_m_s": speed,
        "csi": csi,
        "receiver": link.get("csi"),
        "grid": link.get("grid"),
        "command": "osnerf " + " ".join(argv),
        "wall_seconds": wall or None,
        "link": {k: link.get(k) for k in LINK_KEYS},
        "max_rms_doppler_spread_hz": max(spreads, default=None),
        "views_with_doppler_spread": sum(x > SPREAD_FLOOR_HZ for x in spreads),
        "views_traced": len(spreads),
        "psnr_object": {n: s.psnr_object for n, s in report.schemes.items()},
        "symbols_sent": {n: s.symbols_sent for n, s in report.schemes.items()},
        "views_lost": {n: s.views_lost for n, s in report.schemes.items()},
        "views_sent": {n: s.views_sent for n, s in report.schemes.items()},
        "median_measured_snr_db": float(np.median(list(measured.values()))),
    }


def run(out_dir: Path) -> dict:
    rows = [_one(Path(out_dir), v, csi) for csi in CSI for v in SPEEDS_M_S]
    return {
        "command": f"osnerf run --channel raytraced --drone-speed V --snr-db {SNR_DB} "
        f"--schemes {SCHEMES} [--csi ls|lmmse] " + " ".join(SMALL),
        "snr_db_at_median_position": SNR_DB,
        "rows": rows,
        "csi": "perfect: CSI of h at each symbol's time, symbols on the traced subcarriers "
        "in turn; ls, lmmse: the symbols on the run's OFDM grid, h estimated from its pilots "
        "(each row's receiver and grid)",
        "note": "wall_seconds is null where this commit's report was reused",
    }

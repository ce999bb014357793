"""Published Kodak numbers to measure against (``../shared/reference/jscc-anchors.md``): one
table, read by the plots and the codec benchmark.

Conventions as ours: CBR = complex symbols per real source value, SNR = Es/N0 per complex
symbol, PSNR the mean of per-image PSNR. Names ending in "(plot)" were read off published
figures (about +-0.3 dB). The published Rayleigh results are fast fading with CSI at the
receiver, so they sit under ``rayleigh_fast``.
"""

from __future__ import annotations

import csv
import math
from collections import defaultdict
from pathlib import Path

from osnerf.paths import shared_data_dir

KODAK_CBR = 1 / 16
"""The CBR of :data:`KODAK`."""
STANDARD_SNRS_DB = (1, 4, 7, 10, 13)
"""The SNRs most anchors are published at; points elsewhere are "at their own SNR"."""

KODAK: dict[str, dict[str, list[tuple[float, float]]]] = {
    "awgn": {
        "BPG + 5G LDPC, best MCS (WITT paper, plot)": [
            (2, 29.3),
            (6, 30.2),
            (8, 32.0),
            (10, 33.3),
            (13, 35.5),
        ],
        "Deep JSCC, CNN (WITT paper, plot)": list(
            zip(STANDARD_SNRS_DB, (28.2, 29.5, 30.4, 31.5, 32.1))
        ),
        "WITT (plot)": list(zip(STANDARD_SNRS_DB, (29.7, 31.3, 32.6, 33.6, 34.3))),
        "SwinJSCC, one model": list(zip(STANDARD_SNRS_DB, (29.54, 31.09, 32.27, 33.17, 33.80))),
    },
    "rayleigh_fast": {
        "BPG + 5G LDPC, best MCS (WITT paper, plot)": [
            (2.4, 27.9),
            (5.2, 29.3),
            (8.3, 30.3),
            (11.3, 32.0),
        ],
        "Deep JSCC, CNN (WITT paper, plot)": list(
            zip(STANDARD_SNRS_DB, (26.7, 27.7, 28.4, 29.2, 29.6))
        ),
        "WITT (plot)": list(zip(STANDARD_SNRS_DB, (28.3, 29.4, 30.3, 30.8, 31.2))),
    },
}
"""channel -> anchor -> [(snr_db, psnr_db)], Kodak at CBR 1/16."""

KODAK_AWGN_10DB_VS_CBR: dict[str, list[tuple[float, float]]] = {
    "SwinJSCC, one model": [
        (1 / 48, 29.04),
        (1 / 24, 31.55),
        (1 / 16, 33.17),
        (1 / 12, 34.41),
        (1 / 8, 36.05),
    ]
}
"""Kodak, AWGN at 10 dB, across CBR: anchor -> [(cbr, psnr_db)]."""

CAPACITY_CSV = Path("anchors") / "kodak_codec_plus_capacity.csv"
"""Codec + ideal channel code grid (CBR x SNR), under the shared data folder."""
CAPACITY_CODECS = ("BPG444", "VTM")


def at_own_snr(points: list[tuple[float, float]]) -> bool:
    """Whether an anchor's points lie off :data:`STANDARD_SNRS_DB` (compare them at their
    own SNRs, not row by row)."""
    return any(float(s) not in STANDARD_SNRS_DB for s, _ in points)


def capacity_anchor(
    data_dir: Path | None, cbr: float | None = None, snr_db: float | None = None
) -> dict[str, list[tuple[float, float]]]:
    """Codec + ideal channel code (Kodak, AWGN) from the shared CSV: vs SNR at ``cbr`` (within
    2 %) or vs CBR at ``snr_db``. Empty when the file is not there."""
    if data_dir is None:
        data_dir = shared_data_dir()
    path = Path(data_dir) / CAPACITY_CSV
    if not path.is_file():
        return {}
    out: dict[str, list[tuple[float, float]]] = defaultdict(list)
    with open(path, newline="") as f:
        for row in csv.DictReader(f):
            c, s = float(row["cbr_complex_per_dim"]), float(row["snr_db"])
            for codec in CAPACITY_CODECS:
                v = float(row[codec])
                if not math.isfinite(v):
                    continue
                if cbr is not None and abs(c - cbr) / cbr < 0.02:
                    out[codec].append((s, v))
                elif snr_db is not None and abs(s - snr_db) < 1e-6:
                    out[codec].append((c, v))
    return {k: sorted(v) for k, v in out.items()}

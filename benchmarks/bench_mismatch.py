"""When the transmitter's SNR is wrong: every scheme planned from a belief, judged at the truth.

All on Kodak (the first ``OSNERF_BENCH_MISMATCH_IMAGES``, default all 24, or per part, e.g.
``24,estimate:6,cbr:4``), CBR 1/16, through
``osnerf eval-codec``:

* ``panel``: AWGN, every transmitter planned at :data:`PLAN_SNR_DB` (``--plan-snr-db``),
  the channel at :data:`PANEL_SNRS`: jscc, digital, softcast, and ideal at the true SNR (a
  bound); digital's staircase, ``digital_fixed`` at each of :data:`STAIRCASE_MCS` (it plans
  nothing). Where each scheme leads, where digital loses its images and whether it gains
  above its plan are stated in ``findings``.
* ``estimate``: each image's estimate is its true SNR plus a 2 dB Gaussian error
  (``--snr-error-db 2``) at :data:`ESTIMATE_SNRS`, on AWGN (1 draw) and block Rayleigh
  (:data:`RAYLEIGH_DRAWS` draws): digital planned over the error against ``digital_naive``,
  jscc and softcast with the same estimates; on AWGN the same with exact knowledge beside it
  (:data:`ESTIMATE_ERRORS`: on block Rayleigh the exact-knowledge run costs as much as the
  error's and is left to ``OSNERF_BENCH_MISMATCH_RAYLEIGH_EXACT=1``). Block Rayleigh rows
  carry the per-image outage statistics (5th and 10th percentile PSNR, fraction lost).
* ``forecast``: the digital planner with exact knowledge on AWGN at :data:`FORECAST_SNRS`:
  the images it expected to lose (the sum of its per-image loss probabilities) against those
  lost.
* ``cbr``: quality against the bandwidth ratio, every scheme with exact knowledge, AWGN at
  :data:`CBR_SNR_DB` (where the published anchors are), at each of :data:`CBRS`.
* ``blocks``: the same forecast tested where it is thin, without the image codec: whole
  Kodak-sized blocks (CBR 1/16) of random payload filling an MCS's capacity, sent
  ``OSNERF_BENCH_MISMATCH_BLOCKS`` times (default 60) over AWGN at :data:`BLOCK_POINTS`
  (the MCS the planner picks there), against the calibration's image BLER.

Each eval-codec run is written to ``mismatch_<part>.json`` in the output folder and reused
when its arguments match and a clean tree of the same commit made it; the figures (the panel,
digital's staircase and envelope in PSNR and MS-SSIM, PSNR against CBR, the outage CDF on
block Rayleigh) go
to ``mismatch/`` beside them.
``OSNERF_BENCH_MISMATCH_PARTS``: comma-separated subset of ``panel,staircase,estimate,
forecast,cbr,blocks``; ``OSNERF_BENCH_MISMATCH_REUSE=any``: reuse a file with the same arguments
whatever commit made it (each keeps its own ``git_commit``). On a shared 2-core CPU the whole
benchmark on 24 images takes hours: the digital chain (AVIF at many qualities, LDPC decoding)
dominates.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import torch

import phy
from common import write_figure, write_text
from osnerf.cli import main
from osnerf.paths import shared_data_dir
from osnerf.plots import (
    eval_record,
    outage_entries,
    plot_digital_cliff,
    plot_mismatch,
    plot_outage_cdf,
    plot_psnr_vs_cbr,
)
from osnerf.plots.rows import is_bound
from osnerf.provenance import git_commit
from osnerf.results import result_rows
from phy.digital import codeword_layout, payload_capacity_bits, transmit_bytes
from semcodec.digital.calibration import load_calibration

PLAN_SNR_DB = 4.0
PANEL_SNRS = (-2.0, 0.0, 2.0, 4.0, 7.0, 10.0, 13.0)
PANEL_SCHEMES = "jscc,digital,softcast,ideal"
STAIRCASE_MCS = (
    "qpsk-120/1024",
    "qpsk-1/3",
    "qpsk-1/2",
    "qpsk-3/4",
    "16qam-1/2",
    "16qam-3/4",
    "64qam-2/3",
    "64qam-5/6",
)
"""The MCSs of digital's staircase (every third step of ``phy.digital.MCS_TABLE`` or so)."""
ESTIMATE_SNRS = (0.0, 4.0, 10.0)
ESTIMATE_SCHEMES = "jscc,digital,digital_naive,softcast"
SNR_ERROR_DB = 2.0
RAYLEIGH_DRAWS = 4
ESTIMATE_ERRORS = {"awgn": (SNR_ERROR_DB, 0.0), "rayleigh": (SNR_ERROR_DB,)}
"""The SNR errors (dB) the ``estimate`` part runs on each channel."""
FORECAST_SNRS = tuple(float(s) for s in range(-10, 14))
BLOCK_POINTS = (("16qam-1/2", 7.0), ("qpsk-3/4", 5.0), ("qpsk-157/1024", -4.0))
CBR_SNR_DB = 10.0
CBRS = ("1/48", "1/16", "1/6", "1/3")
"""The rates of the codec card's CBR sweep (within the shipped codec's ``cbr_range``)."""
CBR_SCHEMES = "jscc,digital,softcast,ideal"
PARTS = ("panel", "staircase", "estimate", "forecast", "cbr", "blocks")


def _blocks(trials: int) -> list[dict]:
    """Image loss of whole blocks of random payload against the calibration's forecast."""
    cal = load_calibration()
    n = phy.num_symbols_for_cbr(1 / 16, 512, 768)  # a Kodak image's budget
    link = phy.channel_link("awgn")
    out = []
    for mcs, snr in BLOCK_POINTS:
        cap = payload_capacity_bits(n, mcs) // 8
        g = torch.Generator().manual_seed(11)
        lost = 0
        for _ in range(trials):
            data = bytes(torch.randint(0, 256, (cap,), generator=g, dtype=torch.uint8).tolist())
            lost += not transmit_bytes(data, mcs, link, snr, generator=g, num_symbols=n).ok
        out.append(
            {
                "mcs": mcs,
                "snr_db": snr,
                "codewords": codeword_layout(n, mcs).num_codewords,
                "blocks": trials,
                "lost": lost,
                "forecast_loss": cal.image_bler("awgn", mcs, snr, n),
            }
        )
    return out


def _eval(out_dir: Path, tag: str, argv: list[str]) -> dict:
    """One ``osnerf eval-codec`` run, reused when its file has the same arguments and a clean
    tree of the same commit made it."""
    path = out_dir / f"mismatch_{tag}.json"
    if path.exists():
        doc = json.loads(path.read_text())
        commit = git_commit()
        same = doc.get("git_commit") == commit and commit != "unknown" and "-dirty" not in commit
        same = same or os.environ.get("OSNERF_BENCH_MISMATCH_REUSE") == "any"
        if doc.get("argv") == argv and same:
            return doc
    if main(["eval-codec", *argv, "--out", str(path), "--overwrite"]) != 0:
        raise RuntimeError(f"eval-codec failed: {' '.join(argv)}")
    doc = json.loads(path.read_text())
    doc["argv"] = argv
    write_text(path, json.dumps(doc))
    return doc


def _row(r: dict) -> dict:
    keys = (
        "scheme",
        "snr_db",
        "psnr",
        "psnr_ci95",
        "ssim",
        "ms_ssim",
        "num_images",
        "draws",
        "lost_images",
        "lost_fraction",
        "psnr_p5",
        "psnr_p10",
        "mcs_used",
        "forecast_lost_images",
        "plan_snr_db",
        "snr_error_db",
        "bound",
    )
    out = {k: r[k] for k in keys if k in r}
    if r.get("mcs_choice") == "fixed":
        out["mcs"] = next(iter(r.get("mcs_used") or {}), None)
    return out


def _common(n: int, cbr: str = "1/16") -> list[str]:
    folder = os.environ.get("OSNERF_BENCH_MISMATCH_FOLDER") or str(shared_data_dir() / "kodak")
    return ["--images", folder, "--max-images", str(n), "--cbr", cbr, "--no-lpips"]


def _snrs(values) -> str:
    return ",".join(f"{v:g}" for v in values)


def _findings(panel: list[dict], staircase: list[dict]) -> list[str]:
    """Where each scheme leads at each SNR; digital's losses below its plan and its gain
    above it."""
    by = {(r["scheme"], r["snr_db"]): r for r in panel}
    out = []
    for s in PANEL_SNRS:
        real = {k: r["psnr"] for (k, x), r in by.items() if x == s and not is_bound(k)}
        if real:
            lead = max(real, key=real.get)
            out.append(
                f"{s:g} dB: {lead} leads ("
                + ", ".join(f"{k} {v:.2f}" for k, v in sorted(real.items()))
                + ")"
            )
    dig = [by["digital", s] for s in PANEL_SNRS if ("digital", s) in by]
    if dig:
        lost = [f"{r['snr_db']:g} dB: {r['lost_images']}/{r['num_images']}" for r in dig]
        out.append(f"digital planned at {PLAN_SNR_DB:g} dB, images lost: " + ", ".join(lost))
        above = [r["psnr"] for r in dig if r["snr_db"] >= PLAN_SNR_DB]
        if len(above) > 1:
            gain = max(above) - above[0]
            said = "no gain above its plan" if gain <= 0 else f"{gain:.2f} dB above its plan"
            out.append(
                f"digital from {PLAN_SNR_DB:g} to {max(PANEL_SNRS):g} dB: "
                f"{min(above):.2f} .. {max(above):.2f} dB ({said})"
            )
    if staircase:
        env = {}
        for r in staircase:
            env[r["snr_db"]] = max(env.get(r["snr_db"], -1.0), r["psnr"])
        out.append(
            "staircase envelope: " + ", ".join(f"{s:g} dB {v:.2f}" for s, v in sorted(env.items()))
        )
    return out


def _figures(out_dir: Path, docs: dict[str, dict]) -> list[str]:
    """The figure set from the eval-codec files of this run, as PNGs under ``mismatch/``."""

    def rows(*tags):
        return result_rows([eval_record(docs[t]) for t in tags if t in docs])

    stairs = [t for t in docs if t.startswith("staircase_")]
    figs = []
    if "panel" in docs:
        figs.append(("mismatch", plot_mismatch(rows("panel", *stairs))))
    if stairs:  # the fixed MCSs alone: their envelope is over the same images
        figs.append(("staircase_psnr", plot_digital_cliff(rows(*stairs), "psnr", anchors=True)))
        figs.append(("staircase_ms_ssim", plot_digital_cliff(rows(*stairs), "ms_ssim")))
    rates = [t for t in docs if t.startswith("cbr_")]
    if len(rates) > 1:
        figs.append(("psnr_vs_cbr", plot_psnr_vs_cbr(rows(*rates))))
    fading = [eval_record(docs[t]) for t in docs if t.startswith("estimate_rayleigh")]
    if fading:
        figs.append(("outage_cdf", plot_outage_cdf(outage_entries(fading))))
    folder = out_dir / "mismatch"
    folder.mkdir(exist_ok=True)
    for name, fig in figs:
        write_figure(folder / f"{name}.png", fig, dpi=110)
    return [f"mismatch/{name}.png" for name, _ in figs]


def _estimate(out_dir: Path, n: int, docs: dict[str, dict]) -> list[dict]:
    """Each scheme under a Gaussian error on each image's SNR estimate (and exact knowledge
    beside it where :data:`ESTIMATE_ERRORS` says), on the first ``n`` Kodak images."""
    rows = []
    for channel, draws in (("awgn", 1), ("rayleigh", RAYLEIGH_DRAWS)):
        errors = ESTIMATE_ERRORS[channel]
        if channel == "rayleigh" and os.environ.get("OSNERF_BENCH_MISMATCH_RAYLEIGH_EXACT"):
            errors = (SNR_ERROR_DB, 0.0)
        for err in errors:
            argv = _common(n) + ["--channel", channel, "--snr-db", _snrs(ESTIMATE_SNRS)]
            argv += ["--draws", str(draws), "--schemes", ESTIMATE_SCHEMES]
            argv += ["--snr-error-db", f"{err:g}"]
            tag = f"estimate_{channel}_err{err:g}"
            docs[tag] = _eval(out_dir, tag, argv)
            rows += [{"channel": channel, **_row(r)} for r in docs[tag]["results"]]
    return rows


def _image_counts(text: str) -> dict[str, int]:
    """Part -> Kodak images from ``OSNERF_BENCH_MISMATCH_IMAGES`` (``N`` for every part, or
    ``N,part:M,...``)."""
    counts = dict.fromkeys(PARTS, 24)
    for item in filter(None, (t.strip() for t in text.split(","))):
        part, _, value = item.rpartition(":")
        if part and part not in PARTS:
            raise ValueError(f"OSNERF_BENCH_MISMATCH_IMAGES: unknown part {part!r}; known: {PARTS}")
        if not value.isdigit() or not 1 <= int(value) <= 24:
            raise ValueError(f"OSNERF_BENCH_MISMATCH_IMAGES: {item!r} is not a count in 1..24")
        counts.update({part: int(value)} if part else dict.fromkeys(PARTS, int(value)))
    return counts


def run(out_dir: Path) -> dict:
    torch.set_num_threads(1)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    counts = _image_counts(os.environ.get("OSNERF_BENCH_MISMATCH_IMAGES", "24"))
    parts = [p for p in os.environ.get("OSNERF_BENCH_MISMATCH_PARTS", ",".join(PARTS)).split(",")]
    result: dict = {"images": counts, "cbr": "1/16", "plan_snr_db": PLAN_SNR_DB}
    panel: list[dict] = []
    staircase: list[dict] = []
    docs: dict[str, dict] = {}
    if "panel" in parts:
        argv = _common(counts["panel"]) + ["--channel", "awgn", "--snr-db", _snrs(PANEL_SNRS)]
        argv += ["--plan-snr-db", f"{PLAN_SNR_DB:g}", "--schemes", PANEL_SCHEMES]
        docs["panel"] = _eval(out_dir, "panel", argv)
        panel = [_row(r) for r in docs["panel"]["results"]]
        result["panel"] = panel
    if "staircase" in parts:
        for mcs in STAIRCASE_MCS:
            argv = _common(counts["staircase"]) + ["--channel", "awgn"]
            argv += ["--snr-db", _snrs(PANEL_SNRS), "--schemes", "digital_fixed", "--mcs", mcs]
            tag = "staircase_" + mcs.replace("/", "_")
            docs[tag] = _eval(out_dir, tag, argv)
            staircase += [_row(r) for r in docs[tag]["results"]]
        result["staircase"] = staircase
    result["findings"] = _findings(panel, staircase)
    if "estimate" in parts:
        result["estimate"] = _estimate(out_dir, counts["estimate"], docs)
    if "forecast" in parts:
        argv = _common(counts["forecast"]) + ["--channel", "awgn"]
        argv += ["--snr-db", _snrs(FORECAST_SNRS)]
        argv += ["--schemes", "digital"]
        doc = _eval(out_dir, "forecast", argv)
        rows = [
            {
                "snr_db": r["snr_db"],
                "forecast_lost_images": r["forecast_lost_images"],
                "lost_images": r["lost_images"],
                "num_images": r["num_images"],
                "mcs_used": r["mcs_used"],
                "psnr": r["psnr"],
            }
            for r in doc["results"]
        ]
        f = np.array([r["forecast_lost_images"] for r in rows])
        m = np.array([r["lost_images"] for r in rows])
        result["forecast"] = {
            "rows": rows,
            "forecast_total": float(f.sum()),
            "lost_total": int(m.sum()),
            "sends": int(sum(r["num_images"] for r in rows)),
        }
    if "cbr" in parts:
        rows = []
        for cbr in CBRS:
            argv = _common(counts["cbr"], cbr) + [
                "--channel",
                "awgn",
                "--snr-db",
                f"{CBR_SNR_DB:g}",
            ]
            tag = "cbr_" + cbr.replace("/", "_")
            docs[tag] = _eval(out_dir, tag, argv + ["--schemes", CBR_SCHEMES])
            rows += [{"cbr": cbr, **_row(r)} for r in docs[tag]["results"]]
        result["cbr_sweep"] = rows
    if "blocks" in parts:
        result["blocks"] = _blocks(int(os.environ.get("OSNERF_BENCH_MISMATCH_BLOCKS", "60")))
    result["figures"] = _figures(out_dir, docs)
    return result

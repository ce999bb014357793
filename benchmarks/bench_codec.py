"""Semantic codec benchmark: speed, the Kodak table against the digital baselines, focus.

* encode+decode images/s on Kodak-size (768x512) and 128 px images, training images/s
  (96 px crops, batch 12), with the shipped checkpoint; timings on a shared 2-core machine
  are noisy.
* The codec table: Kodak x channels (awgn; rayleigh = block fading, 4 draws per image;
  rayleigh_fast) x SNR -10, -5, -2, 0, 1, 4, 10 dB at CBR 1/16, through ``osnerf eval-codec``: jscc
  (each checkpoint; on block fading also jscc_refined, :data:`REFINED_CHANNELS`), digital
  (honest: MCS from the calibration table), digital_genie and ideal (bounds), mean and 95 %
  interval, with the published anchors beside each row and checks (jscc above digital,
  genie never below digital); the same on other photos (BSDS500's
  test split, block fading: :data:`OTHER_PHOTOS`).
* The rate curve: Kodak (``OSNERF_BENCH_CODEC_RATE_IMAGES``, default 12) on AWGN at 1 and
  10 dB, CBR 1/48 .. 1/3: jscc, its learned channels alone (``jscc_learned``) and digital.
* On-demand focus on nerf_synthetic lego views (alpha = object mask): object-region PSNR
  at equal symbols and symbols saved.

Environment: ``OSNERF_BENCH_CODEC_IMAGES`` (default 24 Kodak images);
``OSNERF_BENCH_CODEC_CHECKPOINTS``: os.pathsep-separated checkpoints for jscc (default the
shipped one); ``OSNERF_BENCH_CODEC_FOLDER``: another image folder;
``OSNERF_BENCH_CODEC_ONLY``: ``jscc`` or ``separate`` to run one half;
``OSNERF_BENCH_CODEC_CHANNELS``: comma-separated subset of the channels. Each eval-codec run
is written to ``codec_<channel>_<part>.json`` in the output folder and reused when its
arguments match and the same clean commit made it (the LDPC chain takes the better part of an
hour here).
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

import numpy as np
import torch

import phy
from common import write_text
from osnerf.anchors import KODAK, KODAK_CBR, at_own_snr, capacity_anchor
from osnerf.cli import main
from osnerf.paths import shared_data_dir
from osnerf.provenance import git_commit
from semcodec import load_codec
from semcodec.jscc.focus_eval import focus_gain
from semcodec.jscc.model import make_model
from semcodec.links.schemes import DIGITAL, IDEAL, JSCC, LINK_SCHEMES
from semcodec.training.loop import forward_train


def _speed(codec) -> dict:
    out = {"threads": torch.get_num_threads()}
    for name, shape, reps, cbr in (
        ("kodak_768x512", (1, 3, 512, 768), 3, 1 / 16),
        ("kodak_768x512_cbr_1_3", (1, 3, 512, 768), 3, 1 / 3),  # with the analog layer's split
        ("px128_batch8", (8, 3, 128, 128), 3, 1 / 16),
    ):
        x = torch.rand(*shape, generator=torch.Generator().manual_seed(0))
        enc = codec.encode(x, 10.0, cbr)
        codec.decode(enc.symbols, enc.meta, 10.0)
        t = time.perf_counter()
        for _ in range(reps):
            enc = codec.encode(x, 10.0, cbr)
            codec.decode(enc.symbols, enc.meta, 10.0)
        out[f"encode_decode_images_per_s_{name}"] = shape[0] * reps / (time.perf_counter() - t)

    model = make_model(codec.model.cfg.name)
    opt = torch.optim.Adam(model.parameters(), 1e-4)
    g = torch.Generator().manual_seed(0)
    x = torch.rand(12, 3, 96, 96, generator=g)
    times = []
    for i in range(6):
        t = time.perf_counter()
        y = forward_train(model, x, torch.full((12,), 5.0), torch.full((12,), 3), "awgn", g)
        loss = ((y - x) ** 2).mean()
        opt.zero_grad()
        loss.backward()
        opt.step()
        if i:
            times.append(time.perf_counter() - t)
    out["train_images_per_s_96px_batch12"] = 12 / float(np.median(times))
    return out


CHANNELS = (("awgn", 1), ("rayleigh", 4), ("rayleigh_fast", 1))
"""(channel, draws per image) of the codec table."""
OTHER_PHOTOS = ("bsds500/test", (("rayleigh", 4),))
"""Photos other than Kodak (a folder of the shared data, its channels): block fading, where
the honest digital link must be beaten on more than one image set. Read for evaluation
only (BSDS500 is the codec's training source: its test split was never trained on)."""
REFINED_CHANNELS = ("rayleigh",)
"""Channels where the table also has ``jscc_refined`` (the transmitter refines each image's
symbols, :func:`semcodec.jscc.refine_symbols`; about 20 CPU s per Kodak image and SNR): block
fading, where jscc meets the honest digital link."""
TABLE_SNRS = (-10.0, -5.0, -2.0, 0.0, 1.0, 4.0, 10.0)
"""The table's SNRs: the HIWE range from -10 to 10 dB."""
SEPARATE = tuple(
    name
    for name, s in LINK_SCHEMES.items()
    if s.kind in (DIGITAL, IDEAL) and s.image_codec == "avif" and s.mcs != "fixed"
)
"""The AVIF separate schemes of the table: honest digital, its genie bound, the capacity bound."""


def _anchors_at(channel: str, snr_db: float) -> dict[str, float]:
    """The published Kodak numbers (``osnerf.anchors``) at exactly this channel and SNR,
    codec + capacity included on AWGN."""
    table = dict(KODAK.get(channel, {}))
    if channel == "awgn":
        table.update({f"{k} + capacity": v for k, v in capacity_anchor(None, KODAK_CBR).items()})
    return {k: p for k, pts in table.items() for s, p in pts if abs(s - snr_db) < 1e-6}


def _eval(out_dir: Path, tag: str, argv: list[str]) -> dict:
    """One ``osnerf eval-codec`` run, reused when its result file has the same config and
    was made by the same code (git commit of a clean tree)."""
    path = out_dir / f"codec_{tag}.json"
    want = argv + ["--out", str(path)]
    if path.exists():
        doc = json.loads(path.read_text())
        commit = git_commit()
        same_code = (
            doc.get("git_commit") == commit and commit != "unknown" and "-dirty" not in commit
        )
        if doc.get("argv") == want[:-2] and same_code:
            return doc
    if main(["eval-codec", *want]) != 0:
        raise RuntimeError(f"eval-codec failed: {' '.join(want)}")
    doc = json.loads(path.read_text())
    doc["argv"] = want[:-2]
    write_text(path, json.dumps(doc))
    return doc


def _codec_table(
    out_dir: Path, photos: str | None = None, channels=CHANNELS, prefix: str = ""
) -> dict:
    """Images x channels x SNR (default Kodak and :data:`CHANNELS`): jscc (each checkpoint),
    digital, digital_genie, ideal, with the anchors beside each row. ``photos``: a folder
    of the shared data instead; ``prefix`` keeps its eval-codec result files apart."""
    n = int(os.environ.get("OSNERF_BENCH_CODEC_IMAGES", "24"))
    ckpts = [p for p in os.environ.get("OSNERF_BENCH_CODEC_CHECKPOINTS", "").split(os.pathsep) if p]
    ckpts = ckpts or [None]
    if photos:
        folder = str(shared_data_dir() / photos)
    else:
        folder = os.environ.get("OSNERF_BENCH_CODEC_FOLDER") or str(shared_data_dir() / "kodak")
    only = os.environ.get("OSNERF_BENCH_CODEC_ONLY")  # "jscc" or "separate": one half
    common = [
        "--images",
        folder,
        "--snr-db=" + ",".join(f"{s:g}" for s in TABLE_SNRS),
        "--cbr",
        "1/16",
        "--seed",
        "0",
        "--max-images",
        str(n),
        "--no-lpips",
        "--threads",
        "1",
    ]
    rows: dict = {}
    codecs = {}
    pick = [c for c in os.environ.get("OSNERF_BENCH_CODEC_CHANNELS", "").split(",") if c]
    for channel, draws in channels:
        if pick and channel not in pick:
            continue
        base = [*common, "--channel", channel, "--draws", str(draws)]
        docs = []
        if only != JSCC:
            docs.append(
                _eval(
                    out_dir,
                    f"{prefix}{channel}_separate",
                    [*base, "--schemes", ",".join(SEPARATE)],
                )
            )
        if only != "separate":
            docs += _jscc_docs(out_dir, f"{prefix}{channel}", channel, base, ckpts, codecs)
        for doc in docs:
            _add_rows(rows, channel, draws, doc)
    table = sorted(
        rows.values(), key=lambda r: ([c for c, _ in channels].index(r["channel"]), r["snr_db"])
    )
    for row in table:
        row["anchors"] = _anchors_at(row["channel"], row["snr_db"])
        own = {k: v for k, v in KODAK.get(row["channel"], {}).items() if at_own_snr(v)}
        if own:
            row["anchors_at_own_snr"] = own
    return {
        "images": folder,
        "num_images": n,
        "cbr": "1/16",
        "checkpoints": codecs,
        "metric": "mean of per-image PSNR over images x draws; 95% percentile bootstrap interval",
        "ideal": "AVIF at the AWGN capacity of the average SNR, error free (a bound)",
        "table": table,
        "checks": _checks(table, codecs),
    }


def _jscc_docs(out_dir: Path, tag: str, channel: str, base: list[str], ckpts, codecs: dict):
    """The eval-codec results of jscc for each checkpoint (and jscc_refined on
    :data:`REFINED_CHANNELS`), each row's scheme named by its codec; ``codecs`` gets each
    label's checkpoint."""
    docs = []
    for ck in ckpts:
        codec = load_codec(ck)
        label = f"jscc[{codec.name}]"
        codecs[label] = {"path": ck or "shipped default", "sha256": codec.sha256}
        args = [*base, "--schemes", "jscc"] + (["--codec", ck] if ck else [])
        doc = _eval(out_dir, f"{tag}_jscc_{codec.sha256[:12]}", args)
        for r in doc["results"]:
            r["scheme"] = label
        docs.append(doc)
        if channel in REFINED_CHANNELS:
            label = f"jscc_refined[{codec.name}]"
            codecs[label] = codecs[f"jscc[{codec.name}]"]
            args[args.index("jscc")] = "jscc_refined"
            doc = _eval(out_dir, f"{tag}_jscc_refined_{codec.sha256[:12]}", args)
            for r in doc["results"]:
                r["scheme"] = label
            docs.append(doc)
    return docs


def _add_rows(rows: dict, channel: str, draws: int, doc: dict) -> None:
    """Each result of ``doc`` into its (channel, SNR) row of the table, rounded."""
    for r in doc["results"]:
        row = rows.setdefault(
            (channel, r["snr_db"]),
            {"channel": channel, "snr_db": r["snr_db"], "draws": draws, "schemes": {}},
        )
        row["schemes"][r["scheme"]] = {
            "psnr": round(r["psnr"], 2),
            "psnr_ci95": [None if v is None else round(v, 2) for v in r["psnr_ci95"]],
            "ssim": round(r["ssim"], 4),
            **({"views_lost": r["views_lost"]} if "views_lost" in r else {}),
            **({"mcs_used": r["mcs_used"]} if "mcs_used" in r else {}),
            **({"bound": r["bound"]} if r.get("bound") else {}),
        }


def _checks(table: list[dict], codecs: dict) -> dict[str, bool]:
    """Per row: the genie digital is not below digital, and each jscc is above digital."""
    checks = {}
    for row in table:
        sch = row["schemes"]
        key = f"{row['channel']}_{row['snr_db']:g}dB"
        if "digital" in sch and "digital_genie" in sch:
            checks[f"genie_not_below_digital_{key}"] = (
                sch["digital_genie"]["psnr"] >= sch["digital"]["psnr"]
            )
        for label in codecs:
            if label in sch and "digital" in sch:
                checks[f"{label}_above_digital_{key}"] = sch[label]["psnr"] > sch["digital"]["psnr"]
    return checks


RATE_CBRS = ("1/48", "1/16", "1/6", "1/4", "1/3")
"""The rate curve's CBRs: the codec's range, through the analog refinement layer's."""
RATE_SCHEMES = ("jscc", "jscc_learned", "digital")
RATE_SNRS = (1.0, 10.0)


def _rate_curve(out_dir: Path) -> dict:
    """Kodak on AWGN at every CBR of :data:`RATE_CBRS`: jscc (with the analog refinement
    layer where it pays), its learned channels alone and honest digital; checks that jscc
    rises with the rate at every SNR and that CBR 1/3 is 2 dB above CBR 1/6 at 10 dB."""
    n = int(os.environ.get("OSNERF_BENCH_CODEC_RATE_IMAGES", "12"))
    folder = str(shared_data_dir() / "kodak")
    curve: dict = {}
    for cbr in RATE_CBRS:
        argv = ["--images", folder, "--channel", "awgn", "--cbr", cbr, "--seed", "0"]
        argv += ["--snr-db=" + ",".join(f"{v:g}" for v in RATE_SNRS), "--max-images", str(n)]
        argv += ["--no-lpips", "--threads", "1", "--schemes", ",".join(RATE_SCHEMES)]
        doc = _eval(out_dir, f"rate_awgn_{cbr.replace('/', '_')}", argv)
        for r in doc["results"]:
            point = curve.setdefault(r["scheme"], {}).setdefault(f"{r['snr_db']:g}dB", {})
            point[cbr] = round(r["psnr"], 2)
    checks = {}
    for snr, points in curve.get("jscc", {}).items():
        values = [points[c] for c in RATE_CBRS]
        checks[f"jscc_rises_with_rate_{snr}"] = all(b > a for a, b in zip(values, values[1:]))
        for c in RATE_CBRS:
            checks[f"jscc_above_digital_{snr}_cbr_{c}"] = points[c] > curve["digital"][snr][c]
    ten = curve.get("jscc", {}).get("10dB", {})
    if ten:
        checks["jscc_cbr_1/3_2dB_above_1/6_at_10dB"] = ten["1/3"] >= ten["1/6"] + 2.0
    return {"images": folder, "num_images": n, "channel": "awgn", "psnr": curve, "checks": checks}


def _focus(codec) -> dict:
    from PIL import Image

    link = phy.FlatLink(phy.make_channel("awgn"))
    recs = []
    for i in (0, 10, 20):
        a = (
            np.asarray(
                Image.open(shared_data_dir() / "nerf_synthetic/lego/test" / f"r_{i}.png").resize(
                    (200, 200), Image.LANCZOS
                )
            ).astype(np.float32)
            / 255
        )
        rgb = a[..., :3] * a[..., 3:] + (
            1 - a[..., 3:]
        )  # white background, as the renderer composites
        x = torch.from_numpy(rgb).permute(2, 0, 1)[None].contiguous()
        mask = torch.from_numpy(a[..., 3] > 0.5).float()[None, None]
        for snr in (1.0, 10.0):
            r = focus_gain(codec, x, mask, link, snr, 1 / 16)
            recs.append(
                {
                    "view": i,
                    **{k: v for k, v in r.items() if k != "focus_curve"},
                    "curve": [
                        (c["fraction"], round(c["object_psnr"], 2)) for c in r["focus_curve"]
                    ],
                }
            )
    summary = {}
    for snr in (1.0, 10.0):
        rs = [r for r in recs if r["snr_db"] == snr]
        summary[f"{snr:g}"] = {
            "whole_object_psnr": round(float(np.mean([r["whole_object_psnr"] for r in rs])), 2),
            "focus_object_psnr_same_symbols": round(
                float(np.mean([r["focus_object_psnr_same_symbols"] for r in rs])), 2
            ),
            "symbols_saved_mean": round(float(np.mean([r["symbols_saved"] for r in rs])), 3),
        }
    return {"views": recs, "summary": summary}


def run(out_dir: Path) -> dict:
    torch.set_num_threads(min(2, os.cpu_count() or 1))
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    codec = load_codec()
    other, other_channels = OTHER_PHOTOS
    return {
        "speed": _speed(codec),
        "focus": _focus(codec),
        "codec_table": _codec_table(out_dir),
        "rate_curve": _rate_curve(out_dir),
        "codec_table_other_photos": _codec_table(out_dir, other, other_channels, "other_"),
    }

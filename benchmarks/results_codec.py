"""The codec against the digital link on Kodak: the ``osnerf eval-codec`` files of
``bench-results/`` (jscc only of the shipped checkpoint) and their section of
``docs/results.md``, with the cells the headline table writes alike."""

from __future__ import annotations

import re
from fractions import Fraction
from pathlib import Path

from benchmarks.results_common import (
    CARDS,
    RESULTS,
    ResultsError,
    commit_of,
    load_json,
    markdown_table,
)

CHANNEL_LABELS = {"awgn": "AWGN", "rayleigh": "block Rayleigh", "rayleigh_fast": "fast Rayleigh"}


CODEC_SCHEMES = ("jscc", "digital", "digital_genie", "ideal")


BOUNDS = ("digital_genie", "ideal", "gt")


def scheme_label(scheme: str) -> str:
    return f"{scheme} (bound)" if scheme in BOUNDS else scheme


def lost_count(entry: dict | None) -> int:
    """Views or images lost to the budget or the channel (0 when the scheme cannot lose any)."""
    lost = (entry or {}).get("views_lost") or {}
    return int(sum(lost.values())) if isinstance(lost, dict) else int(lost)


def shipped_sha(cards_dir: Path = CARDS) -> str:
    """The sha256 of the shipped default checkpoint (its ``default.card.json``)."""
    path = cards_dir / "default.card.json"
    if not path.is_file():
        raise ResultsError(f"{path} not found: the shipped default's card")
    sha = load_json(path).get("sha256")
    if not isinstance(sha, str) or not re.fullmatch(r"[0-9a-f]{64}", sha):
        raise ResultsError(f"{path} has no sha256")
    return sha


def codec_results(folder: Path = RESULTS, default_sha: str | None = None) -> dict:
    """channel -> {"rows": {(scheme, snr_db): result row}, "docs": [eval-codec files]}; jscc
    results only of the checkpoint whose sha256 starts ``default_sha`` (default: the shipped
    one's)."""
    sha12 = (default_sha or shipped_sha())[:12]
    out: dict = {}
    for path in sorted(folder.glob("codec_*.json")):
        m = re.fullmatch(r"codec_(?P<ch>.+?)_(separate|jscc_(?P<sha>[0-9a-f]{12}))", path.stem)
        if not m or m["ch"] not in CHANNEL_LABELS:  # Kodak's table only
            continue
        if m["sha"] and m["sha"] != sha12:  # another checkpoint's: not the shipped codec
            continue
        doc = load_json(path)
        entry = out.setdefault(m["ch"], {"rows": {}, "docs": []})
        entry["docs"].append((path.name, doc))
        for r in doc["results"]:
            entry["rows"][(r["scheme"], float(r["snr_db"]))] = r
    return out


def psnr_text(x: float | None) -> str:
    return "–" if x is None else f"{x:.2f}"


def cbr_text(cbr: float) -> str:
    return str(Fraction(cbr).limit_denominator(64))


def _eval_command(doc: dict) -> str:
    """The eval-codec command line that made ``doc`` (rebuilt from its config if not stored)."""
    argv = doc.get("argv")
    if not argv:
        c = doc["config"]
        argv = [
            *("--images", c["images"], "--max-images", str(len(c["image_names"]))),
            *("--channel", c["channel"], "--draws", str(c["draws"])),
            "--snr-db=" + ",".join(f"{x:g}" for x in c["snr_db"]),
            *("--cbr", cbr_text(c["cbr"]), "--schemes", ",".join(c["schemes"])),
            *("--seed", str(doc["seed"])),
            *([] if c.get("lpips", True) else ["--no-lpips"]),
        ]
    text = "osnerf eval-codec " + " ".join(argv)
    return re.sub(r"\S*/shared/data/", "../shared/data/", text)


OUTAGE_CHANNELS = ("rayleigh",)
"""Block fading: where the tail of per-image PSNR (outage) is shown beside the mean."""


def _percentile(values: list[float], q: float) -> float:
    """The q-th percentile, linear between order statistics (numpy's default)."""
    v = sorted(values)
    k = (len(v) - 1) * q / 100.0
    lo = int(k)
    hi = min(lo + 1, len(v) - 1)
    return v[lo] + (v[hi] - v[lo]) * (k - lo)


def _outage_table(entry: dict, schemes: list[str], snrs: list[float]) -> list[str]:
    """5th and 10th percentile of per-image PSNR over images x draws, per scheme and SNR
    (from each row's ``psnr_per_draw``)."""
    rows = []
    for scheme in schemes:
        cells = []
        for snr in snrs:
            r = entry["rows"].get((scheme, snr))
            per = [v for row in (r or {}).get("psnr_per_draw") or [] for v in row]
            cells.append(f"{_percentile(per, 5):.2f} / {_percentile(per, 10):.2f}" if per else "–")
        rows.append([scheme_label(scheme), *cells])
    return [
        "The tail: 5th / 10th percentile of per-image PSNR over images x draws (dB).",
        "",
        *markdown_table(["scheme", *(f"{s:g} dB" for s in snrs)], rows),
        "",
    ]


def codec_section(codec: dict) -> list[str]:
    lines = ["## The codec against the digital link", ""]
    if not codec:
        return lines + ["No `codec_*.json` in bench-results/ (`python -m benchmarks codec`).", ""]
    for channel in (c for c in CHANNEL_LABELS if c in codec):
        entry = codec[channel]
        lines.append(f"### {CHANNEL_LABELS.get(channel, channel)}")
        lines.append("")
        for name, doc in entry["docs"]:
            lines.append(f"- `{name}`: `{_eval_command(doc)}`, commit {commit_of(doc)}")
        lines.append("")
        snrs = sorted({s for _, s in entry["rows"]})
        schemes = [
            s
            for s in (*CODEC_SCHEMES, "jscc_refined")
            if any((s, x) in entry["rows"] for x in snrs)
        ]
        rows = []
        for scheme in schemes:
            cells = []
            for snr in snrs:
                r = entry["rows"].get((scheme, snr))
                if r is None:
                    cells.append("–")
                    continue
                total = r["num_images"] * r["draws"]
                lost = lost_count(r)
                cells.append(psnr_text(r["psnr"]) + (f" ({lost}/{total} lost)" if lost else ""))
            rows.append([scheme_label(scheme), *cells])
        lines += markdown_table(["scheme", *(f"{s:g} dB" for s in snrs)], rows)
        lines.append("")
        if channel in OUTAGE_CHANNELS:
            lines += _outage_table(entry, schemes, snrs)
    lines.append(
        "Mean of per-image PSNR over images x draws (peak 1.0); `lost` counts images that "
        "did not arrive (the digital link shows them mid-grey). `digital_genie` knows each "
        "draw's fade and `ideal` sends at the AWGN capacity: both are bounds, not systems."
    )
    return lines + [""]

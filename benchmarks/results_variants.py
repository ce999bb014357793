"""The demo's variants in ``docs/results.md``: a 2 dB error on each view's SNR estimate and
digital sending the demanded objects' box, beside exact knowledge, from the ``osnerf run``
reports of ``python -m benchmarks pipeline`` (``pipeline_demo``,
``pipeline_demo_<variant>_seed<N>``, ``pipeline_tiny_ota[_box]_<S>dB_seed<N>``). A missing
report leaves its row out."""

from __future__ import annotations

import re
from pathlib import Path
from statistics import mean

from benchmarks.results_common import RESULTS, commit_of, load_json, markdown_table

DEMO_DIR = re.compile(r"pipeline_demo_(?P<variant>[a-z0-9]+)_seed(?P<seed>\d+)$")
OTA_DIR = re.compile(r"pipeline_tiny_(?P<tag>ota|ota_box)_(?P<snr>-?\d+)dB_seed(?P<seed>\d+)$")
VARIANT_WORDS = {
    "exact": "exact knowledge",
    "err2": "2 dB estimate error (--snr-error-db 2)",
    "box": "digital sends the box (--digital-box true)",
}
SCHEMES = ("jscc", "digital", "full", "gt")


def demo_variants(folder: Path = RESULTS) -> dict[str, dict[int, dict]]:
    """variant -> seed -> report (seed 0 with exact knowledge is ``pipeline_demo``)."""
    out: dict[str, dict[int, dict]] = {}
    base = folder / "pipeline_demo" / "report.json"
    if base.is_file():
        out.setdefault("exact", {})[0] = load_json(base)
    for d in sorted(folder.glob("pipeline_demo_*")):
        m = DEMO_DIR.match(d.name)
        if m and (d / "report.json").is_file():
            out.setdefault(m["variant"], {})[int(m["seed"])] = load_json(d / "report.json")
    return {v: dict(sorted(out[v].items())) for v in VARIANT_WORDS if v in out}


def ota_pairs(folder: Path = RESULTS) -> dict[tuple[float, int], dict[str, dict]]:
    """(SNR, seed) -> {"ota": report, "ota_box": report} for the tiny scene over the air."""
    out: dict[tuple[float, int], dict[str, dict]] = {}
    for d in sorted(folder.glob("pipeline_tiny_ota*")):
        m = OTA_DIR.match(d.name)
        if m and (d / "report.json").is_file():
            key = (float(m["snr"]), int(m["seed"]))
            out.setdefault(key, {})[m["tag"]] = load_json(d / "report.json")
    return dict(sorted(out.items(), key=lambda kv: (-kv[0][0], kv[0][1])))


def _obj(doc: dict | None, scheme: str) -> float | None:
    s = (doc or {}).get("schemes", {}).get(scheme)
    return None if s is None else s.get("psnr_object")


def _gap(doc: dict | None) -> float | None:
    j, d = _obj(doc, "jscc"), _obj(doc, "digital")
    return None if j is None or d is None else j - d


def _f(v: float | None, sign: bool = False) -> str:
    return "–" if v is None else (f"{v:+.2f}" if sign else f"{v:.2f}")


def section(folder: Path = RESULTS) -> list[str]:
    """Per seed and variant each scheme's object PSNR and jscc minus digital; the mean over
    the seeds each variant has; the tiny scene over the air with and without the box."""
    lines = ["## End to end when the link is not known exactly, and like for like", ""]
    runs = demo_variants(folder)
    if len(runs) < 2:
        return lines + ["No demo variants (`python -m benchmarks pipeline`).", ""]
    lines.append(
        "`osnerf run --channel rayleigh --snr-db 0 --seed N` (the demo) with each variant's "
        "flags; object PSNR (dB) of each field, jscc minus digital:"
    )
    lines.append("")
    rows = []
    for variant, by_seed in runs.items():
        for seed, doc in by_seed.items():
            rows.append(
                [VARIANT_WORDS[variant], seed, *(_f(_obj(doc, s)) for s in SCHEMES)]
                + [_f(_gap(doc), sign=True), commit_of(doc)]
            )
        if len(by_seed) > 1:
            means = [
                [v for d in by_seed.values() if (v := _obj(d, s)) is not None] for s in SCHEMES
            ]
            gaps = [g for d in by_seed.values() if (g := _gap(d)) is not None]
            rows.append(
                [
                    f"**{VARIANT_WORDS[variant]}, mean**",
                    "",
                    *(_f(mean(m)) if m else "–" for m in means),
                ]
                + [_f(mean(gaps), sign=True) if gaps else "–", ""]
            )
    lines += markdown_table(["variant", "seed", *SCHEMES, "jscc − digital", "commit"], rows)
    lines.append("")
    pairs = {k: v for k, v in ota_pairs(folder).items() if "ota_box" in v}
    if pairs:
        lines.append(
            "The tiny scene over the air (`--scene tiny --channel ota --schemes jscc,digital,gt "
            "--renderer-steps 0`), jscc minus digital with digital sending the whole view and "
            "the box:"
        )
        lines.append("")
        rows = [
            [f"{snr:g} dB", seed, _f(_gap(v.get("ota")), True), _f(_gap(v["ota_box"]), True)]
            for (snr, seed), v in pairs.items()
        ]
        lines += markdown_table(["SNR", "seed", "whole view", "box"], rows)
        lines.append("")
    return lines

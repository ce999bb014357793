"""The SNR-mismatch rows of ``docs/results.md`` and the README's table, from
``bench-results/mismatch.json`` (``python -m benchmarks mismatch``) and its figures under
``bench-results/mismatch/``. A missing file leaves its rows out."""

from __future__ import annotations

from pathlib import Path

from benchmarks.results_common import RESULTS, commit_of, load_json, markdown_table

PARTS = ("panel", "staircase", "estimate", "forecast", "cbr")


def load(folder: Path = RESULTS) -> dict | None:
    """``mismatch.json`` with ``part_commits``: each part's commits, read from the eval-codec
    files beside it (``mismatch_<part>*.json``; a part may be reused from an older commit)."""
    path = folder / "mismatch.json"
    if not path.is_file():
        return None
    doc = load_json(path)
    doc["part_commits"] = {
        part: sorted({commit_of(load_json(f)) for f in folder.glob(f"mismatch_{part}*.json")})
        for part in PARTS
    }
    return doc


def _commits(doc: dict, part: str) -> str:
    return ", ".join(doc.get("part_commits", {}).get(part) or [commit_of(doc)])


def _psnr(r: dict | None) -> str:
    if not r:
        return "–"
    total = r.get("num_images", 0) * r.get("draws", 1)
    lost = r.get("lost_images", 0)
    return f"{r['psnr']:.2f}" + (f" ({lost}/{total} lost)" if lost else "")


def headline_rows(doc: dict | None) -> list[list[str]]:
    """README rows: the panel's jscc and digital (every transmitter at the plan's SNR) at the
    panel's lowest and highest channel SNR."""
    if not doc or "panel" not in doc["results"]:
        return []
    res = doc["results"]
    by = {(r["scheme"], r["snr_db"]): r for r in res["panel"]}
    rows = []
    snrs = sorted({r["snr_db"] for r in res["panel"]})
    for snr in snrs[:1] + snrs[-1:] if len(snrs) > 1 else snrs:
        if ("jscc", snr) not in by or ("digital", snr) not in by:
            continue
        rows.append(
            [
                f"Kodak-{by['jscc', snr]['num_images']}, CBR 1/16, every transmitter planned at "
                f"{res['plan_snr_db']:g} dB, image PSNR",
                f"AWGN {snr:g} dB",
                _psnr(by["jscc", snr]),
                _psnr(by["digital", snr]),
                "ideal " + _psnr(by.get(("ideal", snr))),
                _commits(doc, "panel"),
            ]
        )
    return rows


def section(doc: dict | None, folder: Path = RESULTS) -> list[str]:
    """The section from ``mismatch.json`` (``doc``, None when missing), its figures in
    ``folder``."""
    lines = ["## When the transmitter's SNR is wrong", ""]
    if not doc:
        return lines + [
            "No `mismatch.json` in bench-results/ (`python -m benchmarks mismatch`).",
            "",
        ]
    res = doc["results"]
    counts = {
        part: sorted({r["num_images"] for r in rows})
        for part, rows in (
            ("panel", res.get("panel", [])),
            ("staircase", res.get("staircase", [])),
            ("estimate", res.get("estimate", [])),
            ("forecast", res.get("forecast", {}).get("rows", [])),
            ("cbr", res.get("cbr_sweep", [])),
        )
        if rows
    }
    told = ", ".join(f"{p} {'/'.join(map(str, n))} ({_commits(doc, p)})" for p, n in counts.items())
    lines.append(
        f"`python -m benchmarks mismatch`, Kodak images per part (commit): {told}; CBR 1/16 "
        "except in the CBR part. Mean of per-image PSNR (dB); `lost`: images that did not arrive."
    )
    lines.append("")
    if "panel" in res:
        lines += _panel(res)
    if "estimate" in res:
        lines += _estimate(res["estimate"])
    if "forecast" in res:
        lines += _forecast(res["forecast"])
    if "blocks" in res:
        lines += _blocks(res["blocks"])
    if "cbr_sweep" in res:
        lines += _cbr(res["cbr_sweep"])
    for name in res.get("figures", []):
        if (folder / name).is_file():
            lines.append(f"![{Path(name).stem}](../bench-results/{name})")
    return lines + [""]


def _panel(res: dict) -> list[str]:
    """Every transmitter planned at one SNR, and the fixed-MCS staircase, across the truth."""
    from osnerf.plots.rows import is_bound  # loads the scheme tables (torch): only here

    lines = []
    by = {(r["scheme"], r["snr_db"]): r for r in res["panel"]}
    snrs = sorted({r["snr_db"] for r in res["panel"]})
    lines.append(f"### Every transmitter planned at {res['plan_snr_db']:g} dB, AWGN at the truth")
    lines.append("")
    rows = [
        [
            s + (" (bound, true SNR)" if is_bound(s) else ""),
            *(_psnr(by.get((s, x))) for x in snrs),
        ]
        for s in dict.fromkeys(r["scheme"] for r in res["panel"])  # as the benchmark ran them
    ]
    stairs: dict[str, dict] = {}
    for r in res.get("staircase", []):
        stairs.setdefault(r.get("mcs") or "?", {})[r["snr_db"]] = r
    rows += [[f"digital_fixed {m}", *(_psnr(v.get(x)) for x in snrs)] for m, v in stairs.items()]
    lines += markdown_table(["scheme", *(f"{x:g} dB" for x in snrs)], rows)
    lines.append("")
    lines += [f"- {f}" for f in res.get("findings", [])]
    lines.append("")
    return lines


def _estimate(estimate: list[dict]) -> list[str]:
    """Each scheme under a Gaussian error on each image's SNR estimate."""
    errors = sorted({r.get("snr_error_db") or 0.0 for r in estimate} - {0.0})
    told = " / ".join(f"{e:g}" for e in errors) or "no"
    lines = [f"### A {told} dB Gaussian error on each image's SNR estimate", ""]
    rows = []
    for r in estimate:
        err = r.get("snr_error_db") or 0.0
        p5 = f"{r['psnr_p5']:.2f}" if r.get("psnr_p5") is not None else "–"
        ms = f"{r['ms_ssim']:.4f}" if r.get("ms_ssim") is not None else "–"
        rows.append([r["channel"], f"{err:g}", r["scheme"], f"{r['snr_db']:g}", _psnr(r), ms, p5])
    header = ["channel", "error (dB)", "scheme", "SNR (dB)", "PSNR", "MS-SSIM", "5th pct"]
    lines += markdown_table(header, rows)
    lines.append("")
    lines.append(
        "`digital` plans its MCS over the estimate's error; `digital_naive` plans as if the "
        "estimate were exact; jscc is told the same estimate; softcast plans nothing."
    )
    lines.append("")
    return lines


def _forecast(f: dict) -> list[str]:
    """The digital planner's forecast of lost images beside the count."""
    lines = ["### The digital planner's own forecast (AWGN, exact knowledge)", ""]
    rows = [
        [
            f"{r['snr_db']:g}",
            f"{r['forecast_lost_images']:.2f}",
            r["lost_images"],
            r["num_images"],
        ]
        for r in f["rows"]
    ]
    lines += markdown_table(["SNR (dB)", "forecast lost", "lost", "images"], rows)
    lines.append("")
    lines.append(
        f"Over all {f['sends']} sends: {f['forecast_total']:.2f} images forecast lost, "
        f"{f['lost_total']} lost."
    )
    lines.append("")
    return lines


def _blocks(blocks: list[dict]) -> list[str]:
    """Kodak-sized blocks of random payload at the planner's MCS."""
    lines = ["Whole Kodak-sized blocks of random payload at the planner's MCS (AWGN):", ""]
    rows = [
        [
            b["mcs"],
            f"{b['snr_db']:g}",
            b["codewords"],
            f"{b['lost']}/{b['blocks']}",
            f"{b['forecast_loss'] * b['blocks']:.2f}",
        ]
        for b in blocks
    ]
    lines += markdown_table(["MCS", "SNR (dB)", "codewords", "lost", "forecast lost"], rows)
    lines.append("")
    return lines


def _cbr(rows: list[dict]) -> list[str]:
    """Each scheme at each bandwidth ratio, exact knowledge."""
    from osnerf.plots.rows import is_bound  # loads the scheme tables (torch): only here

    snrs = sorted({r["snr_db"] for r in rows})
    told = " / ".join(f"{s:g}" for s in snrs)
    lines = [f"### Quality against the bandwidth ratio (AWGN {told} dB, exact knowledge)", ""]
    cbrs = list(dict.fromkeys(r["cbr"] for r in rows))
    by = {(r["scheme"], r["cbr"]): r for r in rows}
    table = [
        [s + (" (bound)" if is_bound(s) else ""), *(_psnr(by.get((s, c))) for c in cbrs)]
        for s in dict.fromkeys(r["scheme"] for r in rows)
    ]
    lines += markdown_table(["scheme", *(f"CBR {c}" for c in cbrs)], table)
    lines.append("")
    return lines

"""Generate ``docs/results.md`` and the README's results table from ``bench-results/``.

    python -m benchmarks.results            # rewrite both
    python -m benchmarks.results --check    # exit 1 if either is out of date

It reads only what the benchmarks write there: ``osnerf eval-codec`` result files
(``codec_<channel>_separate.json``, ``codec_<channel>_jscc_<sha12>.json``, from
``python -m benchmarks codec``) and ``osnerf run`` reports (``pipeline_demo/report.json``,
``pipeline_tiny_ota_<snr>dB_seed<seed>/report.json``, from ``python -m benchmarks
pipeline``), the moving-drone and view-selection benchmarks (:mod:`benchmarks.results_channels`),
plus the shipped checkpoints' model cards. Every number it prints carries the
commit that made it. A missing file leaves its rows out, never a stale number in; a jscc
result of another checkpoint than the shipped default is not read. A missing
``bench-results/``, a file that is not JSON or a README without its markers is an error
(exit 1, one line naming the file) and nothing is written.
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path
from statistics import mean

from benchmarks import results_channels, results_mismatch, results_variants
from benchmarks.results_codec import (
    CHANNEL_LABELS,
    CODEC_SCHEMES,
    cbr_text,
    codec_results,
    codec_section,
    lost_count,
    psnr_text,
    scheme_label,
    shipped_sha,
)
from benchmarks.results_common import (
    CARDS,
    RESULTS,
    ROOT,
    ResultsError,
    commit_of,
    load_json,
    markdown_table,
)
from common import write_files

README = ROOT / "README.md"
DOC = ROOT / "docs" / "results.md"
BEGIN, END = "<!-- results:begin -->", "<!-- results:end -->"

HEADLINE_SNRS = (-10.0, 1.0, 10.0)
OTA_DIR = re.compile(r"pipeline_tiny_ota_(?P<snr>-?\d+)dB_seed(?P<seed>\d+)$")


# --- loading -------------------------------------------------------------------------------


def run_report(path: Path) -> dict | None:
    return load_json(path) if path.is_file() else None


def ota_reports(folder: Path = RESULTS) -> dict[float, list[dict]]:
    """SNR -> the tiny scene's over-the-air reports, by seed."""
    out: dict[float, list[dict]] = {}
    for d in sorted(folder.glob("pipeline_tiny_ota_*")):
        m = OTA_DIR.match(d.name)
        doc = run_report(d / "report.json")
        if m and doc:
            out.setdefault(float(m["snr"]), []).append(doc)
    return {k: sorted(v, key=lambda d: d["seed"]) for k, v in sorted(out.items(), reverse=True)}


def cards(folder: Path = CARDS) -> list[tuple[str, dict]]:
    return [
        (p.name.removesuffix(".card.json"), load_json(p))
        for p in sorted(folder.glob("*.card.json"))
    ]


# --- tables --------------------------------------------------------------------------------


def _seeds(docs: list[dict]) -> str:
    seeds = ", ".join(str(d["seed"]) for d in docs)
    return f"seed {seeds}" if len(docs) == 1 else f"mean of seeds {seeds}"


def _lost_of(r: dict) -> str:
    lost = lost_count(r)
    return f" ({lost} of {r['num_images'] * r['draws']} lost)" if lost else ""


def _mean_object(docs: list[dict], scheme: str) -> float | None:
    vals = [d["schemes"][scheme]["psnr_object"] for d in docs if scheme in d["schemes"]]
    return mean(vals) if vals else None


def _views(docs: list[dict]) -> int:
    return docs[0]["schemes"]["digital"]["views_sent"]


def headline(
    codec: dict, demo: dict | None, ota: dict[float, list[dict]], mismatch: dict | None
) -> list[str]:
    """The README's one table: the demo, over the air, the codec against digital, and the
    transmitter planned at a wrong SNR (``mismatch``: ``mismatch.json``, or None)."""
    rows = []
    if demo:
        s = demo["schemes"]
        rows.append(
            [
                "demo: firefighter scene, hydrant, object PSNR of the field",
                f"block Rayleigh {demo['snr_db']:g} dB",
                psnr_text(s.get("jscc", {}).get("psnr_object")),
                psnr_text(s.get("digital", {}).get("psnr_object"))
                + (
                    f" ({lost_count(s.get('digital'))} of {s['digital']['views_sent']} lost)"
                    if "digital" in s
                    else ""
                ),
                "gt " + psnr_text(s.get("gt", {}).get("psnr_object")),
                commit_of(demo),
            ]
        )
    for snr, docs in ota.items():
        lost = [lost_count(d["schemes"].get("digital")) for d in docs if "digital" in d["schemes"]]
        rows.append(
            [
                "over the air: tiny scene, emulated HackRFs, " + _seeds(docs),
                f"{snr:g} dB",
                psnr_text(_mean_object(docs, "jscc")),
                psnr_text(_mean_object(docs, "digital"))
                + (f" ({sum(lost)} of {len(lost) * _views(docs)} lost)" if any(lost) else ""),
                "gt " + psnr_text(_mean_object(docs, "gt")),
                ", ".join(sorted({commit_of(d) for d in docs})),
            ]
        )
    for channel in (c for c in CHANNEL_LABELS if c in codec):
        entry = codec[channel]
        for snr in HEADLINE_SNRS:
            r = {k: entry["rows"].get((k, snr)) for k in CODEC_SCHEMES}
            if not r["jscc"] or not r["digital"]:
                continue
            commits = sorted({commit_of(doc) for _, doc in entry["docs"]})
            rows.append(
                [
                    f"Kodak-{r['jscc']['num_images']}, CBR {cbr_text(r['jscc']['cbr'])}, "
                    "image PSNR",
                    f"{CHANNEL_LABELS.get(channel, channel)} {snr:g} dB",
                    psnr_text(r["jscc"]["psnr"]),
                    psnr_text(r["digital"]["psnr"]) + _lost_of(r["digital"]),
                    "ideal " + psnr_text((r["ideal"] or {}).get("psnr")),
                    ", ".join(commits),
                ]
            )
    rows += results_mismatch.headline_rows(mismatch)
    header = ["experiment", "link", "jscc (dB)", "digital (dB)", "bound (dB)", "commit"]
    return markdown_table(header, rows)


def demo_section(demo: dict | None) -> list[str]:
    lines = ["## End to end: the demo", ""]
    if not demo:
        return lines + ["No `pipeline_demo/report.json` (`python -m benchmarks pipeline`).", ""]
    cfg = demo["config"]
    lines.append(
        f"`osnerf demo` = `osnerf run --channel {cfg['channel']} --snr-db {cfg['snr_db']:g} "
        f"--seed {demo['seed']}` (scene `{cfg['scene']}`, {cfg['nerf_steps']} NeRF steps per "
        f"scheme), commit {commit_of(demo)}. Object PSNR of each scheme's field on the held-out "
        "views (the demanded object's pixels), whole-view PSNR, views that did not arrive:"
    )
    lines.append("")
    rows = []
    for name, s in demo["schemes"].items():
        rows.append(
            [
                scheme_label(name) if s.get("bound") else name,
                psnr_text(s["psnr_object"]),
                psnr_text(s["psnr"]),
                f"{s['ssim']:.3f}",
                f"{lost_count(s)} of {s['views_sent']}",
                f"{s['symbols_sent']:,}",
                s["nerf_steps"],
            ]
        )
    lines += markdown_table(
        ["scheme", "object PSNR", "PSNR", "SSIM", "lost", "symbols", "NeRF steps"], rows
    )
    return lines + [""]


def ota_section(ota: dict[float, list[dict]]) -> list[str]:
    lines = ["## Over the air", ""]
    if not ota:
        return lines + ["No `pipeline_tiny_ota_*` reports (`python -m benchmarks pipeline`).", ""]
    lines.append(
        "`osnerf run --scene tiny --channel ota --snr-db S --schemes jscc,digital,gt "
        "--renderer-steps 0 --seed N` between two emulated HackRFs (crystal offsets, "
        "multipath); object PSNR of each field:"
    )
    lines.append("")
    rows = []
    for snr, docs in ota.items():
        for d in docs:
            s = d["schemes"]
            dig = s.get("digital")
            rows.append(
                [
                    f"{snr:g} dB",
                    d["seed"],
                    psnr_text(s.get("jscc", {}).get("psnr_object")),
                    psnr_text((dig or {}).get("psnr_object"))
                    + (f" ({lost_count(dig)} of {dig['views_sent']} lost)" if dig else ""),
                    psnr_text(s.get("gt", {}).get("psnr_object")),
                    f"{d['link'].get('frames_lost', 0)} of {d['link'].get('frames_sent', 0)}",
                    commit_of(d),
                ]
            )
    lines += markdown_table(
        ["SNR", "seed", "jscc", "digital", "gt (bound)", "frames lost", "commit"], rows
    )
    return lines + [""]


def checkpoint_section(cards_dir: Path = CARDS) -> list[str]:
    lines = ["## Shipped checkpoints", ""]
    rows = []
    for stem, card in cards(cards_dir):
        rows.append(
            [
                f"`semcodec/checkpoints/{stem}.safetensors`",
                f"`{card['name']}`",
                card.get("version", "–"),
                f"`{card['sha256'][:12]}`",
            ]
        )
    lines += markdown_table(["file", "name", "version", "sha256"], rows)
    lines.append("")
    lines.append(
        "`default.safetensors` is what every command uses without `--codec`; the others load "
        "with `--codec PATH`. Each card (`*.card.json`) records its training and its metric."
    )
    return lines + [""]


def render(results: Path | None = None, cards_dir: Path | None = None) -> tuple[str, list[str]]:
    """(docs/results.md, the README's table lines) from ``results`` (default
    ``bench-results/``) and the checkpoints' cards in ``cards_dir``."""
    results = results or RESULTS
    cards_dir = cards_dir or CARDS
    if not results.is_dir():
        raise ResultsError(f"{results} not found: run make bench (or python -m benchmarks NAME)")
    codec = codec_results(results, shipped_sha(cards_dir))
    demo = run_report(results / "pipeline_demo" / "report.json")
    ota = ota_reports(results)
    mismatch = results_mismatch.load(results)
    head = headline(codec, demo, ota, mismatch)
    doc = [
        "# Results",
        "",
        "<!-- generated by `python -m benchmarks.results` from bench-results/; do not edit -->",
        "",
        "Every number here is read from a file the benchmarks wrote under `bench-results/` "
        "(`make bench`, or `python -m benchmarks NAME`); `python -m benchmarks.results` "
        "regenerates this page and the README's table, and a test fails when they drift. "
        "PSNR in dB, peak 1.0; SNR is Es/N0 per complex symbol.",
        "",
        "## Summary",
        "",
        *head,
        "",
        *demo_section(demo),
        *ota_section(ota),
        *results_variants.section(results),
        *codec_section(codec),
        *results_mismatch.section(mismatch, results),
        *results_channels.sections(results),
        *checkpoint_section(cards_dir),
    ]
    return "\n".join(doc).rstrip() + "\n", head


def readme_with(table: list[str], text: str, path: Path | str = "README.md") -> str:
    """``text`` (the README at ``path``) with ``table`` between its markers."""
    if text.count(BEGIN) != 1 or text.count(END) != 1 or text.index(BEGIN) > text.index(END):
        raise ResultsError(f"{path} has no {BEGIN} ... {END} block (once each, in that order)")
    before, rest = text.split(BEGIN, 1)
    _, after = rest.split(END, 1)
    return before + BEGIN + "\n" + "\n".join(table) + "\n" + END + after


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.results", description=__doc__)
    parser.add_argument("--check", action="store_true", help="exit 1 if a file is out of date")
    args = parser.parse_args(argv)
    try:
        doc, table = render()
        if not README.is_file():
            raise ResultsError(f"{README} not found")
        readme = readme_with(table, README.read_text(), README)
    except ResultsError as e:
        print(f"python -m benchmarks.results: error: {e}", file=sys.stderr)
        return 1
    except (KeyError, TypeError, IndexError) as e:  # a file of another shape than expected
        print(
            f"python -m benchmarks.results: error: a file in {RESULTS} lacks what the pages "
            f"read ({type(e).__name__}: {e}); rerun its benchmark",
            file=sys.stderr,
        )
        return 1
    stale = [
        p for p, text in ((DOC, doc), (README, readme)) if not p.is_file() or p.read_text() != text
    ]
    if args.check:
        for p in stale:
            print(
                f"{p.relative_to(ROOT)} is out of date: run python -m benchmarks.results",
                file=sys.stderr,
            )
        return 1 if stale else 0
    write_files({DOC: doc.encode(), README: readme.encode()})  # both or neither
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Figures from sweep results files and ``osnerf eval-codec`` result files: BER vs SNR with
theory, quality (PSNR, SSIM, MS-SSIM, ...) vs SNR per scheme (with published anchors), PSNR vs
CBR, the digital baseline's staircase and envelope (PSNR and MS-SSIM), the SNR-mismatch panel
(every transmitter planned at one SNR, judged across the channel's), and the outage CDF of
per-image PSNR on block fading. Published numbers are drawn grey and labelled
"anchor: ... published": they were not measured here.

Pure functions: ``osnerf.results.result_rows`` flattens records into rows, each ``plot_*`` function
takes rows and returns a ``matplotlib.figure.Figure`` (no pyplot state), :func:`make_plots`
writes every figure the rows support as PNG and PDF. Values averaged over seeds are the mean
(error bars: one standard deviation across seeds). PSNR/SSIM are the mean of per-image
values, as the commands report them.
"""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from matplotlib.figure import Figure

from common import write_figure
from osnerf.anchors import KODAK, KODAK_AWGN_10DB_VS_CBR, KODAK_CBR, capacity_anchor
from osnerf.report import QUALITY_METRICS
from osnerf.results import result_rows, scheme_entry
from semcodec.links import DIGITAL

CLIFF_SLOPE = 3.0  # dB of PSNR per dB of SNR: steeper than any graceful (JSCC-like) curve


# --- rows -----------------------------------------------------------------------------------


def _finite(v: Any) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)


def _mean_std(rows: list[dict], x: str, y: str) -> tuple[list[float], list[float], list[float]]:
    """Group by x; mean and std of y over the group (seeds); sorted by x."""
    groups: dict[float, list[float]] = defaultdict(list)
    for r in rows:
        if _finite(r.get(x)) and _finite(r.get(y)):
            groups[float(r[x])].append(float(r[y]))
    xs = sorted(groups)
    means = [sum(groups[v]) / len(groups[v]) for v in xs]
    stds = [
        math.sqrt(sum((g - m) ** 2 for g in groups[v]) / len(groups[v])) for v, m in zip(xs, means)
    ]
    return xs, means, stds


def _series(rows: list[dict], keys: tuple[str, ...]) -> dict[tuple, list[dict]]:
    out: dict[tuple, list[dict]] = defaultdict(list)
    for r in rows:
        out[tuple(r.get(k) for k in keys)].append(r)
    return dict(sorted(out.items(), key=lambda kv: tuple(str(v) for v in kv[0])))


def _varying(rows: list[dict], keys: Iterable[str]) -> tuple[str, ...]:
    """The keys whose value differs between rows (what a legend must tell apart)."""
    return tuple(k for k in keys if len({str(r.get(k)) for r in rows}) > 1)


def _label(keys: tuple[str, ...], values: tuple) -> str:
    parts = []
    for k, v in zip(keys, values):
        if v is None:
            continue
        if k == "cbr" and _finite(v) and v > 0:
            parts.append(f"CBR 1/{1 / v:.3g}")
        elif k == "snr_db" and _finite(v):
            parts.append(f"{v:g} dB")
        elif k == "scheme" and _is_bound(v):
            parts.append(f"{v} (bound)")
        else:
            parts.append(str(v))
    return ", ".join(parts) or "result"


def _is_bound(scheme) -> bool:
    """Whether a scheme is a bound, not a system (by its table entry, :func:`scheme_entry`)."""
    entry = scheme_entry({"scheme": scheme})
    return bool(entry is not None and entry.bound)


def _ber_row_is_pooled(rows: list[dict]) -> bool:
    return all(_finite(r.get("num_errors")) and _finite(r.get("num_bits")) for r in rows)


LEGEND_INSIDE_MAX = 8
"""Legends of more entries go beside the axes, where they cover no curve."""


def _legend(ax) -> None:
    n = len(ax.get_legend_handles_labels()[1])
    if n > LEGEND_INSIDE_MAX:
        fig = ax.figure
        w, h = fig.get_size_inches()
        fig.set_size_inches(w + 4.2, max(h, 0.16 * n + 1.0))
        ax.legend(fontsize=6.5, loc="upper left", bbox_to_anchor=(1.02, 1.0))
    else:
        ax.legend(fontsize=7)


def _mean_line(ax, xs, ys, sd, color, label):
    """The mean as a labelled line with markers; one std across seeds as error bars."""
    ax.plot(xs, ys, marker="o", ms=4, color=color, label=label)
    if any(sd):
        ax.errorbar(xs, ys, yerr=sd, fmt="none", ecolor=color, capsize=2)


# --- figures --------------------------------------------------------------------------------


def plot_ber(rows: list[dict], theory: bool = True) -> Figure:
    """BER vs SNR (Es/N0) per (channel, modulation), markers; theory curves as lines.

    Seeds are pooled (errors / bits) when the rows carry ``num_errors`` and ``num_bits``.
    Theory comes from ``phy.ber_theory`` on a fine grid when available, else from the rows'
    ``ber_theory``.
    """
    rows = [r for r in rows if _finite(r.get("ber")) and _finite(r.get("snr_db"))]
    if not rows:
        raise ValueError("no BER rows (rows with 'ber' and 'snr_db')")
    fig = Figure(figsize=(6.4, 4.6), layout="constrained")
    ax = fig.add_subplot()
    keys = ("channel", "modulation")
    for i, (values, group) in enumerate(_series(rows, keys).items()):
        color = f"C{i % 10}"
        label = _label(keys, values)
        if _ber_row_is_pooled(group):
            errs: dict[float, list[float]] = defaultdict(lambda: [0.0, 0.0])
            for r in group:
                errs[r["snr_db"]][0] += r["num_errors"]
                errs[r["snr_db"]][1] += r["num_bits"]
            xs = sorted(errs)
            ys = [errs[x][0] / errs[x][1] for x in xs]
        else:
            xs, ys, _ = _mean_std(group, "snr_db", "ber")
        pos = [(x, y) for x, y in zip(xs, ys) if y > 0]
        if pos:
            ax.semilogy(*zip(*pos), "o", color=color, label=f"{label} (sim.)")
        if theory:
            tx, ty = _ber_theory_curve(values[1], values[0], min(xs), max(xs), group)
            if tx:
                ax.semilogy(tx, ty, "-", color=color, lw=1.2, label=f"{label} (theory)")
    ax.set_xlabel("SNR Es/N0 per complex symbol [dB]")
    ax.set_ylabel("bit error rate")
    ax.grid(True, which="both", alpha=0.3)
    _legend(ax)
    ax.set_title("Uncoded BER vs SNR")
    return fig


def _ber_theory_curve(modulation, channel, lo, hi, group) -> tuple[list[float], list[float]]:
    try:
        import numpy as np

        try:
            from phy import ber_theory
        except ImportError:  # before phy re-exports it
            from phy import ber_theory

        grid = np.linspace(lo, hi, 61)
        ys = np.asarray(
            ber_theory(str(modulation), grid, channel=str(channel)), dtype=float
        ).ravel()
        keep = ys > 0
        return list(grid[keep]), list(ys[keep])
    except (ImportError, AttributeError, KeyError, ValueError, TypeError):
        xs, ys, _ = _mean_std(group, "snr_db", "ber_theory")
        return [x for x, y in zip(xs, ys) if y > 0], [y for y in ys if y > 0]


def plot_quality_vs_snr(
    rows: list[dict], metric: str = "psnr", anchors: bool = True, data_dir: Path | None = None
) -> Figure:
    """``metric`` (psnr, ssim, psnr_object) vs SNR, one line per scheme (and per channel, CBR
    or other setting that varies). With ``anchors``, PSNR figures add the published Kodak
    curves for the channels present (CBR 1/16) and, when the shared data has it, codec +
    ideal channel code at the results' CBR."""
    rows = [r for r in rows if _finite(r.get(metric)) and _finite(r.get("snr_db"))]
    if not rows:
        raise ValueError(f"no rows with {metric!r} and 'snr_db'")
    fig = Figure(figsize=(6.8, 4.6), layout="constrained")
    ax = fig.add_subplot()
    keys = ("scheme",) + _varying(
        rows,
        ("channel", "cbr", "image_codec", "mcs", "plan_snr_db", "snr_error_db", "scene", "demand"),
    )
    for i, (values, group) in enumerate(_series(rows, keys).items()):
        xs, ys, sd = _mean_std(group, "snr_db", metric)
        _mean_line(ax, xs, ys, sd, f"C{i % 10}", _label(keys, values))
    if anchors and metric == "psnr":
        _draw_snr_anchors(ax, rows, data_dir)
    ax.set_xlabel("SNR Es/N0 [dB]")
    unit = " [dB]" if metric.startswith("psnr") else ""
    ax.set_ylabel(f"{metric.upper().replace('_', ' ')}{unit} (mean per image)")
    ax.grid(True, alpha=0.3)
    _legend(ax)
    ax.set_title(f"{metric.upper().replace('_', ' ')} vs SNR")
    return fig


def _draw_snr_anchors(ax, rows, data_dir):
    """Published Kodak curves for the channels in ``rows``, clipped to their SNR range +- 1 dB."""
    channels = {str(r.get("channel", "awgn")).lower() for r in rows}
    cbrs = {r["cbr"] for r in rows if _finite(r.get("cbr"))}
    snrs = [r["snr_db"] for r in rows]
    lo, hi = min(snrs) - 1.0, max(snrs) + 1.0
    near_1_16 = not cbrs or any(abs(c - KODAK_CBR) / KODAK_CBR < 0.02 for c in cbrs)
    styles = ["--", ":", "-.", (0, (5, 1, 1, 1))]
    curves = []
    if near_1_16:
        for ch in sorted(channels & set(KODAK)):
            for name, pts in KODAK[ch].items():
                curves.append((pts, "0.45", f"anchor: {name} [Kodak, {ch}, CBR 1/16, published]"))
    if "awgn" in channels:
        for c in sorted(cbrs) or [KODAK_CBR]:
            for codec, pts in capacity_anchor(data_dir, cbr=c).items():
                curves.append(
                    (
                        pts,
                        "0.7",
                        f"anchor: {codec} + ideal code [Kodak, awgn, CBR 1/{1 / c:.3g}, published]",
                    )
                )
    for j, (pts, color, label) in enumerate(curves):
        pts = [(x, y) for x, y in pts if lo <= x <= hi]
        if pts:
            marker = "xv^sd+"[j % 6] if len(pts) <= 12 else None  # the published points
            ax.plot(
                *zip(*pts),
                linestyle=styles[j % 4],
                marker=marker,
                ms=4,
                color=color,
                lw=1,
                label=label,
            )


def plot_psnr_vs_cbr(
    rows: list[dict], anchors: bool = True, data_dir: Path | None = None
) -> Figure:
    """PSNR vs CBR, one line per (scheme, SNR, ...); anchors for AWGN at the SNRs present."""
    rows = [r for r in rows if _finite(r.get("psnr")) and _finite(r.get("cbr"))]
    if len({r["cbr"] for r in rows}) < 2:
        raise ValueError("PSNR vs CBR needs rows at two or more CBRs")
    fig = Figure(figsize=(6.8, 4.6), layout="constrained")
    ax = fig.add_subplot()
    keys = ("scheme",) + _varying(rows, ("snr_db", "channel", "image_codec"))
    for i, (values, group) in enumerate(_series(rows, keys).items()):
        xs, ys, sd = _mean_std(group, "cbr", "psnr")
        _mean_line(ax, xs, ys, sd, f"C{i % 10}", _label(keys, values))
    channels = {str(r.get("channel", "awgn")).lower() for r in rows}
    if anchors and channels == {"awgn"}:
        snrs = sorted({r["snr_db"] for r in rows if _finite(r.get("snr_db"))})
        if 10.0 in snrs:
            for name, pts in KODAK_AWGN_10DB_VS_CBR.items():
                ax.plot(
                    *zip(*pts),
                    "--",
                    color="0.45",
                    lw=1,
                    label=f"anchor: {name} [Kodak, awgn, 10 dB, published]",
                )
        for s in snrs:
            for codec, pts in capacity_anchor(data_dir, snr_db=s).items():
                ax.plot(
                    *zip(*pts),
                    ":",
                    color="0.65",
                    lw=1,
                    label=f"anchor: {codec} + ideal code [Kodak, awgn, {s:g} dB, published]",
                )
    ax.set_xscale("log", base=2)
    ax.set_xlabel("CBR (complex symbols per real source value)")
    ax.set_ylabel("PSNR [dB] (mean per image)")
    ax.grid(True, which="both", alpha=0.3)
    _legend(ax)
    ax.set_title("PSNR vs bandwidth ratio")
    return fig


def _is_digital(r: dict) -> bool:
    """By the row's scheme kind (``result_rows`` sets it; else from the scheme tables)."""
    kind = r.get("scheme_kind")
    if kind is None:
        entry = scheme_entry(r)
        kind = entry.kind if entry is not None else None
    return kind == DIGITAL


def plot_digital_cliff(
    rows: list[dict], metric: str = "psnr", anchors: bool = False, data_dir: Path | None = None
) -> Figure:
    """The digital baseline vs SNR: each fixed (modulation, code rate) as a thin line, their
    upper envelope in bold, and the cliff (the steepest drop of each fixed scheme, when
    steeper than ``CLIFF_SLOPE`` in PSNR) shaded.
    The other schemes (jscc, ideal, ...) are drawn thin for reference. ``metric``: psnr or
    ms_ssim (or any row metric); ``anchors`` adds the published PSNR curves."""
    rows = [r for r in rows if _finite(r.get(metric)) and _finite(r.get("snr_db"))]
    digital = [r for r in rows if _is_digital(r)]
    if not digital:
        raise ValueError("no rows of a digital scheme (by the kind in its scheme table)")
    fig = Figure(figsize=(6.8, 4.6), layout="constrained")
    ax = fig.add_subplot()
    keys = ("scheme", "mcs") if any(r.get("mcs") for r in digital) else ("scheme",)
    keys += _varying(digital, ("channel",))
    envelope: dict[float, float] = {}
    for i, (values, group) in enumerate(_series(digital, keys).items()):
        xs, ys, _ = _mean_std(group, "snr_db", metric)
        for x, y in zip(xs, ys):
            envelope[x] = max(envelope.get(x, -math.inf), y)
        ax.plot(
            xs,
            ys,
            "-",
            marker=".",
            lw=0.9,
            color=f"C{i % 10}",
            alpha=0.8,
            label=_label(keys, values),
        )
        if len(xs) >= 2:
            # steepest rise with SNR (dB PSNR per dB SNR) = where it falls off the cliff below
            slope, k = max(
                ((ys[k + 1] - ys[k]) / (xs[k + 1] - xs[k]), k) for k in range(len(xs) - 1)
            )
            if slope > (CLIFF_SLOPE if metric == "psnr" else CLIFF_SLOPE / 30):
                ax.axvspan(xs[k], xs[k + 1], color=f"C{i % 10}", alpha=0.08)
    ex = sorted(envelope)
    ax.plot(ex, [envelope[x] for x in ex], "k-", lw=2.2, label="digital envelope (best per SNR)")
    other_keys = ("scheme",) + _varying(rows, ("channel",))
    others = _series([r for r in rows if not _is_digital(r)], other_keys)
    for j, (values, group) in enumerate(others.items()):
        xs, ys, _ = _mean_std(group, "snr_db", metric)
        ax.plot(
            xs,
            ys,
            ("--", ":", "-.")[j % 3],
            lw=1.2,
            color=f"C{(9 - j) % 10}",
            label=f"{_label(other_keys, values)} (reference)",
        )
    if anchors and metric == "psnr":
        _draw_snr_anchors(ax, rows, data_dir)
    ax.set_xlabel("SNR Es/N0 [dB]")
    name = "PSNR [dB]" if metric == "psnr" else metric.upper().replace("_", "-")
    ax.set_ylabel(f"{name} (mean per image)")
    ax.grid(True, alpha=0.3)
    _legend(ax)
    ax.set_title("Digital baseline: the cliff (shaded: steepest drop of each scheme)")
    return fig


def plot_mismatch(rows: list[dict], metric: str = "psnr") -> Figure:
    """The SNR-mismatch panel: every transmitter planned at one SNR (rows with
    ``plan_snr_db``), ``metric`` against the channel's true SNR, one line per scheme; bounds
    dashed; digital's fixed MCSs (rows of a fixed-MCS digital scheme, which plans nothing)
    thin grey behind; the plan marked."""
    rows = [r for r in rows if _finite(r.get(metric)) and _finite(r.get("snr_db"))]
    planned = [r for r in rows if _finite(r.get("plan_snr_db"))]
    if not planned:
        raise ValueError("no rows planned at a fixed SNR ('plan_snr_db')")
    plans = sorted({float(r["plan_snr_db"]) for r in planned})
    fig = Figure(figsize=(6.8, 4.6), layout="constrained")
    ax = fig.add_subplot()
    fixed = [r for r in rows if r.get("mcs_choice") == "fixed" and r.get("mcs")]
    for j, (values, group) in enumerate(_series(fixed, ("mcs",)).items()):
        xs, ys, _ = _mean_std(group, "snr_db", metric)
        ax.plot(
            xs,
            ys,
            "-",
            lw=0.8,
            color="0.6",
            alpha=0.8,
            label="digital, fixed MCS" if not j else None,
        )
        if xs:
            ax.annotate(str(values[0]), (xs[-1], ys[-1]), fontsize=5, color="0.45")
    keys = ("scheme",) + _varying(planned, ("plan_snr_db", "channel", "cbr"))
    for i, (values, group) in enumerate(_series(planned, keys).items()):
        xs, ys, sd = _mean_std(group, "snr_db", metric)
        style = "--" if _is_bound(values[0]) else "-"
        ax.plot(xs, ys, style, marker="o", ms=4, color=f"C{i % 10}", label=_label(keys, values))
    for p in plans:
        ax.axvline(p, color="k", ls=":", lw=1)
        ax.annotate(
            f"planned at {p:g} dB",
            (p, ax.get_ylim()[0]),
            fontsize=7,
            rotation=90,
            va="bottom",
            ha="right",
        )
    ax.set_xlabel("channel SNR Es/N0 [dB] (the truth)")
    name = "PSNR [dB]" if metric == "psnr" else metric.upper().replace("_", "-")
    ax.set_ylabel(f"{name} (mean per image)")
    ax.grid(True, alpha=0.3)
    _legend(ax)
    ax.set_title("Transmitters planned at one SNR, judged at the channel's (bounds dashed)")
    return fig


def plot_outage_cdf(entries: list[tuple[str, str, list[float]]]) -> Figure:
    """Empirical CDF of per-image (per draw) PSNR: one panel per (SNR, channel), one line per
    scheme (the same colour in every panel; dashed with an SNR-estimate error): the tail that
    a mean hides (lost images sit at the left).

    Args:
        entries: (panel, line label, values) as :func:`outage_entries` gives them.
    """
    entries = [(p, k, sorted(v)) for p, k, v in entries if v]
    if not entries:
        raise ValueError("no per-image PSNR values")
    panels = list(dict.fromkeys(p for p, _, _ in entries))
    labels = list(dict.fromkeys(k for _, k, _ in entries))
    schemes = list(dict.fromkeys(k.split(",")[0] for k in labels))
    fig = Figure(figsize=(3.4 * len(panels) + 1.8, 3.8), layout="constrained")
    axes = fig.subplots(1, len(panels), sharey=True, squeeze=False)[0]
    for ax, panel in zip(axes, panels):
        for _, label, v in (e for e in entries if e[0] == panel):
            y = [(k + 1) / len(v) for k in range(len(v))]
            color = f"C{schemes.index(label.split(',')[0]) % 10}"
            ls = "--" if "error" in label else "-"
            ax.step(v, y, where="post", color=color, ls=ls, lw=1.2, label=label)
        ax.axhline(0.05, color="0.5", lw=0.8, ls=":")
        ax.axhline(0.10, color="0.5", lw=0.8, ls=":")
        ax.set_title(panel, fontsize=9)
        ax.set_xlabel("PSNR per image and draw [dB]")
        ax.grid(True, alpha=0.3)
    axes[0].set_ylabel("fraction of images at or below")
    handles, names = axes[-1].get_legend_handles_labels()
    axes[-1].legend(handles, names, fontsize=6.5, loc="upper left", bbox_to_anchor=(1.02, 1.0))
    fig.suptitle("Outage on block fading: per-image PSNR CDF (5 % and 10 % dotted)", fontsize=10)
    return fig


BLOCK_FADING_CHANNELS = ("rayleigh", "rician")


def eval_record(doc: dict[str, Any]) -> dict[str, Any]:
    """An ``osnerf eval-codec`` result file as a sweep record (what :func:`make_plots`
    takes): its config, seed and rows; a fixed-MCS digital row gets its ``mcs``."""
    config = doc.get("config") or {}
    results = []
    for r in doc.get("results") or []:
        r = dict(r)
        if r.get("mcs_choice") == "fixed" and "mcs" not in r:
            r["mcs"] = config.get("fixed_mcs")
        results.append(r)
    return {
        "command": "eval-codec",
        "config": config,
        "seed": doc.get("seed"),
        "metrics": {"results": results},
    }


def outage_entries(records: list[dict[str, Any]]) -> list[tuple[str, str, list[float]]]:
    """(panel "SNR, channel", line label "scheme[, error S dB]", per-image-per-draw PSNRs) of
    every eval-codec row on block fading."""
    out = []
    for rec in records:
        channel = str((rec.get("config") or {}).get("channel", ""))
        if channel not in BLOCK_FADING_CHANNELS:
            continue
        for r in (rec.get("metrics") or {}).get("results") or []:
            per = r.get("psnr_per_draw")
            if isinstance(per, list) and r.get("scheme") is not None:
                vals = [float(v) for row in per for v in (row if isinstance(row, list) else [row])]
                label = str(r["scheme"])
                if _finite(r.get("snr_error_db")) and r["snr_error_db"]:
                    label += f", error {r['snr_error_db']:g} dB"
                out.append((f"{float(r['snr_db']):g} dB, {channel}", label, vals))
    return out


# --- all figures ----------------------------------------------------------------------------


def make_plots(
    records: list[dict[str, Any]],
    out_dir: str | Path,
    anchors: bool = True,
    formats: tuple[str, ...] = ("png", "pdf"),
    data_dir: Path | None = None,
) -> list[Path]:
    """Write every figure the records support to ``out_dir`` as ``<name>.<format>``.

    Returns:
        The files written (in order: ber_vs_snr, {psnr,ssim,ms_ssim,lpips,psnr_object}_vs_snr,
        psnr_vs_cbr, digital_cliff, digital_cliff_ms_ssim, mismatch, outage_cdf).
    Raises:
        ValueError: nothing in the records can be plotted.
    """
    bad = sorted(set(formats) - {"png", "pdf", "svg"})
    if bad or not formats:
        raise ValueError(f"--formats must be some of png, pdf, svg; got {','.join(formats)!r}")
    rows = result_rows(records)
    figures: list[tuple[str, Figure]] = []
    if any(_finite(r.get("ber")) for r in rows):
        figures.append(("ber_vs_snr", plot_ber(rows)))
    with_scheme = [r for r in rows if "scheme" in r]
    for metric in QUALITY_METRICS:
        if any(_finite(r.get(metric)) and _finite(r.get("snr_db")) for r in with_scheme):
            figures.append(
                (f"{metric}_vs_snr", plot_quality_vs_snr(with_scheme, metric, anchors, data_dir))
            )
    if (
        len({r["cbr"] for r in with_scheme if _finite(r.get("cbr")) and _finite(r.get("psnr"))})
        >= 2
    ):
        figures.append(("psnr_vs_cbr", plot_psnr_vs_cbr(with_scheme, anchors, data_dir)))
    matched = [r for r in with_scheme if not _finite(r.get("plan_snr_db"))]
    if any(_is_digital(r) and _finite(r.get("psnr")) for r in matched):
        figures.append(("digital_cliff", plot_digital_cliff(matched, "psnr", anchors, data_dir)))
        if any(_is_digital(r) and _finite(r.get("ms_ssim")) for r in matched):
            figures.append(("digital_cliff_ms_ssim", plot_digital_cliff(matched, "ms_ssim")))
    if any(_finite(r.get("plan_snr_db")) and _finite(r.get("psnr")) for r in with_scheme):
        figures.append(("mismatch", plot_mismatch(with_scheme)))
    outage = outage_entries(records)
    if outage:
        figures.append(("outage_cdf", plot_outage_cdf(outage)))
    if not figures:
        keys = sorted({k for r in rows for k in r})
        raise ValueError(
            f"nothing to plot: no 'ber', or 'psnr'/'ssim' with 'scheme' and 'snr_db', in "
            f"the results (fields seen: {keys[:20]})"
        )
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    written = []
    for name, fig in figures:
        for fmt in formats:
            path = out_dir / f"{name}.{fmt}"
            write_figure(path, fig, dpi=150)
            written.append(path)
    return written

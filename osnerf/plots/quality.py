"""Quality (PSNR, SSIM, MS-SSIM, ...) vs SNR per scheme and PSNR vs CBR, with published
anchors drawn grey."""

from __future__ import annotations

from pathlib import Path

from matplotlib.figure import Figure

from osnerf.anchors import KODAK, KODAK_AWGN_10DB_VS_CBR, KODAK_CBR, capacity_anchor
from osnerf.plots.rows import (
    finite_value,
    mean_line,
    mean_std,
    place_legend,
    series_label,
    series_of,
    varying_keys,
)


def plot_quality_vs_snr(
    rows: list[dict], metric: str = "psnr", anchors: bool = True, data_dir: Path | None = None
) -> Figure:
    """``metric`` (psnr, ssim, psnr_object) vs SNR, one line per scheme (and per channel, CBR
    or other setting that varies). With ``anchors``, PSNR figures add the published Kodak
    curves for the channels present (CBR 1/16) and, when the shared data has it, codec +
    ideal channel code at the results' CBR."""
    rows = [r for r in rows if finite_value(r.get(metric)) and finite_value(r.get("snr_db"))]
    if not rows:
        raise ValueError(f"no rows with {metric!r} and 'snr_db'")
    fig = Figure(figsize=(6.8, 4.6), layout="constrained")
    ax = fig.add_subplot()
    keys = ("scheme",) + varying_keys(
        rows,
        ("channel", "cbr", "image_codec", "mcs", "plan_snr_db", "snr_error_db", "scene", "demand"),
    )
    for i, (values, group) in enumerate(series_of(rows, keys).items()):
        xs, ys, sd = mean_std(group, "snr_db", metric)
        mean_line(ax, xs, ys, sd, f"C{i % 10}", series_label(keys, values))
    if anchors and metric == "psnr":
        draw_snr_anchors(ax, rows, data_dir)
    ax.set_xlabel("SNR Es/N0 [dB]")
    unit = " [dB]" if metric.startswith("psnr") else ""
    ax.set_ylabel(f"{metric.upper().replace('_', ' ')}{unit} (mean per image)")
    ax.grid(True, alpha=0.3)
    place_legend(ax)
    ax.set_title(f"{metric.upper().replace('_', ' ')} vs SNR")
    return fig


def draw_snr_anchors(ax, rows, data_dir):
    """Published Kodak curves for the channels in ``rows``, clipped to their SNR range +- 1 dB."""
    channels = {str(r.get("channel", "awgn")).lower() for r in rows}
    cbrs = {r["cbr"] for r in rows if finite_value(r.get("cbr"))}
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
    rows = [r for r in rows if finite_value(r.get("psnr")) and finite_value(r.get("cbr"))]
    if len({r["cbr"] for r in rows}) < 2:
        raise ValueError("PSNR vs CBR needs rows at two or more CBRs")
    fig = Figure(figsize=(6.8, 4.6), layout="constrained")
    ax = fig.add_subplot()
    keys = ("scheme",) + varying_keys(rows, ("snr_db", "channel", "image_codec"))
    for i, (values, group) in enumerate(series_of(rows, keys).items()):
        xs, ys, sd = mean_std(group, "cbr", "psnr")
        mean_line(ax, xs, ys, sd, f"C{i % 10}", series_label(keys, values))
    channels = {str(r.get("channel", "awgn")).lower() for r in rows}
    if anchors and channels == {"awgn"}:
        snrs = sorted({r["snr_db"] for r in rows if finite_value(r.get("snr_db"))})
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
    place_legend(ax)
    ax.set_title("PSNR vs bandwidth ratio")
    return fig

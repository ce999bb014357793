"""The digital baseline's staircase and envelope (PSNR or MS-SSIM)."""

from __future__ import annotations

import math
from pathlib import Path

from matplotlib.figure import Figure

from osnerf.plots.quality import draw_snr_anchors
from osnerf.plots.rows import (
    finite_value,
    is_digital,
    mean_std,
    place_legend,
    series_label,
    series_of,
    varying_keys,
)

CLIFF_SLOPE = 3.0  # dB of PSNR per dB of SNR: steeper than any graceful (JSCC-like) curve


def plot_digital_cliff(
    rows: list[dict], metric: str = "psnr", anchors: bool = False, data_dir: Path | None = None
) -> Figure:
    """The digital baseline vs SNR: each fixed (modulation, code rate) as a thin line, their
    upper envelope in bold, and the cliff (the steepest drop of each fixed scheme, when
    steeper than ``CLIFF_SLOPE`` in PSNR) shaded.
    The other schemes (jscc, ideal, ...) are drawn thin for reference. ``metric``: psnr or
    ms_ssim (or any row metric); ``anchors`` adds the published PSNR curves."""
    rows = [r for r in rows if finite_value(r.get(metric)) and finite_value(r.get("snr_db"))]
    digital = [r for r in rows if is_digital(r)]
    if not digital:
        raise ValueError("no rows of a digital scheme (by the kind in its scheme table)")
    fig = Figure(figsize=(6.8, 4.6), layout="constrained")
    ax = fig.add_subplot()
    keys = ("scheme", "mcs") if any(r.get("mcs") for r in digital) else ("scheme",)
    keys += varying_keys(digital, ("channel",))
    envelope: dict[float, float] = {}
    for i, (values, group) in enumerate(series_of(digital, keys).items()):
        xs, ys, _ = mean_std(group, "snr_db", metric)
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
            label=series_label(keys, values),
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
    other_keys = ("scheme",) + varying_keys(rows, ("channel",))
    others = series_of([r for r in rows if not is_digital(r)], other_keys)
    for j, (values, group) in enumerate(others.items()):
        xs, ys, _ = mean_std(group, "snr_db", metric)
        ax.plot(
            xs,
            ys,
            ("--", ":", "-.")[j % 3],
            lw=1.2,
            color=f"C{(9 - j) % 10}",
            label=f"{series_label(other_keys, values)} (reference)",
        )
    if anchors and metric == "psnr":
        draw_snr_anchors(ax, rows, data_dir)
    ax.set_xlabel("SNR Es/N0 [dB]")
    name = "PSNR [dB]" if metric == "psnr" else metric.upper().replace("_", "-")
    ax.set_ylabel(f"{name} (mean per image)")
    ax.grid(True, alpha=0.3)
    place_legend(ax)
    ax.set_title("Digital baseline: the cliff (shaded: steepest drop of each scheme)")
    return fig

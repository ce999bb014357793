"""The SNR-mismatch panel: every transmitter planned at one SNR, judged across the
channel's."""

from __future__ import annotations

from matplotlib.figure import Figure

from osnerf.plots.rows import (
    finite_value,
    is_bound,
    mean_std,
    place_legend,
    series_label,
    series_of,
    varying_keys,
)


def plot_mismatch(rows: list[dict], metric: str = "psnr") -> Figure:
    """The SNR-mismatch panel: every transmitter planned at one SNR (rows with
    ``plan_snr_db``), ``metric`` against the channel's true SNR, one line per scheme; bounds
    dashed; digital's fixed MCSs (rows of a fixed-MCS digital scheme, which plans nothing)
    thin grey behind; the plan marked."""
    rows = [r for r in rows if finite_value(r.get(metric)) and finite_value(r.get("snr_db"))]
    planned = [r for r in rows if finite_value(r.get("plan_snr_db"))]
    if not planned:
        raise ValueError("no rows planned at a fixed SNR ('plan_snr_db')")
    plans = sorted({float(r["plan_snr_db"]) for r in planned})
    fig = Figure(figsize=(6.8, 4.6), layout="constrained")
    ax = fig.add_subplot()
    fixed = [r for r in rows if r.get("mcs_choice") == "fixed" and r.get("mcs")]
    for j, (values, group) in enumerate(series_of(fixed, ("mcs",)).items()):
        xs, ys, _ = mean_std(group, "snr_db", metric)
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
    keys = ("scheme",) + varying_keys(planned, ("plan_snr_db", "channel", "cbr"))
    for i, (values, group) in enumerate(series_of(planned, keys).items()):
        xs, ys, _ = mean_std(group, "snr_db", metric)
        style = "--" if is_bound(values[0]) else "-"
        ax.plot(
            xs, ys, style, marker="o", ms=4, color=f"C{i % 10}", label=series_label(keys, values)
        )
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
    place_legend(ax)
    ax.set_title("Transmitters planned at one SNR, judged at the channel's (bounds dashed)")
    return fig

"""BER vs SNR, with the theory curves."""

from __future__ import annotations

from collections import defaultdict

from matplotlib.figure import Figure

from osnerf.plots.rows import (
    ber_row_is_pooled,
    finite_value,
    mean_std,
    place_legend,
    series_label,
    series_of,
)
from phy import ber_theory


def plot_ber(rows: list[dict], theory: bool = True) -> Figure:
    """BER vs SNR (Es/N0) per (channel, modulation), markers; theory curves as lines.

    Seeds are pooled (errors / bits) when the rows carry ``num_errors`` and ``num_bits``.
    Theory comes from ``phy.ber_theory`` on a fine grid when available, else from the rows'
    ``ber_theory``.
    """
    rows = [r for r in rows if finite_value(r.get("ber")) and finite_value(r.get("snr_db"))]
    if not rows:
        raise ValueError("no BER rows (rows with 'ber' and 'snr_db')")
    fig = Figure(figsize=(6.4, 4.6), layout="constrained")
    ax = fig.add_subplot()
    keys = ("channel", "modulation")
    for i, (values, group) in enumerate(series_of(rows, keys).items()):
        color = f"C{i % 10}"
        label = series_label(keys, values)
        if ber_row_is_pooled(group):
            errs: dict[float, list[float]] = defaultdict(lambda: [0.0, 0.0])
            for r in group:
                errs[r["snr_db"]][0] += r["num_errors"]
                errs[r["snr_db"]][1] += r["num_bits"]
            xs = sorted(errs)
            ys = [errs[x][0] / errs[x][1] for x in xs]
        else:
            xs, ys, _ = mean_std(group, "snr_db", "ber")
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
    place_legend(ax)
    ax.set_title("Uncoded BER vs SNR")
    return fig


def _ber_theory_curve(modulation, channel, lo, hi, group) -> tuple[list[float], list[float]]:
    try:
        import numpy as np

        grid = np.linspace(lo, hi, 61)
        ys = np.asarray(
            ber_theory(str(modulation), grid, channel=str(channel)), dtype=float
        ).ravel()
        keep = ys > 0
        return list(grid[keep]), list(ys[keep])
    except (ImportError, AttributeError, KeyError, ValueError, TypeError):
        xs, ys, _ = mean_std(group, "snr_db", "ber_theory")
        return [x for x, y in zip(xs, ys) if y > 0], [y for y in ys if y > 0]

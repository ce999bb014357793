"""The outage CDF of per-image PSNR on block fading, from eval-codec records."""

from __future__ import annotations

from typing import Any

from matplotlib.figure import Figure

from osnerf.plots.rows import finite_value


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
                if finite_value(r.get("snr_error_db")) and r["snr_error_db"]:
                    label += f", error {r['snr_error_db']:g} dB"
                out.append((f"{float(r['snr_db']):g} dB, {channel}", label, vals))
    return out

"""Figures from sweep results files and ``osnerf eval-codec`` result files: BER vs SNR with
theory, quality (PSNR, SSIM, MS-SSIM, ...) vs SNR per scheme (with published anchors), PSNR vs
CBR, the digital baseline's staircase and envelope (PSNR and MS-SSIM), the SNR-mismatch panel
(every transmitter planned at one SNR, judged across the channel's), and the outage CDF of
per-image PSNR on block fading. Published numbers are drawn grey and labelled
"anchor: ... published": they were not measured here.

Pure functions: ``osnerf.results.result_rows`` flattens records into rows, each ``plot_*`` function
takes rows and returns a ``matplotlib.figure.Figure`` (no pyplot state), :func:`make_plots`
writes every figure the rows support as PNG and PDF. One module per figure family
(:mod:`osnerf.plots.ber`, ``quality``, ``digital``, ``mismatch``, ``outage``) over the shared
rows, series and legends of :mod:`osnerf.plots.rows`. Values averaged over seeds are the mean
(error bars: one standard deviation across seeds). PSNR/SSIM are the mean of per-image
values, as the commands report them.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from matplotlib.figure import Figure

from common import write_figure
from osnerf.plots.ber import plot_ber
from osnerf.plots.digital import CLIFF_SLOPE, plot_digital_cliff
from osnerf.plots.mismatch import plot_mismatch
from osnerf.plots.outage import BLOCK_FADING_CHANNELS, eval_record, outage_entries, plot_outage_cdf
from osnerf.plots.quality import plot_psnr_vs_cbr, plot_quality_vs_snr
from osnerf.plots.rows import finite_value, is_digital
from osnerf.report import QUALITY_METRICS
from osnerf.results import result_rows

__all__ = [
    "BLOCK_FADING_CHANNELS",
    "CLIFF_SLOPE",
    "eval_record",
    "make_plots",
    "outage_entries",
    "plot_ber",
    "plot_digital_cliff",
    "plot_mismatch",
    "plot_outage_cdf",
    "plot_psnr_vs_cbr",
    "plot_quality_vs_snr",
]


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
    if any(finite_value(r.get("ber")) for r in rows):
        figures.append(("ber_vs_snr", plot_ber(rows)))
    with_scheme = [r for r in rows if "scheme" in r]
    for metric in QUALITY_METRICS:
        if any(finite_value(r.get(metric)) and finite_value(r.get("snr_db")) for r in with_scheme):
            figures.append(
                (f"{metric}_vs_snr", plot_quality_vs_snr(with_scheme, metric, anchors, data_dir))
            )
    if (
        len(
            {
                r["cbr"]
                for r in with_scheme
                if finite_value(r.get("cbr")) and finite_value(r.get("psnr"))
            }
        )
        >= 2
    ):
        figures.append(("psnr_vs_cbr", plot_psnr_vs_cbr(with_scheme, anchors, data_dir)))
    matched = [r for r in with_scheme if not finite_value(r.get("plan_snr_db"))]
    if any(is_digital(r) and finite_value(r.get("psnr")) for r in matched):
        figures.append(("digital_cliff", plot_digital_cliff(matched, "psnr", anchors, data_dir)))
        if any(is_digital(r) and finite_value(r.get("ms_ssim")) for r in matched):
            figures.append(("digital_cliff_ms_ssim", plot_digital_cliff(matched, "ms_ssim")))
    if any(finite_value(r.get("plan_snr_db")) and finite_value(r.get("psnr")) for r in with_scheme):
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

"""Figures from a sweep results file: BER vs SNR with theory, quality vs SNR per scheme (with
published anchors), PSNR vs CBR, and the cliff of the digital baseline.

Pure functions: :func:`result_rows` flattens records into rows, each ``plot_*`` function
takes rows and returns a ``matplotlib.figure.Figure`` (no pyplot state), :func:`make_plots`
writes every figure the rows support as PNG and PDF. Values averaged over seeds are the mean
(error bars: one standard deviation across seeds). PSNR/SSIM are the mean of per-image
values, as the commands report them.
"""

from __future__ import annotations

import csv
import math
from collections import defaultdict
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from matplotlib.figure import Figure

from common import write_figure
from osnerf.report import QUALITY_METRICS  # the run report's metrics

# Published Kodak numbers (../shared/reference/jscc-anchors.md): CBR 1/16, mean per-image PSNR.
# scheme -> [(snr_db, psnr_db)]; "(plot)" values read off published figures, about +-0.3 dB.
_SNRS = (1, 4, 7, 10, 13)
ANCHORS: dict[str, dict[str, list[tuple[float, float]]]] = {
    "awgn": {
        "BPG + 5G LDPC, best MCS (WITT paper)": [
            (2, 29.3),
            (6, 30.2),
            (8, 32.0),
            (10, 33.3),
            (13, 35.5),
        ],
        "Deep JSCC, CNN (WITT paper)": list(zip(_SNRS, (28.2, 29.5, 30.4, 31.5, 32.1))),
        "WITT": list(zip(_SNRS, (29.7, 31.3, 32.6, 33.6, 34.3))),
        "SwinJSCC, one model": list(zip(_SNRS, (29.54, 31.09, 32.27, 33.17, 33.80))),
    },
    # the published Rayleigh results are fast fading with CSI at the receiver (issue #12)
    "rayleigh_fast": {
        "BPG + 5G LDPC, best MCS (WITT paper)": [
            (2.4, 27.9),
            (5.2, 29.3),
            (8.3, 30.3),
            (11.3, 32.0),
        ],
        "Deep JSCC, CNN (WITT paper)": list(zip(_SNRS, (26.7, 27.7, 28.4, 29.2, 29.6))),
        "WITT": list(zip(_SNRS, (28.3, 29.4, 30.3, 30.8, 31.2))),
    },
}
ANCHOR_CBR = 1 / 16
# Kodak, AWGN, SNR 10 dB, across CBR (SwinJSCC re-run): [(cbr, psnr_db)]
ANCHORS_CBR_AWGN_10DB = {
    "SwinJSCC, one model": [
        (1 / 48, 29.04),
        (1 / 24, 31.55),
        (1 / 16, 33.17),
        (1 / 12, 34.41),
        (1 / 8, 36.05),
    ]
}
CAPACITY_CSV = Path("anchors") / "kodak_codec_plus_capacity.csv"  # under the shared data folder
CAPACITY_CODECS = ("BPG444", "VTM")

CLIFF_SLOPE = 3.0  # dB of PSNR per dB of SNR: steeper than any graceful (JSCC-like) curve


# --- rows -----------------------------------------------------------------------------------


def result_rows(records: Iterable[dict[str, Any]]) -> list[dict[str, Any]]:
    """Flatten sweep records into one row per measured entry.

    A row is ``{**config, **point, "seed": ..., **entry}`` where the entries are: each item of
    ``metrics["results"]`` (``ber`` with several SNRs, ``eval-codec``), each scheme of
    ``metrics["schemes"]`` (``run``, with ``"scheme": name``), else ``metrics`` itself;
    nested dicts become dotted keys (``seconds.nerf``), lists are left out.
    Later keys win, so an entry's own ``snr_db`` overrides the config's list of SNRs.
    """
    rows = []
    for r in records:
        base = {k: v for k, v in (r.get("config") or {}).items() if not isinstance(v, dict | list)}
        base.update(r.get("point") or {})
        base["seed"] = r.get("seed")
        if r.get("command"):
            base["command"] = r["command"]
        m = r.get("metrics") or {}
        if isinstance(m.get("results"), list):
            rows += [{**base, **_flat(e)} for e in m["results"] if isinstance(e, dict)]
        elif isinstance(m.get("schemes"), dict):
            schemes = m["schemes"].items()
            rows += [{**base, "scheme": k, **_flat(v)} for k, v in schemes if isinstance(v, dict)]
        else:
            rows.append({**base, **_flat(m)})
    for row in rows:
        for k in ("snr_db", "cbr"):
            if k in row:
                row[k] = _number(row[k])
        if "mcs" in row or "fixed_mcs" in row:
            row["mcs"] = _mcs_of(row)
    return rows


def _mcs_of(row: dict[str, Any]) -> str | None:
    """The fixed MCS a row's scheme used, or None (not digital, or the envelope).

    ``eval-codec``'s ``--mcs`` sets only its ``digital_fixed`` scheme (config ``fixed_mcs``);
    ``run``'s ``--mcs`` sets its ``digital`` scheme (``envelope`` or a fixed MCS).
    """
    scheme = str(row.get("scheme", ""))
    if not scheme.startswith("digital"):
        return None
    if "fixed" in scheme:
        return row.get("mcs") or row.get("fixed_mcs")
    if row.get("command") == "eval-codec":
        return None
    m = row.get("mcs")
    return None if m in (None, "envelope") else str(m)


def _flat(d: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    """Nested dicts as dotted keys (``{"seconds": {"nerf": 1}}`` -> ``{"seconds.nerf": 1}``);
    lists are left out."""
    out: dict[str, Any] = {}
    for k, v in d.items():
        if isinstance(v, dict):
            out.update(_flat(v, f"{prefix}{k}."))
        elif not isinstance(v, list):
            out[f"{prefix}{k}"] = v
    return out


def _number(v: Any) -> float | Any:
    if isinstance(v, str) and "/" in v:
        num, _, den = v.partition("/")
        try:
            return float(num) / float(den)
        except (ValueError, ZeroDivisionError):
            return v
    try:
        return float(v)
    except (TypeError, ValueError):
        return v


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
    """Whether a link-level scheme is a bound, not a system (``semcodec.evaluation.SCHEMES``)."""
    from semcodec.evaluation import SCHEMES

    s = SCHEMES.get(str(scheme))
    return bool(s and s.bound)


def _ber_row_is_pooled(rows: list[dict]) -> bool:
    return all(_finite(r.get("num_errors")) and _finite(r.get("num_bits")) for r in rows)


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
    ax.legend(fontsize=7)
    ax.set_title("Uncoded BER vs SNR")
    return fig


def _ber_theory_curve(modulation, channel, lo, hi, group) -> tuple[list[float], list[float]]:
    try:
        import numpy as np

        try:
            from phy import ber_theory
        except ImportError:  # before phy re-exports it
            from phy.theory import ber_theory

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
    keys = ("scheme",) + _varying(rows, ("channel", "cbr", "image_codec", "mcs", "scene", "demand"))
    for i, (values, group) in enumerate(_series(rows, keys).items()):
        xs, ys, sd = _mean_std(group, "snr_db", metric)
        _mean_line(ax, xs, ys, sd, f"C{i % 10}", _label(keys, values))
    if anchors and metric == "psnr":
        _draw_snr_anchors(ax, rows, data_dir)
    ax.set_xlabel("SNR Es/N0 [dB]")
    unit = " [dB]" if metric.startswith("psnr") else ""
    ax.set_ylabel(f"{metric.upper().replace('_', ' ')}{unit} (mean per image)")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7)
    ax.set_title(f"{metric.upper().replace('_', ' ')} vs SNR")
    return fig


def _draw_snr_anchors(ax, rows, data_dir):
    """Published Kodak curves for the channels in ``rows``, clipped to their SNR range +- 1 dB."""
    channels = {str(r.get("channel", "awgn")).lower() for r in rows}
    cbrs = {r["cbr"] for r in rows if _finite(r.get("cbr"))}
    snrs = [r["snr_db"] for r in rows]
    lo, hi = min(snrs) - 1.0, max(snrs) + 1.0
    near_1_16 = not cbrs or any(abs(c - ANCHOR_CBR) / ANCHOR_CBR < 0.02 for c in cbrs)
    styles = ["--", ":", "-.", (0, (5, 1, 1, 1))]
    curves = []
    if near_1_16:
        for ch in sorted(channels & set(ANCHORS)):
            for name, pts in ANCHORS[ch].items():
                curves.append((pts, "0.45", f"anchor: {name} [Kodak, {ch}, CBR 1/16]"))
    if "awgn" in channels:
        for c in sorted(cbrs) or [ANCHOR_CBR]:
            for codec, pts in _capacity_anchor(data_dir, cbr=c).items():
                curves.append(
                    (pts, "0.7", f"anchor: {codec} + ideal code [Kodak, awgn, CBR 1/{1 / c:.3g}]")
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


def _capacity_anchor(
    data_dir: Path | None, cbr: float | None = None, snr_db: float | None = None
) -> dict[str, list[tuple[float, float]]]:
    """Codec + ideal channel code (Kodak, AWGN) from the shared CSV: vs SNR at ``cbr`` (within
    2 %) or vs CBR at ``snr_db``. Empty when the file is not there."""
    if data_dir is None:
        from osnerf.paths import shared_data_dir

        data_dir = shared_data_dir()
    path = Path(data_dir) / CAPACITY_CSV
    if not path.is_file():
        return {}
    out: dict[str, list[tuple[float, float]]] = defaultdict(list)
    with open(path, newline="") as f:
        for row in csv.DictReader(f):
            c, s = float(row["cbr_complex_per_dim"]), float(row["snr_db"])
            for codec in CAPACITY_CODECS:
                v = float(row[codec])
                if not math.isfinite(v):
                    continue
                if cbr is not None and abs(c - cbr) / cbr < 0.02:
                    out[codec].append((s, v))
                elif snr_db is not None and abs(s - snr_db) < 1e-6:
                    out[codec].append((c, v))
    return {k: sorted(v) for k, v in out.items()}


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
            for name, pts in ANCHORS_CBR_AWGN_10DB.items():
                ax.plot(
                    *zip(*pts),
                    "--",
                    color="0.45",
                    lw=1,
                    label=f"anchor: {name} [Kodak, awgn, 10 dB]",
                )
        for s in snrs:
            for codec, pts in _capacity_anchor(data_dir, snr_db=s).items():
                ax.plot(
                    *zip(*pts),
                    ":",
                    color="0.65",
                    lw=1,
                    label=f"anchor: {codec} + ideal code [Kodak, awgn, {s:g} dB]",
                )
    ax.set_xscale("log", base=2)
    ax.set_xlabel("CBR (complex symbols per real source value)")
    ax.set_ylabel("PSNR [dB] (mean per image)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    ax.set_title("PSNR vs bandwidth ratio")
    return fig


def _is_digital(r: dict) -> bool:
    return str(r.get("scheme", "")).startswith("digital")


def plot_digital_cliff(rows: list[dict]) -> Figure:
    """The digital baseline vs SNR: each fixed (modulation, code rate) as a thin line, their
    upper envelope in bold, and the cliff (the steepest drop of each fixed scheme, when
    steeper than ``CLIFF_SLOPE``) shaded.
    The other schemes (jscc, ideal, ...) are drawn thin for reference."""
    rows = [r for r in rows if _finite(r.get("psnr")) and _finite(r.get("snr_db"))]
    digital = [r for r in rows if _is_digital(r)]
    if not digital:
        raise ValueError("no rows of a digital scheme (scheme 'digital...')")
    fig = Figure(figsize=(6.8, 4.6), layout="constrained")
    ax = fig.add_subplot()
    keys = ("scheme", "mcs") if any(r.get("mcs") for r in digital) else ("scheme",)
    envelope: dict[float, float] = {}
    for i, (values, group) in enumerate(_series(digital, keys).items()):
        xs, ys, _ = _mean_std(group, "snr_db", "psnr")
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
            if slope > CLIFF_SLOPE:
                ax.axvspan(xs[k], xs[k + 1], color=f"C{i % 10}", alpha=0.08)
    ex = sorted(envelope)
    ax.plot(ex, [envelope[x] for x in ex], "k-", lw=2.2, label="digital envelope (best per SNR)")
    others = _series([r for r in rows if not _is_digital(r)], ("scheme",))
    for j, (values, group) in enumerate(others.items()):
        xs, ys, _ = _mean_std(group, "snr_db", "psnr")
        ax.plot(
            xs,
            ys,
            ("--", ":", "-.")[j % 3],
            lw=1.2,
            color=f"C{(9 - j) % 10}",
            label=f"{values[0]} (reference)",
        )
    ax.set_xlabel("SNR Es/N0 [dB]")
    ax.set_ylabel("PSNR [dB] (mean per image)")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7)
    ax.set_title("Digital baseline: the cliff (shaded: steepest drop of each scheme)")
    return fig


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
        The files written (in order: ber_vs_snr, {psnr,ssim,psnr_object}_vs_snr,
        psnr_vs_cbr, digital_cliff).
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
    if any(_is_digital(r) and _finite(r.get("psnr")) for r in with_scheme):
        figures.append(("digital_cliff", plot_digital_cliff(with_scheme)))
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

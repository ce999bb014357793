"""What every figure shares: rows averaged over seeds, series, labels, legends."""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Iterable
from typing import Any

from osnerf.results import scheme_entry
from semcodec.links import DIGITAL


def finite_value(v: Any) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)


def mean_std(rows: list[dict], x: str, y: str) -> tuple[list[float], list[float], list[float]]:
    """Group by x; mean and std of y over the group (seeds); sorted by x."""
    groups: dict[float, list[float]] = defaultdict(list)
    for r in rows:
        if finite_value(r.get(x)) and finite_value(r.get(y)):
            groups[float(r[x])].append(float(r[y]))
    xs = sorted(groups)
    means = [sum(groups[v]) / len(groups[v]) for v in xs]
    stds = [
        math.sqrt(sum((g - m) ** 2 for g in groups[v]) / len(groups[v])) for v, m in zip(xs, means)
    ]
    return xs, means, stds


def series_of(rows: list[dict], keys: tuple[str, ...]) -> dict[tuple, list[dict]]:
    out: dict[tuple, list[dict]] = defaultdict(list)
    for r in rows:
        out[tuple(r.get(k) for k in keys)].append(r)
    return dict(sorted(out.items(), key=lambda kv: tuple(str(v) for v in kv[0])))


def varying_keys(rows: list[dict], keys: Iterable[str]) -> tuple[str, ...]:
    """The keys whose value differs between rows (what a legend must tell apart)."""
    return tuple(k for k in keys if len({str(r.get(k)) for r in rows}) > 1)


def series_label(keys: tuple[str, ...], values: tuple) -> str:
    parts = []
    for k, v in zip(keys, values):
        if v is None:
            continue
        if k == "cbr" and finite_value(v) and v > 0:
            parts.append(f"CBR 1/{1 / v:.3g}")
        elif k == "snr_db" and finite_value(v):
            parts.append(f"{v:g} dB")
        elif k == "scheme" and is_bound(v):
            parts.append(f"{v} (bound)")
        else:
            parts.append(str(v))
    return ", ".join(parts) or "result"


def is_bound(scheme) -> bool:
    """Whether a scheme is a bound, not a system (by its table entry, :func:`scheme_entry`)."""
    entry = scheme_entry({"scheme": scheme})
    return bool(entry is not None and entry.bound)


def ber_row_is_pooled(rows: list[dict]) -> bool:
    return all(finite_value(r.get("num_errors")) and finite_value(r.get("num_bits")) for r in rows)


LEGEND_INSIDE_MAX = 8
"""Legends of more entries go beside the axes, where they cover no curve."""


def place_legend(ax) -> None:
    n = len(ax.get_legend_handles_labels()[1])
    if n > LEGEND_INSIDE_MAX:
        fig = ax.figure
        w, h = fig.get_size_inches()
        fig.set_size_inches(w + 4.2, max(h, 0.16 * n + 1.0))
        ax.legend(fontsize=6.5, loc="upper left", bbox_to_anchor=(1.02, 1.0))
    else:
        ax.legend(fontsize=7)


def mean_line(ax, xs, ys, sd, color, label):
    """The mean as a labelled line with markers; one std across seeds as error bars."""
    ax.plot(xs, ys, marker="o", ms=4, color=color, label=label)
    if any(sd):
        ax.errorbar(xs, ys, yerr=sd, fmt="none", ecolor=color, capsize=2)


def is_digital(r: dict) -> bool:
    """By the row's scheme kind (``result_rows`` sets it; else from the scheme tables)."""
    kind = r.get("scheme_kind")
    if kind is None:
        entry = scheme_entry(r)
        kind = entry.kind if entry is not None else None
    return kind == DIGITAL

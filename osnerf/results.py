"""Result records (one JSON object per sweep point, or a command's result file) as flat
rows: what plots and tables group and average.

Each row knows its scheme's kind from the scheme tables (:func:`scheme_entry`), never from
the scheme's name.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from osnerf.schemes import SCHEMES
from semcodec import LINK_SCHEMES
from semcodec.links import DIGITAL


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
        entry = scheme_entry(row)
        if entry is not None:
            row["scheme_kind"] = entry.kind
        if "mcs" in row or "fixed_mcs" in row:
            row["mcs"] = _mcs_of(row, entry)
    return rows


def scheme_entry(row: dict[str, Any]):
    """The table entry of a row's scheme: ``semcodec.LINK_SCHEMES`` for the link-level
    commands (``eval-codec``, ``ota``), ``osnerf.schemes.SCHEMES`` for ``run``; a row
    without a command is looked up in both (the names they share have the same kind)."""
    name = row.get("scheme")
    if name is None:
        return None
    tables = {"run": [SCHEMES], "eval-codec": [LINK_SCHEMES], "ota": [LINK_SCHEMES]}
    chosen = tables.get(row.get("command"), [LINK_SCHEMES, SCHEMES])
    return next((t[str(name)] for t in chosen if str(name) in t), None)


def _mcs_of(row: dict[str, Any], entry) -> str | None:
    """The fixed MCS a row's digital scheme used, or None (not digital, or an MCS chosen
    per SNR or per draw).

    ``eval-codec``'s ``--mcs`` sets only its fixed-MCS scheme (config ``fixed_mcs``);
    ``run``'s ``--mcs`` sets its ``digital`` scheme (``auto`` or a fixed MCS).
    """
    if entry is None or entry.kind != DIGITAL or entry.bound:
        return None
    choice = getattr(entry, "mcs", None)
    if choice == "fixed":
        return row.get("mcs") or row.get("fixed_mcs")
    if choice is not None:  # a link-level scheme that picks its own MCS
        return None
    m = row.get("mcs")
    return None if m in (None, "auto", "genie") else str(m)


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

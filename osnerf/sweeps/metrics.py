"""Where a command writes its JSON result and which part of it is a sweep point's metrics.

One rule per command (one registry). The rules:

* ``ber`` (``--out FILE``): with one SNR per point, the single entry of ``results``
  (``{"snr_db", "ber", "ber_theory", "num_bits", "num_errors", ...}``); with several SNRs
  in one point, ``{"results": [...]}``.
* ``eval-codec`` (``--out FILE``): ``{"results": [...], "checkpoint": {...}}``: every
  (scheme, snr_db, cbr) entry of the command's ``results``.
* ``train-nerf`` (``--out RUN_DIR``, reads ``RUN_DIR/metrics.json``): the ``test`` dict plus
  ``train_seconds`` and ``steps``.
* ``run`` (``--out RUN_DIR``, reads ``RUN_DIR/report.json``): ``{"schemes": {...}}``: the
  per-scheme dicts of the report.
* any other command (``--out FILE``): the result JSON without its header
  (``config``, ``seed``, ``git_commit``, ``versions``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from common import Registry
from osnerf.report import Report

HEADER_KEYS = ("config", "seed", "git_commit", "versions")


@dataclass(frozen=True)
class MetricRule:
    """How to find and read one command's result.

    Attributes:
        out_kind: "file" when ``--out`` names the JSON file, "dir" when it names a folder.
        json_name: for ``out_kind="dir"``, the JSON file inside the folder.
        extract: result JSON (dict) -> metrics dict; raises KeyError when a field is missing.
    """

    out_kind: str
    extract: Callable[[dict[str, Any]], dict[str, Any]]
    json_name: str | None = None

    def __post_init__(self):
        if self.out_kind not in ("file", "dir"):
            raise ValueError(f"out_kind must be 'file' or 'dir', got {self.out_kind!r}")
        if self.out_kind == "dir" and not self.json_name:
            raise ValueError("json_name is required when out_kind is 'dir'")


def _without_header(result: dict[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in result.items() if k not in HEADER_KEYS}


def _ber(result: dict[str, Any]) -> dict[str, Any]:
    entries = result["results"]
    return dict(entries[0]) if len(entries) == 1 else {"results": list(entries)}


def _eval_codec(result: dict[str, Any]) -> dict[str, Any]:
    out = {"results": list(result["results"])}
    if "checkpoint" in result:
        out["checkpoint"] = result["checkpoint"]
    return out


def _train_nerf(result: dict[str, Any]) -> dict[str, Any]:
    out = dict(result["test"])
    for k in ("train_seconds", "steps"):
        if k in result:
            out[k] = result[k]
    return out


def _run(result: dict[str, Any]) -> dict[str, Any]:
    from dataclasses import asdict

    report = Report.from_dict(result)
    return {"schemes": {n: asdict(s) for n, s in report.schemes.items()}}


DEFAULT_RULE = MetricRule("file", _without_header)

METRIC_RULES = Registry[MetricRule](
    "metric rule",
    {
        "ber": MetricRule("file", _ber),
        "eval-codec": MetricRule("file", _eval_codec),
        "train-nerf": MetricRule("dir", _train_nerf, "metrics.json"),
        "run": MetricRule("dir", _run, "report.json"),
    },
)


def channel_params(result: dict[str, Any]) -> dict[str, Any] | None:
    """What a command's result records of its channel (``phy.channel_record``: the name and,
    for TDL/CDL, the profile and the pinned TR 38.901 ``spec_version``): ``config`` holds it
    for ``ber`` and ``eval-codec``, the report's ``link`` for ``run``; None where neither does."""
    for part in ("config", "link"):
        found = result.get(part)
        if isinstance(found, dict) and isinstance(found.get("channel_params"), dict):
            return found["channel_params"]
    return None


def metric_rule(command: str) -> MetricRule:
    """The rule for ``command`` (the default rule for commands without their own)."""
    return METRIC_RULES.get(command, DEFAULT_RULE)

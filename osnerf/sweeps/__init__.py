"""Sweeps: many independent runs of an osnerf command, resumable, local or on Ray.

``osnerf sweep SPEC --out results.jsonl [--executor local|ray|serial] [--workers N]``.
See :mod:`osnerf.sweeps.spec` for the spec, :mod:`osnerf.sweeps.metrics` for what each
command's point records, :mod:`osnerf.sweeps.store` for the results file.
"""

from osnerf.sweeps.executors import EXECUTORS, execute_point
from osnerf.sweeps.metrics import METRIC_RULES, MetricRule, metric_rule
from osnerf.sweeps.runner import SweepSummary, errors_path, run_sweep
from osnerf.sweeps.spec import Point, SweepSpec, expand, load_spec, point_key, spec_from_dict
from osnerf.sweeps.store import append_record, open_results, read_results

__all__ = [
    "EXECUTORS",
    "METRIC_RULES",
    "MetricRule",
    "Point",
    "SweepSpec",
    "SweepSummary",
    "append_record",
    "errors_path",
    "execute_point",
    "expand",
    "load_spec",
    "metric_rule",
    "open_results",
    "point_key",
    "read_results",
    "run_sweep",
    "spec_from_dict",
]

"""The one way a command times a call: the median wall time of several calls after one that
warms up (allocations, lazy set-ups, caches), so one slow call does not decide."""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable


def median_seconds(fn: Callable[[], object], repeats: int, before=None) -> float:
    """Median wall seconds of ``repeats`` calls of ``fn`` after a first one that is not
    counted; ``before`` (untimed) runs ahead of each call (to clear a cache, say)."""
    times = []
    for _ in range(repeats + 1):
        if before is not None:
            before()
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return float(statistics.median(times[1:]))

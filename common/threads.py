"""Thread pools of the libraries we call, bounded where our own code needs it:
:func:`one_blas_thread`.

numpy's OpenBLAS starts a pool of threads at its first matrix product and leaves them
spinning after each call; on the small products of a receiver they cost more CPU than the
products themselves, and take the cores an SDR driver's or an emulator's threads need. A
receive path bounds the pool to one thread while it runs (threadpoolctl, on the loaded
libraries), whatever the environment says, and gives the user's setting back afterwards.
"""

from __future__ import annotations

import functools
import sys
import threading
from collections.abc import Callable
from typing import TypeVar

F = TypeVar("F", bound=Callable)

_lock = threading.Lock()
_controller = None
_modules_seen = -1  # how many modules were imported when the controller was made
_local = threading.local()


def _blas_controller():
    """threadpoolctl's view of the BLAS libraries loaded now: made again only after more
    modules were imported (one may have brought a library of its own, e.g. scipy's)."""
    global _controller, _modules_seen
    with _lock:
        if _controller is None or len(sys.modules) != _modules_seen:
            from threadpoolctl import ThreadpoolController

            _controller = ThreadpoolController().select(user_api="blas")
            _modules_seen = len(sys.modules)
        return _controller


def one_blas_thread(fn: F) -> F:
    """Run ``fn`` with each loaded BLAS library at one thread (nested calls: once)."""

    @functools.wraps(fn)
    def bounded(*args, **kwargs):
        if getattr(_local, "depth", 0):
            return fn(*args, **kwargs)
        _local.depth = 1
        try:
            with _blas_controller().limit(limits=1):
                return fn(*args, **kwargs)
        finally:
            _local.depth = 0

    return bounded  # type: ignore[return-value]

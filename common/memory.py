"""glibc's heap, tuned for long CPU runs and given back between their stages.

Training steps, renders and receiver calls allocate the same tens of megabytes of
temporaries again and again: :func:`tune_malloc` keeps those blocks in the heap for reuse
instead of mapping and unmapping each one. A run of many mid-sized temporaries (a feature
grid filled chunk by chunk, thousands of training steps) can then leave more than a gigabyte
resident that no tensor holds: :func:`trim_heap` (``malloc_trim(0)``) releases every free
page, and the next allocations that need them pay a page fault per 4 kB, so call it between
stages and every few hundred steps, not every step.

Both are no-ops (returning False) where the C library is not glibc.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
from typing import Literal

_M_TRIM_THRESHOLD = -1  # glibc mallopt parameters (malloc.h)
_M_MMAP_THRESHOLD = -3
_LIBC: ctypes.CDLL | Literal[False] | None = None


def _libc():
    """The C library with glibc's ``mallopt`` and ``malloc_trim``, or False without them."""
    global _LIBC
    if _LIBC is None:
        try:
            libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
            libc.mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
            libc.malloc_trim.argtypes = [ctypes.c_size_t]
            _LIBC = libc
        except (OSError, AttributeError):
            _LIBC = False
    return _LIBC


def tune_malloc(mmap_threshold: int = 32 << 20, trim_threshold: int = 1 << 30) -> bool:
    """Let glibc keep freed memory for the next allocation of the same size.

    With glibc's defaults every block over the (dynamic) mmap threshold is mapped fresh and
    unmapped on free, so each call pays a page fault per 4 kB page (about 3 us each on these
    VMs): 17 % of a lego training step. Blocks up to ``mmap_threshold`` (glibc's maximum,
    32 MB) come from the heap instead, and the heap is returned to the kernel only above
    ``trim_threshold`` of free memory (or by :func:`trim_heap`).

    Off with ``OSNERF_MALLOC_TUNE=0`` (for measuring the difference). Returns whether the
    settings were applied.
    """
    value = os.environ.get("OSNERF_MALLOC_TUNE", "1")
    if value not in ("0", "1"):
        raise ValueError(f"$OSNERF_MALLOC_TUNE must be 0 or 1, got {value!r}")
    libc = _libc()
    if value == "0" or not libc:
        return False
    return bool(
        libc.mallopt(_M_MMAP_THRESHOLD, int(mmap_threshold))
        and libc.mallopt(_M_TRIM_THRESHOLD, int(trim_threshold))
    )


def trim_heap() -> bool:
    """Return the heap's free pages to the kernel; False where nothing was released."""
    libc = _libc()
    return bool(libc and libc.malloc_trim(0))

"""Process-wide settings for long CPU runs."""

from __future__ import annotations

import ctypes
import os

_M_TRIM_THRESHOLD = -1  # glibc mallopt parameters (malloc.h)
_M_MMAP_THRESHOLD = -3


def tune_malloc(mmap_threshold: int = 32 << 20, trim_threshold: int = 1 << 30) -> bool:
    """Let glibc keep freed memory for the next allocation of the same size.

    Training steps, renders and receiver calls allocate the same tens of megabytes of
    temporaries again and again. With glibc's defaults every block over the (dynamic)
    mmap threshold is mapped fresh and unmapped on free, so each call pays a page fault
    per 4 kB page (about 3 us each on these VMs): 17 % of a lego training step. Blocks up
    to ``mmap_threshold`` (glibc's maximum, 32 MB) come from the heap instead, and the heap
    is returned to the kernel only above ``trim_threshold`` of free memory.

    Off with ``OSNERF_MALLOC_TUNE=0`` (for measuring the difference). Returns whether the
    settings were applied (False off glibc).
    """
    value = os.environ.get("OSNERF_MALLOC_TUNE", "1")
    if value not in ("0", "1"):
        raise ValueError(f"$OSNERF_MALLOC_TUNE must be 0 or 1, got {value!r}")
    if value == "0":
        return False
    try:
        libc = ctypes.CDLL("libc.so.6")
        return bool(
            libc.mallopt(_M_MMAP_THRESHOLD, int(mmap_threshold))
            and libc.mallopt(_M_TRIM_THRESHOLD, int(trim_threshold))
        )
    except (OSError, AttributeError):
        return False

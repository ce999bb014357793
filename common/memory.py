"""Give freed heap memory back to the kernel.

glibc keeps freed blocks in its heap for reuse, and a run of many mid-sized temporaries
(a feature grid filled chunk by chunk, thousands of training steps) can leave more than a
gigabyte resident that no tensor holds. :func:`trim_heap` (``malloc_trim(0)``) releases every
free page; the next allocations that need them pay a page fault per 4 kB, so call it
between stages and every few hundred steps, not every step.
"""

from __future__ import annotations

import ctypes
import ctypes.util

_LIBC = None


def trim_heap() -> bool:
    """Return the heap's free pages to the kernel; False where the C library has no
    ``malloc_trim`` (not glibc) or nothing was released."""
    global _LIBC
    if _LIBC is None:
        try:
            _LIBC = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
            _LIBC.malloc_trim.argtypes = [ctypes.c_size_t]
        except (OSError, AttributeError):
            _LIBC = False
    return bool(_LIBC and _LIBC.malloc_trim(0))

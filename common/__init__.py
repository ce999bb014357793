"""common: the few facts every package shares, each decided once.

* ``common.files``: the one atomic writer. Every output file is written beside its target
  and renamed over it, so a reader sees the old file or the new one, never half of one; a
  path that names anything but a regular file (device, FIFO, symlink) is never replaced; a
  failed write (a full disk) raises one ``OSError`` naming the file and leaves nothing behind.
* ``common.images``: the one image loader (8- and 16-bit, grayscale, palette, alpha, EXIF
  orientation) and the one list of image file suffixes.
* ``common.quality``: the one PSNR (peak 1.0) and the one MS-SSIM.
* ``common.memory``: glibc's heap, ``tune_malloc`` for reuse and ``trim_heap`` to give it back.
* ``common.jit``: ``lazy_njit``, the one numba wrapper (numba loaded on a kernel's first call).
* ``common.checks``: ``bound``, a field's range declared once, read by configs and CLIs.
* ``common.timing``: ``median_seconds``, how a command times a call.
* ``common.errors``: ``InputError``, input that cannot be served, wherever it is found.
* ``common.registry``: ``Registry``, the one way a table of named things is declared.
* ``common.threads``: ``one_blas_thread``, a receive path's bound on numpy's BLAS pool.

Imports nothing else of ours, so ``phy``, ``semcodec``, ``renderer``, ``hil`` and ``osnerf``
may all import it.
"""

from common.checks import MAX_BUDGET_S, SEED_RANGE, Bound, bound, bound_of, check_bounds
from common.errors import InputError
from common.files import (
    atomic_path,
    check_replaceable,
    json_default,
    path_kind,
    to_json,
    write_bytes,
    write_figure,
    write_files,
    write_json,
    write_png,
    write_text,
    write_torch,
)
from common.images import (
    IMAGE_SUFFIXES,
    list_images,
    load_square_images,
    read_image,
    to_chw,
    to_hwc,
)
from common.jit import lazy_njit
from common.memory import trim_heap, tune_malloc
from common.plugins import load_plugins
from common.quality import MS_SSIM_MIN_SIDE_PX, PSNR_MAX_DB, ms_ssim, psnr
from common.registry import Registry
from common.threads import one_blas_thread
from common.timing import median_seconds

__all__ = [
    "MAX_BUDGET_S",
    "SEED_RANGE",
    "Bound",
    "bound",
    "bound_of",
    "check_bounds",
    "InputError",
    "one_blas_thread",
    "json_default",
    "lazy_njit",
    "load_plugins",
    "median_seconds",
    "IMAGE_SUFFIXES",
    "PSNR_MAX_DB",
    "MS_SSIM_MIN_SIDE_PX",
    "ms_ssim",
    "Registry",
    "atomic_path",
    "check_replaceable",
    "list_images",
    "load_square_images",
    "path_kind",
    "psnr",
    "read_image",
    "to_chw",
    "to_hwc",
    "to_json",
    "trim_heap",
    "tune_malloc",
    "write_bytes",
    "write_json",
    "write_png",
    "write_text",
    "write_figure",
    "write_files",
    "write_torch",
]

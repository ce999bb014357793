"""The one lazy numba wrapper: a kernel compiled (or loaded from numba's on-disk cache) on its
first call, so importing a package that holds kernels loads no numba, and processes that never
call one (training, rendering) never start its runtime."""

from __future__ import annotations

import functools
from collections.abc import Callable


def lazy_njit(before: Callable | None = None, **options):
    """A decorator: ``numba.njit(**options)`` of the function, applied on its first call.

    Args:
        before: called once with the ``numba`` module just before the first compilation (to
            compile what the kernel calls, say).
        options: numba's ``njit`` options (``cache``, ``nogil``, ``fastmath``, ...).
    """

    def decorate(python_function):
        compiled = None

        @functools.wraps(python_function)
        def kernel(*args):
            nonlocal compiled
            if compiled is None:
                import numba

                if before is not None:
                    before(numba)
                compiled = numba.njit(**options)(python_function)
            return compiled(*args)

        return kernel

    return decorate

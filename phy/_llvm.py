"""Point Dr.Jit (sionna-rt, Mitsuba) at an LLVM it can use, before either is imported.

sionna-rt and Mitsuba's LLVM variants need LLVM >= 16 as a shared library: LLVM 15
crashes ("Cannot select: fmaximum") and LLVM 14 is refused. Debian 12 ships LLVM 19
as ``libllvm19``.
"""

from __future__ import annotations

import glob
import os
import re

_CANDIDATES = (
    "/usr/lib/x86_64-linux-gnu/libLLVM-19.so",
    "/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1",
    "/usr/lib/aarch64-linux-gnu/libLLVM-19.so",
    "/usr/lib/llvm-19/lib/libLLVM-19.so",
    "/usr/lib/llvm-19/lib/libLLVM.so.19.1",
)
MIN_LLVM_MAJOR = 16
INSTALL_HINT = (
    "install LLVM 19 ('sudo apt-get install libllvm19' on Debian 12) or set DRJIT_LIBLLVM_PATH"
)


def _major_version(path: str) -> int | None:
    m = re.search(r"LLVM(?:-|\.so\.)(\d+)", os.path.basename(path))
    return int(m.group(1)) if m else None


def find_llvm() -> str | None:
    """Return the path of a usable libLLVM (major >= 16), or None."""
    found = [p for p in _CANDIDATES if os.path.exists(p)]
    found += sorted(glob.glob("/usr/lib/*/libLLVM-[0-9]*.so"), reverse=True)
    for path in found:
        major = _major_version(path)
        if major is not None and major >= MIN_LLVM_MAJOR:
            return path
    return None


def configure_llvm() -> str | None:
    """Set ``DRJIT_LIBLLVM_PATH`` when unset and a usable LLVM exists. Cheap; safe at import."""
    current = os.environ.get("DRJIT_LIBLLVM_PATH")
    if current:
        return current
    path = find_llvm()
    if path is not None:
        os.environ["DRJIT_LIBLLVM_PATH"] = path
    return path


def require_llvm() -> str:
    """Return the LLVM path for Dr.Jit, or raise RuntimeError saying what to install."""
    path = configure_llvm()
    if not path or not os.path.exists(path):
        raise RuntimeError(
            f"ray tracing and Mitsuba renders need LLVM >= {MIN_LLVM_MAJOR}: {INSTALL_HINT}"
        )
    major = _major_version(path)
    if major is not None and major < MIN_LLVM_MAJOR:
        raise RuntimeError(
            f"DRJIT_LIBLLVM_PATH={path} is LLVM {major}; Dr.Jit needs LLVM >= {MIN_LLVM_MAJOR}: "
            f"{INSTALL_HINT}"
        )
    return path

"""What every result file carries: config, seed, git commit, versions; written atomically."""

from __future__ import annotations

import functools
import os
import platform
import subprocess
from pathlib import Path
from typing import Any

from common import write_json

REPO_ROOT = Path(__file__).resolve().parent.parent


@functools.lru_cache(maxsize=1)
def git_commit() -> str:
    """The checkout's commit (with ``-dirty`` when it has uncommitted changes), or ``unknown``."""
    try:
        sha = subprocess.run(
            ["git", "rev-parse", "HEAD"], cwd=REPO_ROOT, capture_output=True, text=True, timeout=10
        ).stdout.strip()
        if not sha:
            return "unknown"
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no"],
            cwd=REPO_ROOT,
            capture_output=True,
            text=True,
            timeout=10,
        ).stdout.strip()
        return sha + ("-dirty" if dirty else "")
    except (OSError, subprocess.SubprocessError):
        return "unknown"


@functools.lru_cache(maxsize=1)
def versions() -> dict[str, str]:
    """Versions of the libraries results depend on."""
    from importlib import metadata

    from osnerf import __version__

    out = {"python": platform.python_version(), "osnerf": __version__}
    for name in ("torch", "sionna", "numpy"):
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            pass
    return out


def result_header(config: dict[str, Any], seed: int | None) -> dict[str, Any]:
    """The common head of every result file."""
    return {"config": config, "seed": seed, "git_commit": git_commit(), "versions": versions()}


def write_json_atomic(path: str | os.PathLike, obj: Any) -> Path:
    """Write a result as JSON through the project's one atomic writer (:mod:`common.files`)."""
    return write_json(path, obj)

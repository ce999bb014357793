"""What every result file carries: config, seed, git commit, versions, and the codec it used
(:func:`codec_record`); written atomically."""

from __future__ import annotations

import functools
import os
import platform
import subprocess
import sys
from pathlib import Path
from typing import Any

from common import write_json
from osnerf.version import __version__

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


def open_codec(
    spec: str | None, allow_untrained: bool = False, flag: str = "--codec", warn: bool = True
):
    """The codec a command's ``flag`` names (:func:`semcodec.open_codec`): a refusal names
    the flag; an untrained codec only with ``allow_untrained``, then (``warn``) with a
    one-line warning on stderr."""
    import semcodec

    try:
        codec = semcodec.open_codec(spec, allow_untrained=allow_untrained)
    except (KeyError, ValueError, FileNotFoundError) as e:
        msg = e.args[0] if len(e.args) == 1 and isinstance(e.args[0], str) else str(e)
        raise type(e)(f"{flag}: {msg}") from None
    if warn and not semcodec.is_trained(codec):
        name, _ = semcodec.resolve_codec_spec(spec)
        print(
            f"warning: codec {name} is untrained (freshly initialised weights, "
            "--allow-untrained): its results are labelled untrained",
            file=sys.stderr,
        )
    return codec


def codec_record(codec, spec: str | None) -> dict[str, Any]:
    """What a result records of the semantic codec it used, the same in every command.

    Args:
        codec: the opened codec.
        spec: what named it (``--codec``: None, ``NAME[:CHECKPOINT]`` or a checkpoint path).
    Returns:
        ``{"codec": registry name, "name": the codec's own name, "sha256", "checkpoint":
        path or None (its default weights), "trained": False for freshly initialised
        weights, "plugin": {"distribution", "version", "entry_point"} or None (built-in)}``.
    """
    import semcodec

    name, checkpoint = semcodec.resolve_codec_spec(spec)
    return {
        "codec": name,
        "name": codec.name,
        "sha256": codec.sha256,
        "checkpoint": checkpoint,
        "trained": semcodec.is_trained(codec),
        "plugin": semcodec.plugin_origin(name),
    }


def write_json_atomic(path: str | os.PathLike, obj: Any) -> Path:
    """Write a result as JSON through the project's one atomic writer (:mod:`common.files`)."""
    return write_json(path, obj)

"""eval-codec's ``OUT.partial``: the finished (scheme, SNR) points of an interrupted
evaluation, resumed only by the same evaluation.

The partial file names what produced its points (``config``, ``seed``, ``checkpoint``); a
rerun whose arguments differ in any of them is another evaluation: it is refused with the
changed fields named, and only ``--overwrite`` discards the old points. A partial path that
is not a regular file (a folder, a FIFO) is refused before any work.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from common import path_kind
from osnerf.cli import UsageError

IDENTITY = ("config", "seed", "checkpoint")
"""The fields of a partial file that say which evaluation its points belong to."""


def partial_path(out: Path) -> Path:
    """Where a run keeps its finished points until it completes: ``<out>.partial``."""
    return out.with_name(out.name + ".partial")


def check_partial_kind(out: Path) -> None:
    """Refuse an ``OUT.partial`` that exists and is not a regular file (nothing is created).

    Raises:
        UsageError: naming ``--out``, the partial path and what it is.
    """
    partial = partial_path(out)
    kind = path_kind(partial)
    if kind not in (None, "a file"):
        raise UsageError(
            f"--out {str(out)!r}: its partial file {str(partial)!r} is {kind}, not a regular "
            "file; remove it or give another --out"
        )


def changed_fields(old: dict, new: dict) -> list[str]:
    """Names of the identity fields (``config`` keys, ``seed``, ``checkpoint``) that differ."""
    new = json.loads(json.dumps(new))  # the same types as a file read back (tuples as lists)
    changed = []
    for key in IDENTITY:
        a, b = old.get(key), new.get(key)
        if key == "config" and isinstance(a, dict) and isinstance(b, dict):
            changed += [k for k in dict.fromkeys([*b, *a]) if a.get(k) != b.get(k)]
        elif a != b:
            changed.append(key)
    return changed


def resumable(out: Path, identity: dict, overwrite: bool) -> dict:
    """{(scheme, snr_db): row} of an interrupted run of the same evaluation; {} when there is
    none, or when ``overwrite`` and it was another's (then the old partial file is removed).

    Args:
        identity: ``{"config", "seed", "checkpoint"}`` of this run.
    Raises:
        UsageError: the partial file is unreadable, or holds another evaluation's points,
            and ``overwrite`` is not set (nothing is changed).
    """
    partial = partial_path(out)
    check_partial_kind(out)
    if not partial.exists():
        return {}
    try:
        old = json.loads(partial.read_text())
        rows = {(r["scheme"], r["snr_db"]): r for r in old["results"]}
        why = ", ".join(changed_fields(old, identity))
    except (OSError, ValueError, KeyError, TypeError, AttributeError) as e:
        rows, why = {}, f"unreadable: {type(e).__name__}"
    if not why:
        return rows
    what = f"{len(rows)} finished point(s) of another evaluation (changed: {why})"
    if "unreadable" in why:
        what = f"no partial result of eval-codec ({why})"
    if not overwrite:
        raise UsageError(
            f"--out {str(out)!r}: {partial.name} holds {what}; rerun with its arguments to "
            "resume, or give --overwrite to discard it"
        )
    partial.unlink()
    print(f"eval-codec: --overwrite: discarded {partial.name}, which held {what}", file=sys.stderr)
    return {}

"""What every section of ``docs/results.md`` and the README's table shares: where the
benchmarks' files are, how one is read (``ResultsError`` naming a file that cannot be), and
the table and commit cells every section writes alike."""

from __future__ import annotations

import json
from collections.abc import Iterable
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "bench-results"
CARDS = ROOT / "semcodec" / "checkpoints"


class ResultsError(ValueError):
    """A file the pages are made from that cannot be read; the message names it."""


def load_json(path: Path) -> dict:
    """A benchmark's JSON (``ResultsError`` naming the file when it is empty, truncated or not
    an object)."""
    try:
        doc = json.loads(path.read_text())
    except json.JSONDecodeError as e:
        what = "empty" if not path.read_text().strip() else f"not JSON ({e.msg}, line {e.lineno})"
        raise ResultsError(f"{path} is {what}: rerun the benchmark that writes it") from None
    except (OSError, UnicodeDecodeError) as e:
        raise ResultsError(f"{path} cannot be read ({e})") from None
    if not isinstance(doc, dict):
        raise ResultsError(f"{path} holds a {type(doc).__name__}, not a result object")
    return doc


def commit_of(doc: dict) -> str:
    """A result's commit as the tables show it: 7 hex digits, ``-dirty`` kept."""
    sha = doc.get("git_commit", "unknown")
    return sha[:7] + ("-dirty" if sha.endswith("-dirty") else "")


def markdown_table(header: Iterable[str], rows: Iterable[Iterable[object]]) -> list[str]:
    header = list(header)
    out = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    out += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return out

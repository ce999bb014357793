"""The results file of a sweep: JSON Lines, one finished point per line, appended atomically.

Each line is written with one ``os.write`` of the whole line on an ``O_APPEND`` descriptor,
then ``fsync``: a crash leaves at most a partial *last* line, which :func:`open_results`
detects and cuts off (saving the cut bytes beside the file) without touching earlier points.
Only the sweep's driver process writes the file.
"""

from __future__ import annotations

import errno
import json
import os
import sys
from pathlib import Path
from typing import Any

from common import json_default


def _dumps(record: dict[str, Any]) -> str:
    return json.dumps(record, default=json_default, allow_nan=True, separators=(",", ":"))


def read_results(path: str | Path) -> list[dict[str, Any]]:
    """Every complete, valid record of a results file (a partial last line is ignored).

    Raises:
        FileNotFoundError: no such file.
        ValueError: a line before the last is not valid JSON (not a crash artefact).
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"results file {str(path)!r} does not exist")
    data = path.read_bytes()
    records, good = _parse(data, path)
    if good < len(data) and data[good:].strip():
        print(
            f"warning: {path}: a partial last line ({len(data) - good} bytes, a write cut "
            f"short) is left out; {len(records)} complete points read (rerunning the sweep "
            "repairs the file)",
            file=sys.stderr,
        )
    return records


def _parse(data: bytes, path: Path) -> tuple[list[dict[str, Any]], int]:
    """Records and the byte length of the valid prefix (anything after it is a torn tail).

    A torn tail is an unterminated last line, or a last line that is not a JSON object.
    A bad line *before* the last is not something a crash mid-write can make: ValueError.
    """
    *complete, tail = data.split(b"\n")
    records: list[dict[str, Any]] = []
    good = 0
    for i, line in enumerate(complete):
        try:
            rec = json.loads(line) if line.strip() else None
            if rec is not None and not isinstance(rec, dict):
                raise ValueError("not an object")
        except ValueError:
            if i == len(complete) - 1 and not tail:
                return records, good
            raise ValueError(
                f"{path}: line {i + 1} is not a valid JSON record and is not the last "
                "line; the file is damaged beyond a torn last write: fix or remove it"
            ) from None
        if rec is not None:
            records.append(rec)
        good += len(line) + 1
    return records, good


def check_results(
    path: str | Path, spec_hash: str, data: bytes | None = None, spec: dict | None = None
) -> tuple[list[dict[str, Any]], int]:
    """Refuse a file that is not this spec's results, changing nothing (no file: nothing to
    refuse). Returns its records and the byte length of their valid prefix.

    Raises:
        ValueError: as :func:`open_results`.
    """
    path = Path(path)
    if data is None:
        if not path.exists():
            return [], 0
        data = path.read_bytes()
    records, good = _parse(data, path)
    torn_first = not records and data.startswith(b'{"point":')  # a crash during the first write
    if (data.strip() and not records and not torn_first) or any(
        "spec_hash" not in r for r in records
    ):
        raise ValueError(
            f"--out {str(path)!r} exists and is not the results file of a sweep; "
            "give another --out (nothing was changed in it)"
        )
    others = sorted({r.get("spec_hash", "?") for r in records} - {spec_hash})
    if others:
        old = next(
            (r["spec"] for r in records if r.get("spec_hash") == others[0] and "spec" in r), None
        )
        changed = spec_changes(old, spec) if old is not None and spec is not None else ""
        raise ValueError(
            f"--out {str(path)!r} holds results of another sweep spec (spec_hash "
            f"{others[0][:12]}, this spec {spec_hash[:12]}{changed}); use another --out or "
            "remove it"
        )
    return records, good


def spec_changes(old: dict, new: dict) -> str:
    """What differs between two specs' fields (``to_dict`` form), as ``: exclude was X, is
    now Y; ...`` (empty when nothing is known to differ)."""
    parts = []
    for key in sorted(set(old) | set(new)):
        a, b = old.get(key), new.get(key)
        if a != b:
            parts.append(f"{key} was {_dumps_short(a)}, is now {_dumps_short(b)}")
    return (": " + "; ".join(parts)) if parts else ""


def _dumps_short(value: Any) -> str:
    text = json.dumps(value, default=str, separators=(",", ":"))
    return text if len(text) <= 120 else text[:117] + "..."


def open_results(
    path: str | Path, spec_hash: str, spec: dict | None = None
) -> list[dict[str, Any]]:
    """Load a results file for appending; refuse a file that is not this spec's results; then
    repair a torn last line.

    Nothing is changed in a refused file: the checks come before the repair.

    Returns:
        The records already in the file (all from this spec).
    Raises:
        ValueError: the file is not a sweep's results (no records, or a record without a
            ``spec_hash``), or holds records of another spec (a different ``spec_hash``).
    """
    path = Path(path)
    if not path.exists():
        return []
    data = path.read_bytes()
    records, good = check_results(path, spec_hash, data, spec)
    if good < len(data):
        torn = path.with_name(path.name + ".torn")
        with open(torn, "ab") as f:
            f.write(data[good:] + b"\n")
        os.truncate(path, good)
        print(
            f"osnerf sweep: repaired {path}: cut a partial last line ({len(data) - good} bytes, "
            f"saved to {torn.name}); {len(records)} finished points kept",
            file=sys.stderr,
        )
    return records


def append_record(path: str | Path, record: dict[str, Any]) -> None:
    """Append one record as one line: a single write of the whole line, flushed and fsynced.

    A write that fails or falls short (a full disk) is cut off again, so the file keeps its
    earlier points and no torn line; the ``OSError`` names the file.
    """
    line = (_dumps(record) + "\n").encode()
    fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
    try:
        size = os.fstat(fd).st_size  # the driver is the file's only writer
        try:
            n = _write(fd, line)
            if n != len(line):
                raise OSError(errno.ENOSPC, f"short write ({n} of {len(line)} bytes)")
            os.fsync(fd)
        except OSError as e:
            os.ftruncate(fd, size)  # the line whole or not at all
            raise OSError(e.errno, e.strerror or str(e), str(path)) from e
    finally:
        os.close(fd)


def _write(fd: int, data: bytes) -> int:
    """The one write of a line (tests make it fail as a full disk does)."""
    return os.write(fd, data)

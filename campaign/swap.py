"""Put a set of files in place as one step that an error or Ctrl-C undoes (a promotion's
checkpoints, cards, campaign lines and pages)."""

from __future__ import annotations

from pathlib import Path

from common import write_bytes


def swap(files: dict[Path, bytes | None]) -> None:
    """Put a set of files in place as one step that is undone on any failure or interrupt:
    every new file is written beside its target first (nothing replaced yet), then each target
    is moved aside and the new one renamed in (None: the target removed); an error or Ctrl-C
    midway moves every old file back. A file that is the set's record goes last."""
    import contextlib
    import os

    staged: list[tuple[Path, Path | None]] = []
    moved: list[tuple[Path, Path | None]] = []  # (target, its old file moved aside)
    try:
        for target, data in files.items():
            tmp = None
            if data is not None:
                target.parent.mkdir(parents=True, exist_ok=True)
                tmp = target.with_name(f".{target.name}.promoting")
                write_bytes(tmp, data)
            staged.append((target, tmp))
        for target, tmp in staged:
            aside = None
            if target.exists():
                aside = target.with_name(f".{target.name}.before-promotion")
                os.replace(target, aside)
            moved.append((target, aside))
            if tmp is not None:
                os.replace(tmp, target)
    except BaseException:
        for target, aside in reversed(moved):
            with contextlib.suppress(FileNotFoundError):
                if aside is None:
                    target.unlink()
                else:
                    os.replace(aside, target)
        for _, tmp in staged:
            if tmp is not None:
                tmp.unlink(missing_ok=True)
        raise
    for _, aside in moved:
        if aside is not None:
            aside.unlink(missing_ok=True)

"""Stage cache: ``RUN_DIR/cache/<config key>/<stage>.npz`` + ``.json``, written atomically."""

from __future__ import annotations

import io
import json
import zipfile
from pathlib import Path

import numpy as np

from common import write_bytes
from osnerf.provenance import write_json_atomic


class StageCacheError(ValueError):
    """A cached stage that cannot be read (the message names the file and how to clear it)."""


def _unreadable(npz: Path, why: str) -> StageCacheError:
    return StageCacheError(
        f"cached stage {npz} is corrupt or truncated ({why}); delete it (or the folder "
        f"{npz.parent}) and run again to recompute it"
    )


def check_stage_files(folder: Path) -> None:
    """Refuse a cache folder holding an unreadable stage, before any work (creates nothing).

    Raises:
        StageCacheError: naming the first corrupt file.
    """
    folder = Path(folder)
    for npz in sorted(folder.glob("*.npz")) if folder.is_dir() else ():
        try:
            with zipfile.ZipFile(npz) as z:
                bad = z.testzip()
        except (zipfile.BadZipFile, OSError, EOFError) as e:
            bad = f"{type(e).__name__}: {e}"
        if bad is not None:
            raise _unreadable(npz, str(bad))


class StageCache:
    """Each stage's arrays and JSON info; an interrupted run resumes from what is here. The
    folder is made with the first stage saved: a run refused or failed before it leaves
    none."""

    def __init__(self, root: Path):
        self.root = Path(root)

    def load(self, stage: str):
        """(arrays, info) of ``stage``, or None when it has not finished yet."""
        npz, js = self.root / f"{stage}.npz", self.root / f"{stage}.json"
        if not (npz.exists() and js.exists()):
            return None
        try:
            with np.load(npz) as f:
                arrays = {k: f[k] for k in f.files}
            info = json.loads(js.read_text())
        except (OSError, ValueError, EOFError, zipfile.BadZipFile) as e:
            raise _unreadable(npz, type(e).__name__) from None
        return arrays, info

    def save(self, stage: str, arrays: dict, info: dict) -> None:
        buf = io.BytesIO()
        np.savez_compressed(buf, **arrays)
        self.root.mkdir(parents=True, exist_ok=True)
        write_bytes(self.root / f"{stage}.npz", buf.getvalue())
        write_json_atomic(self.root / f"{stage}.json", info)

"""Stage cache: ``RUN_DIR/cache/<config key>/<stage>.npz`` + ``.json``, written atomically."""

from __future__ import annotations

import json
import zipfile
from pathlib import Path

import numpy as np


class StageCache:
    """Each stage's arrays and JSON info; an interrupted run resumes from what is here."""

    def __init__(self, root: Path):
        self.root = Path(root)
        self.root.mkdir(parents=True, exist_ok=True)

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
            raise RuntimeError(
                f"stage cache {npz} is unreadable ({type(e).__name__}); delete {self.root} to recompute"
            ) from None
        return arrays, info

    def save(self, stage: str, arrays: dict, info: dict) -> None:
        from osnerf.provenance import write_json_atomic

        tmp = self.root / f".{stage}.tmp.npz"
        np.savez_compressed(tmp, **arrays)
        tmp.replace(self.root / f"{stage}.npz")
        write_json_atomic(self.root / f"{stage}.json", info)

"""The campaign on disk: ``campaign.json`` (its lines of runs and each line's best),
``log.jsonl`` (one validation record per run, append-only) and ``lines/<line>/best.safetensors``
(a line's best weights when they are not a shipped checkpoint).

A line is one architecture trained on one recipe; each ``continue`` is a *stretch* of it that
starts from the line's best. A best is referenced by path (relative to the campaign folder)
and sha256: the shipped default is referenced, not copied, and a reference whose file no
longer holds that sha256 is refused rather than trained on.
"""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import json
import math
import os
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

from common import InputError, to_json, write_bytes, write_files

HERE = Path(__file__).resolve().parent
MAX_WEIGHTS_BYTES = 10 * 1024 * 1024
"""A best's file in the repo stays under this; larger weights are stored as float16."""
LR_RANGE = (1e-5, 2e-3)
"""The learning rates a campaign moves between (:func:`next_lrs`)."""


@dataclass
class Campaign:
    """``campaign.json`` read into memory; :meth:`save` writes it back atomically."""

    folder: Path
    doc: dict = field(default_factory=dict)

    @classmethod
    def open(cls, folder: Path | str = HERE) -> Campaign:
        folder = Path(folder)
        path = folder / "campaign.json"
        if not path.is_file():
            raise InputError(f"--campaign: no campaign.json in {folder}")
        try:
            doc = json.loads(path.read_text())
        except json.JSONDecodeError as e:
            raise InputError(f"--campaign: {path} is not JSON ({e.msg}, line {e.lineno})") from None
        for key in ("validation", "lines", "default_line"):
            if key not in doc:
                raise InputError(f"--campaign: {path} has no {key!r}")
        return cls(folder, doc)

    @property
    def log_path(self) -> Path:
        return self.folder / "log.jsonl"

    @contextlib.contextmanager
    def locked(self) -> Iterator[Campaign]:
        """Hold the campaign's lock (an exclusive ``flock`` on its folder, so no file is made)
        and re-read ``campaign.json`` under it: a read-merge-save inside sees every earlier
        save, and two ``continue`` runs that end together take turns."""
        fd = os.open(self.folder, os.O_RDONLY)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX)
            self.doc = Campaign.open(self.folder).doc
            yield self
        finally:
            os.close(fd)  # releases the lock

    def check_writable(self) -> None:
        """Refuse (``InputError`` naming ``--campaign``) a folder that cannot take the files a
        stretch writes at its end, before any training."""
        probe = self.folder / ".campaign-write-check"
        try:
            write_bytes(probe, b"")
            probe.unlink()
            for name in ("campaign.json", "log.jsonl"):
                path = self.folder / name
                if path.exists() and not os.access(path, os.W_OK):
                    raise PermissionError(13, "Permission denied", str(path))
        except OSError as e:
            raise InputError(
                f"--campaign: {self.folder} cannot be written ({e.strerror or e}); nothing trained"
            ) from None

    def line(self, name: str | None) -> tuple[str, dict]:
        """(name, line) of ``name`` (None: the campaign's default line)."""
        name = name or self.doc["default_line"]
        lines = self.doc["lines"]
        if name not in lines:
            raise InputError(f"--line must be one of {', '.join(lines)}, got {name!r}")
        return name, lines[name]

    def best_path(self, line: dict) -> Path | None:
        """The line's best checkpoint (None: the line starts from scratch), its sha256 checked
        against the file's card."""
        best = line.get("best")
        if not best:
            return None
        path = (self.folder / best["path"]).resolve()
        sha = card_of(path).get("sha256")
        if sha != best["sha256"]:
            raise InputError(
                f"campaign best {best['path']} holds sha256 {str(sha)[:12]}, the campaign "
                f"recorded {best['sha256'][:12]}: restore that file or repoint the line"
            )
        return path

    def store_best(self, line_name: str, src: Path, card: dict) -> dict:
        """Write ``src`` as the line's best (float16 when float32 would pass
        :data:`MAX_WEIGHTS_BYTES`); returns the ``best`` reference."""
        dst = self.folder / "lines" / line_name / "best.safetensors"
        sha = write_weights(src, dst, card)
        return {"path": str(dst.relative_to(self.folder)), "sha256": sha}

    def save(self, records: list[dict] | None = None) -> None:
        """Write ``campaign.json`` atomically, with ``records`` appended to the log as one set
        (both new or, after a failure, both old)."""
        files = {}
        if records:
            old = self.log_path.read_text() if self.log_path.is_file() else ""
            new = "".join(json.dumps(r, sort_keys=True) + "\n" for r in records)
            files[self.log_path] = (old + new).encode()
        files[self.folder / "campaign.json"] = (to_json(self.doc) + "\n").encode()
        write_files(files)

    def log(self) -> list[dict]:
        if not self.log_path.is_file():
            return []
        return [json.loads(s) for s in self.log_path.read_text().splitlines() if s.strip()]


def card_of(path: Path) -> dict:
    """The model card inside a safetensors checkpoint.

    Raises:
        FileNotFoundError: nothing at ``path``.
        ValueError: ``path`` is not a safetensors checkpoint with a JSON model card.
    """
    from safetensors import safe_open

    if not Path(path).is_file():
        raise FileNotFoundError(f"checkpoint not found: {path}")
    try:
        with safe_open(str(path), framework="pt") as f:
            meta = f.metadata() or {}
        return json.loads(meta.get("model_card", "{}"))
    except Exception as e:  # safetensors' own errors are not exceptions of one kind
        first = (str(e).strip().splitlines() or [type(e).__name__])[0]
        raise ValueError(f"{path} is not a safetensors checkpoint ({first})") from None


def images_sha256(images) -> str:
    """The sha256 of a held-out set as scored: its images ([count, 3, side, side] float32 in
    [0, 1], 8-bit values) as bytes, so another folder, count or crop hashes differently."""
    import numpy as np

    arr = np.round(images.detach().cpu().numpy() * 255.0).astype(np.uint8)
    return hashlib.sha256(arr.tobytes() + str(arr.shape).encode()).hexdigest()


def write_weights(src: Path, dst: Path, card: dict) -> str:
    """Copy the JSCC checkpoint ``src`` to ``dst`` with ``card`` merged into its model card;
    float16 weights when the float32 file passes :data:`MAX_WEIGHTS_BYTES`. Returns the sha256
    (of what is stored: float16 weights hash as themselves)."""
    import torch

    from semcodec import make_codec

    codec = make_codec(f"jscc:{src}")
    merged = {**codec.card, **card}
    if Path(src).stat().st_size > MAX_WEIGHTS_BYTES:
        codec.model.to(torch.float16)
        merged["stored_as"] = "float16 (training ran in float32)"
    merged.pop("sha256", None)
    return codec.save(dst, merged)  # atomic (common.write_bytes)


def next_lrs(lrs: list[float], winner: float) -> list[float]:
    """The next stretch's two learning rates: the winner stays and its partner moves a factor
    2 beyond it, on the side the winner lay (the higher won: try twice it; the lower won:
    half of it), both kept in :data:`LR_RANGE`."""
    lo, hi = LR_RANGE
    step = 2.0 if winner >= max(lrs) else 0.5
    other = min(max(winner * step, lo), hi)
    if math.isclose(other, winner):
        other = winner / step
    return [winner, other]


def now_utc() -> str:
    return time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())


def at_work(fn, *args):
    """Call ``fn`` once the inputs are checked: its ValueError, KeyError or FileNotFoundError
    is a runtime failure (exit 1), not bad input; an ``InputError`` stays bad input."""
    try:
        return fn(*args)
    except InputError:
        raise
    except (ValueError, KeyError, FileNotFoundError) as e:
        raise RuntimeError(f"{type(e).__name__}: {e}") from e

"""What a bare GPU machine needs to continue the campaign, packed into one folder that the
device tool carries (``.campaign-carry``, ignored by git; BSDS500 is for research use and
never committed):

* ``data/train``, ``data/val``: the training images (the files themselves: the data hash in
  each card stays the one of ``bsds500/train`` + ``val``);
* ``data/test``: the held-out set, only its first images (those the campaign validates on);
* ``site/``: sionna's pure-Python ``phy`` and ``sys`` parts (no ray tracer) and
  ``importlib_resources``, which the device image lacks, so ``ofdm_tdl_ls`` stays in the
  training mixture there (``PYTHONPATH=.campaign-carry/site``).
"""

from __future__ import annotations

import importlib.util
import shutil
from pathlib import Path

from common import InputError, list_images

PACK = ".campaign-carry"
"""The carried folder, relative to the repository root."""
SITE_PACKAGES = ("sionna", "importlib_resources")
SIONNA_SKIP = ("rt",)
"""sionna's ray tracer: 52 MB and Mitsuba; the training channels never use it."""


def _package_dir(name: str) -> Path:
    spec = importlib.util.find_spec(name)
    if spec is None or not spec.submodule_search_locations:
        raise FileNotFoundError(f"python package {name} is not installed here: pip install {name}")
    return Path(next(iter(spec.submodule_search_locations)))


def _ignore(root: Path, skip_top: tuple[str, ...]):
    def ignore(folder: str, names: list[str]) -> list[str]:
        skip = {n for n in names if n == "__pycache__" or n.endswith(".pyc")}
        if Path(folder) == root:
            skip |= {n for n in names if n in skip_top}
        return sorted(skip)

    return ignore


MARK = ".campaign-pack"
"""The file a finished pack holds (written last): only a folder with it is replaced or used."""


def is_pack(folder: Path) -> bool:
    """Whether ``folder`` is a finished pack (an earlier one, or none half-written)."""
    return (Path(folder) / MARK).is_file()


def pack(bsds: Path, out: Path, val_count: int) -> dict:
    """Write the carried folder ``out`` (replacing an earlier pack, never another folder);
    returns what it holds and its size. Written beside ``out`` first and renamed into place
    when complete: a failure leaves the earlier pack (or nothing) and raises ``RuntimeError``.
    """
    import os
    import tempfile

    for split in ("train", "val", "test"):
        if not (bsds / split).is_dir():
            raise FileNotFoundError(f"--bsds: no {split} folder in {bsds}")
    if out.exists() and not (out.is_dir() and not out.is_symlink() and is_pack(out)):
        raise InputError(
            f"--out {out} exists and is not an earlier pack (no {MARK} in it): not replaced; "
            "name a new folder"
        )
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".packing", dir=out.parent))
    try:
        data = tmp / "data"
        for split in ("train", "val"):
            shutil.copytree(bsds / split, data / split)
        (data / "test").mkdir(parents=True)
        for p in list_images(bsds / "test", "--bsds test")[:val_count]:
            shutil.copy2(p, data / "test" / p.name)
        for name in SITE_PACKAGES:
            src = _package_dir(name)
            skip = SIONNA_SKIP if name == "sionna" else ()
            shutil.copytree(src, tmp / "site" / name, ignore=_ignore(src, skip))
        (tmp / MARK).write_text("written by python -m campaign pack\n")
        size = sum(p.stat().st_size for p in tmp.rglob("*") if p.is_file())
        old = None
        if out.exists():
            old = out.with_name(f".{out.name}.old")
            shutil.rmtree(old, ignore_errors=True)
            os.replace(out, old)
        try:
            os.replace(tmp, out)
        except OSError:
            if old is not None:  # the earlier pack back where it was
                os.replace(old, out)
            raise
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
    except OSError as e:
        raise RuntimeError(f"--out {out}: {e.strerror or e} ({e.filename or out})") from None
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return {"folder": str(out), "megabytes": round(size / 2**20, 1)}

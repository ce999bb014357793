"""The one atomic writer: every output file of the project is written through here.

A file is written to a hidden temporary file beside its target (same folder, so the rename
cannot cross file systems) and renamed over the target only when it is complete: a reader,
or a resumed run, sees the old file or the new one, never a torn one.

* A path that exists and is not a regular file (a device node, a FIFO, a symlink, a folder)
  is never replaced: :class:`FileExistsError` naming it.
* A failed write (a full disk, ``ENOSPC``; a read-only folder) removes the temporary file and
  raises one :class:`OSError` whose ``filename`` is the target, e.g. ``[Errno 28] No space left
  on device: 'run/model.pt'``, whatever library produced the bytes. Writers that build the
  bytes in memory first (:func:`write_bytes` and the helpers on it) turn a library's own
  failure text (torch's ``inline_container.cc``, OpenCV's ``False``) into that one line.
* Files that belong together (a report and its pictures) go through :func:`write_files`:
  all are written in full before any is renamed, so a failure leaves the old set whole.
"""

from __future__ import annotations

import contextlib
import errno
import io
import json
import os
import stat
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

_KINDS = {
    stat.S_ISLNK: "a symlink",
    stat.S_ISDIR: "a folder",
    stat.S_ISCHR: "a character device",
    stat.S_ISBLK: "a block device",
    stat.S_ISFIFO: "a FIFO",
    stat.S_ISSOCK: "a socket",
}


def path_kind(path: str | os.PathLike) -> str | None:
    """What ``path`` names without following a symlink: None when nothing is there, "a file"
    for a regular file, else "a symlink", "a folder", "a character device", "a FIFO", ..."""
    try:
        mode = os.lstat(path).st_mode
    except (FileNotFoundError, NotADirectoryError):
        return None
    if stat.S_ISREG(mode):
        return "a file"
    return next((kind for test, kind in _KINDS.items() if test(mode)), "not a regular file")


def check_replaceable(path: str | os.PathLike) -> Path:
    """``path`` as a Path when it names nothing or a regular file.

    Raises:
        FileExistsError: when it names anything else (symlink, device, FIFO, folder, ...).
    """
    kind = path_kind(path)
    if kind not in (None, "a file"):
        raise FileExistsError(
            errno.EEXIST, f"exists and is {kind}, not a regular file; not replaced", str(path)
        )
    return Path(path)


def _unlink(path: str) -> None:
    with contextlib.suppress(FileNotFoundError):
        os.unlink(path)


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """A temporary path beside ``path`` (hidden, same suffix) for a writer that needs a path.

    On a clean exit the temporary file is renamed over ``path``; on any error it is removed
    and an ``OSError`` is raised again with ``path`` as its filename.

    Example::

        with atomic_path("out/clip.mp4") as tmp:
            cv2.imwriteanimation(str(tmp), animation)
    """
    target = check_replaceable(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(
        prefix=f".{target.name}.", suffix=f".tmp{target.suffix}", dir=target.parent
    )
    os.close(fd)
    try:
        yield Path(tmp)
        os.chmod(tmp, 0o644)  # mkstemp makes 0600; results are meant to be shared
        check_replaceable(target)
        os.replace(tmp, target)
    except OSError as e:
        _unlink(tmp)
        if e.filename == str(target):
            raise
        raise OSError(e.errno, e.strerror or str(e), str(target)) from e
    except BaseException:
        _unlink(tmp)
        raise


def _write_file(path: Path, data: bytes) -> None:
    """The one place bytes reach the disk (tests make it fail like a full disk)."""
    with open(path, "wb") as f:
        f.write(data)


def write_bytes(path: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically (see the module docstring). Returns the path."""
    with atomic_path(path) as tmp:
        _write_file(tmp, bytes(data))
    return Path(path)


def write_files(files: dict[str | os.PathLike, bytes]) -> list[Path]:
    """Write several files as one set: every new file, or (after a failure) every old one.

    Each file is first written in full to a temporary file beside its target; only when all
    of them are on disk are they renamed over their targets, in the order given (put the
    file that says the set is complete, e.g. ``report.json``, last). A failed write (a full
    disk) removes every temporary file and raises one :class:`OSError` naming the target
    whose bytes did not fit, before any target is touched. Renames need no free space.

    Returns:
        The targets, in the order given.
    Raises:
        FileExistsError: a target names something other than a regular file (nothing written).
        OSError: a failed write, ``filename`` = its target (nothing replaced, nothing left).
    """
    targets = [check_replaceable(path) for path in files]
    staged: list[tuple[str, Path]] = []
    try:
        for target, data in zip(targets, files.values()):
            try:
                target.parent.mkdir(parents=True, exist_ok=True)
                fd, tmp = tempfile.mkstemp(
                    prefix=f".{target.name}.", suffix=f".tmp{target.suffix}", dir=target.parent
                )
                os.close(fd)
                staged.append((tmp, target))
                _write_file(Path(tmp), bytes(data))
                os.chmod(tmp, 0o644)  # mkstemp makes 0600; results are meant to be shared
            except OSError as e:
                raise OSError(e.errno, e.strerror or str(e), str(target)) from e
        for tmp, target in staged:
            check_replaceable(target)
            os.replace(tmp, target)
    except BaseException:
        for tmp, _ in staged:
            _unlink(tmp)  # the ones already renamed are gone: nothing to remove
        raise
    return targets


def write_text(path: str | os.PathLike, text: str) -> Path:
    """Write UTF-8 text atomically."""
    return write_bytes(path, text.encode("utf-8"))


def json_default(o: Any):
    """``json.dumps(default=)`` for numpy scalars and arrays, torch scalars and paths."""
    if hasattr(o, "item") and getattr(o, "ndim", None) == 0:  # numpy / torch scalars
        return o.item()
    if hasattr(o, "tolist"):  # numpy arrays
        return o.tolist()
    if isinstance(o, os.PathLike):
        return os.fspath(o)
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


def to_json(obj: Any, indent: int | None = 2) -> str:
    """``obj`` as JSON text (numpy scalars and arrays and paths included), newline-terminated."""
    return json.dumps(obj, indent=indent, default=json_default, allow_nan=True) + "\n"


def write_json(path: str | os.PathLike, obj: Any, indent: int | None = 2) -> Path:
    """Write ``obj`` as JSON atomically."""
    return write_text(path, to_json(obj, indent))


def write_png(path: str | os.PathLike, image) -> Path:
    """Write an image as PNG atomically.

    Args:
        image: [height, width] or [height, width, 3] (RGB) or [height, width, 4] (RGBA),
            uint8 or uint16.
    Raises:
        ValueError: when OpenCV cannot encode it (wrong dtype or shape).
    """
    import cv2
    import numpy as np

    a = np.asarray(image)
    if a.dtype not in (np.uint8, np.uint16) or a.ndim not in (2, 3):
        raise ValueError(
            f"{path}: a PNG needs uint8/uint16 [height, width(, 3|4)], got {a.dtype} {a.shape}"
        )
    if a.ndim == 3:
        a = a[..., [2, 1, 0, 3][: a.shape[2]]] if a.shape[2] in (3, 4) else a
    ok, buf = cv2.imencode(".png", np.ascontiguousarray(a))
    if not ok:
        raise ValueError(f"{path}: OpenCV could not encode a {a.dtype} {a.shape} image as PNG")
    return write_bytes(path, buf.tobytes())


def write_figure(path: str | os.PathLike, fig, **savefig_kwargs) -> Path:
    """Write a matplotlib figure atomically, in the format of ``path``'s suffix (png, pdf, svg)."""
    buf = io.BytesIO()
    fig.savefig(buf, format=Path(path).suffix.lstrip(".").lower() or "png", **savefig_kwargs)
    return write_bytes(path, buf.getvalue())


def write_torch(path: str | os.PathLike, obj: Any) -> Path:
    """``torch.save(obj)`` atomically: serialised in memory, then written as bytes."""
    import torch

    buf = io.BytesIO()
    torch.save(obj, buf)
    return write_bytes(path, buf.getvalue())

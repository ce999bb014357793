"""Validators shared by the ``osnerf`` commands: one check per kind of value, run before work.

Two kinds:

* argparse ``type=`` callables (:func:`seed`, :func:`threads`, :func:`resolution`,
  :func:`snr_db`, :func:`snr_db_list`, :func:`number`): a bad value is refused while the
  command line is parsed (``osnerf X: error: argument --seed: must be ...``, exit 2), so
  it never reaches the work, and ``osnerf sweep`` refuses a bad spec before any point runs.
* output-path checks (:func:`output_file`, :func:`output_dir`, :func:`distinct_outputs`):
  called first thing in a command's ``run``; they create nothing, so a refused command
  leaves no partial output behind.
"""

from __future__ import annotations

import argparse
import math
import os
import re
from collections.abc import Callable, Sequence
from pathlib import Path

from common import MAX_BUDGET_S, SEED_RANGE, Bound, path_kind
from osnerf.cli import UsageError

THREADS_RANGE = (1, 256)
RESOLUTION_PX_RANGE = (16, 512)  # the same as osnerf.scenes.RenderConfig.resolution_px
MAX_VIEWS = 10_000  # the most views a command renders or captures


def checked(b: Bound, name: str = "number") -> Callable:
    """An argparse type from a :class:`common.Bound` (a config field's declared range): the
    same check the config makes, refused while the command line is parsed."""

    def parse(text: str):
        if b.optional and str(text).strip().lower() in ("none", ""):
            return None
        try:
            return b.parse(text)
        except ValueError as e:
            raise argparse.ArgumentTypeError(str(e)) from None

    parse.__name__ = name
    return parse


def count(lo: int, hi: int) -> Callable:
    """An argparse type: an integer in [lo, hi] (counts and sizes always have an upper bound)."""
    return checked(Bound(lo, hi, integer=True), "count")


def names_from(known: Sequence[str], flag: str) -> Callable:
    """argparse type: comma-separated names, each one of ``known``, none twice -> tuple."""

    def parse(text: str) -> tuple[str, ...]:
        names = tuple(n.strip() for n in text.split(",") if n.strip())
        unknown = [n for n in names if n not in known]
        if not names or unknown or len(set(names)) != len(names):
            what = f"unknown {', '.join(map(repr, unknown))}; " if unknown else ""
            raise argparse.ArgumentTypeError(
                f"{what}give one or more of {', '.join(known)}, comma-separated, each once "
                f"(got {text!r})"
            )
        return names

    parse.__name__ = flag.lstrip("-")
    return parse


def seconds(text: str) -> float:
    """A time budget in seconds: a finite number in (0, MAX_BUDGET_S] (one week)."""
    return number(0.0, MAX_BUDGET_S, "s", low_open=True)(text)


def int_in(text: str, lo: int, hi: int, what: str = "") -> int:
    """An argparse type's body: ``text`` as an integer in [lo, hi], else ArgumentTypeError."""
    try:
        return Bound(lo, hi, integer=True).parse(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"must be an integer {what}in [{lo}, {hi}], got {text!r}"
        ) from None


def seed(text: str) -> int:
    """``--seed``: an integer in [0, 2**63 - 1]."""
    return int_in(text, *SEED_RANGE, "")


def refine_steps(text: str) -> int:
    """``--refine-steps``: an integer in [0, 10000]."""
    return int_in(text, 0, 10_000, "")


def threads(text: str) -> int:
    """``--threads``: torch CPU threads, an integer in [1, 256]."""
    return int_in(text, *THREADS_RANGE, "")


def resolution(text: str) -> int:
    """``--resolution``: image width in pixels, an integer in [16, 512]."""
    return int_in(text, *RESOLUTION_PX_RANGE, "of pixels ")


def boolean(text: str) -> bool:
    """A yes/no option's value: true/false (also yes/no, on/off, 1/0), any case."""
    t = str(text).strip().lower()
    if t in ("true", "yes", "on", "1"):
        return True
    if t in ("false", "no", "off", "0"):
        return False
    raise argparse.ArgumentTypeError(f"must be true or false, got {text!r}")


def number(lo: float, hi: float, unit: str = "", *, low_open: bool = False) -> Callable:
    """An argparse type: a finite float in [lo, hi] (``(lo, hi]`` with ``low_open``)."""
    return checked(Bound(lo, hi, unit, low_open=low_open))


def ground_station(text: str) -> tuple[float, float, float] | None:
    """``--ground-station``: ``X,Y,Z`` metres in the scene's frame, each in
    ``osnerf.run.config.GROUND_STATION_RANGE_M``, or ``scene`` for the scene's own (None,
    what leaving the flag out gives)."""
    from osnerf.run.config import GROUND_STATION_RANGE_M

    lo, hi = GROUND_STATION_RANGE_M
    if str(text).strip().lower() == "scene":
        return None
    try:
        xyz = tuple(float(v) for v in str(text).split(","))
    except ValueError:
        xyz = ()
    if len(xyz) != 3 or not all(math.isfinite(v) and lo <= v <= hi for v in xyz):
        raise argparse.ArgumentTypeError(
            f"must be X,Y,Z metres, each in [{lo:g}, {hi:g}], or 'scene' (the scene's own), "
            f"got {text!r}"
        )
    return xyz[0], xyz[1], xyz[2]


def _snr_range() -> tuple[float, float]:
    from phy import SNR_DB_RANGE

    return SNR_DB_RANGE


def snr_db(text: str) -> float:
    """``--snr-db`` with one value: Es/N0 in dB, finite, in ``phy.conventions.SNR_DB_RANGE``."""
    return number(*_snr_range(), "dB")(text)


def snr_db_list(text) -> list[float]:
    """``--snr-db`` with a list: ``'-10,-5,0'`` -> [-10.0, -5.0, 0.0]; no empty items."""
    lo, hi = _snr_range()
    items = [s.strip() for s in str(text).split(",")]
    one = number(lo, hi, "dB")
    try:
        if not items or any(not s for s in items):
            raise argparse.ArgumentTypeError("")
        return [one(s) for s in items]
    except argparse.ArgumentTypeError:
        raise argparse.ArgumentTypeError(
            f"must be comma-separated numbers in [{lo:g}, {hi:g}] dB, e.g. -10,-5,0, got {text!r}"
        ) from None


# ----------------------------------------------------------------------------- output paths
def add_allow_untrained(p: argparse.ArgumentParser) -> None:
    """Add ``--allow-untrained``: without it a codec without trained weights is refused."""
    p.add_argument(
        "--allow-untrained",
        action="store_true",
        help="run a codec that has no trained weights (e.g. deepjscc without a checkpoint): "
        "a freshly initialised network, labelled untrained in the results; without it such "
        "a codec is refused (exit 2)",
    )


def add_overwrite(p: argparse.ArgumentParser, what: str) -> None:
    """Add ``--overwrite``: without it an existing output that holds results is refused.

    Args:
        what: what the flag replaces, for its help ("the result JSON and --plot").
    """
    p.add_argument(
        "--overwrite",
        action="store_true",
        help=f"replace {what} when it already exists; without it an existing one is refused "
        "(exit 2, nothing written)",
    )


def _check_parent(path: Path, flag: str) -> None:
    """The nearest existing ancestor of ``path`` must be a writable folder."""
    parent = path.parent if str(path.parent) else Path(".")
    for a in (parent, *parent.parents):
        if a.exists():
            if not a.is_dir():
                raise UsageError(f"{flag} {str(path)!r}: {str(a)!r} is a file, not a folder")
            if not os.access(a, os.W_OK | os.X_OK):
                raise UsageError(f"{flag} {str(path)!r}: folder {str(a)!r} is not writable")
            return


def _kind(p: Path, flag: str, want: str) -> str | None:
    """What ``p`` names (``common.path_kind``); anything but a regular file or folder is
    refused: a device node, FIFO or symlink would be replaced by the atomic rename."""
    kind = path_kind(p)
    if kind not in (None, "a file", "a folder"):
        raise UsageError(f"{flag} {str(p)!r} is {kind}, not a regular file or folder; give {want}")
    return kind


def _outside_inputs(p: Path, flag: str, inputs: dict[str, str | None] | None) -> None:
    """Refuse an output inside (or equal to) an input folder, or equal to an input file."""
    out = Path(os.path.realpath(p))
    for in_flag, path in (inputs or {}).items():
        if path is None:
            continue
        src = Path(os.path.realpath(path))
        if out == src or (src.is_dir() and src in out.parents):
            raise UsageError(
                f"{flag} {str(p)!r} is inside the input {in_flag} {str(path)!r}: outputs must "
                "not be written among the inputs; give another path"
            )


def output_file(
    path,
    flag: str = "--out",
    *,
    overwrite: bool = False,
    resume: bool = False,
    inputs: dict[str, str | None] | None = None,
) -> Path:
    """Check a result file path before any work.

    Args:
        overwrite: an existing file may be replaced (``--overwrite``).
        resume: an existing file is the command's own to continue (``osnerf sweep``).
        inputs: ``{"--images": path, ...}``: the output must not be inside any of them.
    Raises:
        UsageError: naming ``flag`` and what is wrong (exit 2). Nothing is created.
    """
    p = Path(path)
    kind = _kind(p, flag, "a file path")
    if kind == "a folder":
        raise UsageError(f"{flag} {str(p)!r} is a folder; give a file path")
    if kind == "a file":
        if not os.access(p, os.W_OK):
            raise UsageError(f"{flag} {str(p)!r} exists and is not writable")
        if not (overwrite or resume):
            raise UsageError(
                f"{flag} {str(p)!r} exists; give --overwrite to replace it, or another path"
            )
    _check_parent(p, flag)
    _outside_inputs(p, flag, inputs)
    return p


def output_dir(
    path,
    flag: str = "--out",
    *,
    overwrite: bool = False,
    resumable: Callable[[Path], bool] | None = None,
    inputs: dict[str, str | None] | None = None,
) -> Path:
    """Check an output folder path before any work: absent, empty, or replaceable.

    Args:
        overwrite: a folder that holds files may be written into (``--overwrite``).
        resumable: ``resumable(folder) -> True`` when a non-empty folder is the command's
            own unfinished work, which it continues without ``--overwrite``.
        inputs: ``{"--data": path, ...}``: the output must not be inside any of them.
    Raises:
        UsageError: naming ``flag`` and what is wrong (exit 2). Nothing is created.
    """
    p = Path(path)
    kind = _kind(p, flag, "a folder path")
    if kind == "a file":
        raise UsageError(f"{flag} {str(p)!r} is a file; give a folder path")
    if kind == "a folder":
        if not os.access(p, os.W_OK | os.X_OK):
            raise UsageError(f"{flag} {str(p)!r} is not writable")
        if _holds_files(p) and not overwrite and not (resumable and resumable(p)):
            raise UsageError(
                f"{flag} {str(p)!r} exists and holds files; give --overwrite to write over "
                "them, or another folder"
            )
    _check_parent(p, flag)
    _outside_inputs(p, flag, inputs)
    return p


def _holds_files(folder: Path) -> bool:
    """Whether anything but empty folders lies under ``folder`` (a run refused or failed
    before its first file leaves at most empty folders: not files to protect)."""
    return any(not q.is_dir() or q.is_symlink() for q in folder.rglob("*"))


def distinct_outputs(**paths) -> None:
    """Refuse two outputs that name the same file (``out=..., plot=...``; None is skipped)."""
    seen: dict[Path, str] = {}
    for name, path in paths.items():
        if path is None:
            continue
        key = Path(os.path.abspath(path))
        flag = "--" + name.replace("_", "-")
        if key in seen:
            raise UsageError(f"{seen[key]} and {flag} are the same file {str(path)!r}")
        seen[key] = flag


def flag_error(e: ValueError, flags: dict[str, str] | None = None) -> UsageError:
    """A config's ``ValueError("max_papr_db must be ...")`` as the flag's
    (``--max-papr-db must ...``).

    Args:
        flags: field -> option where they differ (``{"num_train_views": "--views"}``); other
            fields become ``--field-name``. Every field named in the message is renamed.
    """
    msg = str(e)
    renames = dict(flags or {})
    first, sep, _ = msg.partition(" ")
    if sep and first.isidentifier() and first.islower():
        renames.setdefault(first, "--" + first.replace("_", "-"))
    for name in sorted(renames, key=len, reverse=True):  # a word, never part of a path
        msg = re.sub(rf"(?<![-\w/\\.]){re.escape(name)}(?![-\w/\\]|\.\w)", renames[name], msg)
    return UsageError(msg)

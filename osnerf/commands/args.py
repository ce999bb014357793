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
from collections.abc import Callable
from pathlib import Path

from osnerf.cli import UsageError

SEED_RANGE = (0, 2**63 - 1)  # what torch.Generator.manual_seed and numpy accept alike
THREADS_RANGE = (1, 256)
RESOLUTION_PX_RANGE = (16, 512)  # the same as osnerf.scenes.RenderConfig.resolution_px


def _int_in(text: str, lo: int, hi: int, what: str) -> int:
    try:
        value = int(str(text).strip())
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"must be an integer {what}in [{lo}, {hi}], got {text!r}"
        ) from None
    if not lo <= value <= hi:
        raise argparse.ArgumentTypeError(f"must be an integer {what}in [{lo}, {hi}], got {text!r}")
    return value


def seed(text: str) -> int:
    """``--seed``: an integer in [0, 2**63 - 1]."""
    return _int_in(text, *SEED_RANGE, "")


def refine_steps(text: str) -> int:
    """``--refine-steps``: an integer in [0, 10000]."""
    return _int_in(text, 0, 10_000, "")


def threads(text: str) -> int:
    """``--threads``: torch CPU threads, an integer in [1, 256]."""
    return _int_in(text, *THREADS_RANGE, "")


def resolution(text: str) -> int:
    """``--resolution``: image width in pixels, an integer in [16, 512]."""
    return _int_in(text, *RESOLUTION_PX_RANGE, "of pixels ")


def number(lo: float, hi: float, unit: str = "", *, low_open: bool = False) -> Callable:
    """An argparse type: a finite float in [lo, hi] (``(lo, hi]`` with ``low_open``)."""
    span = f"{'(' if low_open else '['}{lo:g}, {hi:g}]{' ' + unit if unit else ''}"

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not math.isfinite(value) or not (lo < value if low_open else lo <= value) or value > hi:
            raise argparse.ArgumentTypeError(f"must be a number in {span}, got {text!r}")
        return value

    parse.__name__ = "number"
    return parse


def _snr_range() -> tuple[float, float]:
    from phy.conventions import SNR_DB_RANGE

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


def output_file(path, flag: str = "--out") -> Path:
    """Check a result file path before any work: not a folder, its folder creatable.

    Raises:
        UsageError: naming ``flag`` and what is wrong (exit 2). Nothing is created.
    """
    p = Path(path)
    if p.is_dir():
        raise UsageError(f"{flag} {str(p)!r} is a folder; give a file path")
    if p.exists() and not os.access(p, os.W_OK):
        raise UsageError(f"{flag} {str(p)!r} exists and is not writable")
    _check_parent(p, flag)
    return p


def output_dir(path, flag: str = "--out") -> Path:
    """Check an output folder path before any work: a folder or creatable as one.

    Raises:
        UsageError: naming ``flag`` and what is wrong (exit 2). Nothing is created.
    """
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise UsageError(f"{flag} {str(p)!r} is a file; give a folder path")
    if p.is_dir() and not os.access(p, os.W_OK | os.X_OK):
        raise UsageError(f"{flag} {str(p)!r} is not writable")
    _check_parent(p, flag)
    return p


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


def flag_error(e: ValueError) -> UsageError:
    """A config's ``ValueError("max_papr_db must be ...")`` as the flag's: ``--max-papr-db must ...``.

    For configs whose field names are the commands' option names (units included).
    """
    msg = str(e)
    name, sep, rest = msg.partition(" ")
    if sep and name.isidentifier() and name.islower():
        msg = f"--{name.replace('_', '-')} {rest}"
    return UsageError(msg)

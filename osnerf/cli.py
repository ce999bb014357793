"""The ``osnerf`` command line: ``osnerf <command> [options]``.

Each command lives in ``osnerf/commands/<name>.py`` with ``add_arguments(parser)`` and
``run(args) -> int``. Results go to files (or stdout), progress and logs to stderr.
Exit codes: 0 success, 2 bad arguments or input, 1 runtime failure; always with a
one-line message naming what was wrong. A command calls :func:`inputs_checked` once it has
read and checked its inputs: a ``ValueError``, ``KeyError`` or ``FileNotFoundError`` before
that is bad input (2), after it a runtime failure (1); a ``common.InputError`` (``UsageError``
among them) is always bad input.
"""

from __future__ import annotations

import argparse
import contextvars
import importlib
import re
import sys

from common import InputError, Registry, tune_malloc
from osnerf.provenance import git_commit
from osnerf.version import __version__

# name -> (module, one-line help). One table; `osnerf sweep` uses it too.
COMMANDS = Registry[tuple[str, str]](
    "command",
    {
        "ber": ("osnerf.commands.ber", "uncoded BER vs SNR over AWGN or Rayleigh, against theory"),
        "eval-codec": (
            "osnerf.commands.eval_codec",
            "image transmission: JSCC vs digital vs ideal",
        ),
        "train-codec": ("osnerf.commands.train_codec", "train the semantic codec (JSCC)"),
        "train-nerf": (
            "osnerf.commands.train_nerf",
            "train a radiance field on a nerfstudio folder",
        ),
        "render": ("osnerf.commands.render", "render a camera path from a trained field"),
        "hil": ("osnerf.commands.hil", "SDR front ends: `hil info`, `hil emulate pluto`"),
        "ota": (
            "osnerf.commands.ota",
            "send images over the air (HackRF One or ADALM-Pluto, real or emulated)",
        ),
        "scenes": ("osnerf.commands.scenes", "list built-in scenes and their objects"),
        "radiomap": (
            "osnerf.commands.radiomap",
            "a scene's radio map (sionna-rt) with the candidate drone positions marked",
        ),
        "run": ("osnerf.commands.run", "the end-to-end pipeline: scene -> link -> NeRF -> report"),
        "sweep": ("osnerf.commands.sweep", "run a sweep spec; resumes where it stopped"),
        "plot": ("osnerf.commands.plot", "plots from sweep or eval-codec results"),
        "codec-info": (
            "osnerf.commands.codec_info",
            "a codec's complexity: parameters, MACs per pixel, encode and decode time",
        ),
        "demo": ("osnerf.commands.demo", "the main job on its embedded default"),
    },
)


# argparse takes "-10,-5" for an option unless it looks like a negative number: let
# comma-separated lists of numbers through too ("--snr-db -10,-5,0").
# A fraction ("--cbr -1/16") passes too, so the option's own check can say what is wrong.
_NUM = r"[-+]?\d*\.?\d+([eE][-+]?\d+)?(/\d*\.?\d+)?"
_NEGATIVE_LIST = re.compile(rf"^-\d*\.?\d+([eE][-+]?\d+)?(/\d*\.?\d+)?(,{_NUM})*$")
STDOUT_COMMANDS = ("scenes", "hil", "codec-info")  # their result is what they print


class UsageError(InputError):
    """Bad arguments or input: exit code 2."""


_inputs_checked = contextvars.ContextVar("osnerf_inputs_checked", default=False)


def inputs_checked() -> None:
    """Mark that the running command has read and checked its inputs: from here on a
    ``ValueError``, ``KeyError`` or ``FileNotFoundError`` is a runtime failure (exit 1)."""
    _inputs_checked.set(True)


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors (``osnerf ber: error: argument --channel: ...``)."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message}\n")


def available_commands() -> dict[str, tuple[str, str]]:
    """Commands whose module exists in this checkout."""
    import importlib.util

    return {k: v for k, v in COMMANDS.items() if importlib.util.find_spec(v[0]) is not None}


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    parser = _Parser(prog="osnerf", description=__doc__.splitlines()[0])
    parser.add_argument("--version", action="version", version=f"osnerf {__version__}")
    parser._negative_number_matcher = _NEGATIVE_LIST
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True
    for name, (module, help_text) in available_commands().items():
        p = sub.add_parser(name, help=help_text, description=help_text)
        p._negative_number_matcher = _NEGATIVE_LIST
        if command is None or name == command:
            importlib.import_module(module).add_arguments(p)
    return parser


def _first_command(argv: list[str]) -> str | None:
    for a in argv:
        if not a.startswith("-"):
            return a
    return None


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    command = _first_command(argv)
    parser = build_parser(command if command in COMMANDS else None)
    try:
        args = parser.parse_args(argv)
    except SystemExit as e:  # argparse already printed its message
        return int(e.code or 0)
    module = importlib.import_module(COMMANDS[args.command][0])
    token = _inputs_checked.set(False)
    try:
        if sys.stdout is None and args.command in STDOUT_COMMANDS:
            raise UsageError("standard output is closed; its listing would be lost")
        tune_malloc()
        git_commit()  # read once, now: results name the code this run started with (cached)
        rc = int(module.run(args) or 0)
        if sys.stdout is not None:
            sys.stdout.flush()  # a full disk or closed pipe is a failure, not a lost listing
        return rc
    except (UsageError, ValueError, KeyError, FileNotFoundError) as e:
        msg = e.args[0] if isinstance(e, KeyError) and e.args else e
        if isinstance(e, InputError) or not _inputs_checked.get():
            print(f"osnerf {args.command}: error: {_first_line(msg)}", file=sys.stderr)
            return 2
        print(
            f"osnerf {args.command}: failed: {type(e).__name__}: {_first_line(msg)}",
            file=sys.stderr,
        )
        return 1
    except KeyboardInterrupt:
        print(f"osnerf {args.command}: interrupted", file=sys.stderr)
        return 130
    except Exception as e:  # noqa: BLE001 - the CLI boundary: one line, exit 1
        print(
            f"osnerf {args.command}: failed: {type(e).__name__}: {_first_line(e)}", file=sys.stderr
        )
        return 1
    finally:
        _inputs_checked.reset(token)


def _first_line(e: BaseException) -> str:
    """A message as one line: a library's multi-line text (a state-dict dump) is cut to its
    first line, so the error stays one line."""
    lines = [ln for ln in str(e).splitlines() if ln.strip()]
    return lines[0] + (" (...)" if len(lines) > 1 else "") if lines else type(e).__name__


def entry() -> None:
    rc = main()
    # the interpreter's last collection walks every object the libraries made; nothing left
    # needs it, so an interrupted run exits at once
    import gc

    gc.freeze()
    sys.exit(rc)


if __name__ == "__main__":
    entry()

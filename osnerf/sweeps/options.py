"""The command side of a sweep spec: the argparse sub-parser of the command each point runs,
its long options, a spec value as command-line text, and the command's own ``check_args``."""

from __future__ import annotations

import argparse
from typing import Any

from osnerf import cli


def option_name(name: str) -> str:
    """A spec's option name as argparse's dest (``snr-db`` and ``snr_db`` both ``snr_db``)."""
    return str(name).replace("-", "_")


class ParseError(ValueError):
    """The command's parser refused a point's command line."""


def _raise(msg: str):
    raise ParseError(msg)


def command_parser(command: str) -> argparse.ArgumentParser:
    """The argparse sub-parser of ``osnerf <command>`` (errors raise instead of exiting)."""
    if command not in cli.COMMANDS:
        raise KeyError(
            f"unknown command {command!r} in spec field 'command'; known: {sorted(cli.COMMANDS)}"
        )
    top = cli.build_parser(command)
    sub = next(a for a in top._actions if isinstance(a, argparse._SubParsersAction))
    if command not in sub.choices:
        raise ValueError(
            f"command {command!r} is not available in this checkout (its module "
            f"{cli.COMMANDS[command][0]} is missing)"
        )
    p = sub.choices[command]
    p.error = _raise  # one-line ValueError instead of printing usage and exiting
    return p


def command_options(parser: argparse.ArgumentParser) -> dict[str, argparse.Action]:
    """dest name (underscores) -> action, for every long option of the parser."""
    out = {}
    for a in parser._actions:
        longs = [s for s in a.option_strings if s.startswith("--")]
        if not longs or isinstance(a, argparse._HelpAction):
            continue
        for s in longs:
            out[option_name(s[2:])] = a
        out.setdefault(option_name(a.dest), a)
    return out


def value_text(name: str, value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, list | tuple):
        return ",".join(value_text(name, v) for v in value)
    if isinstance(value, dict) or value is None:
        raise ValueError(f"option {name!r}: value {value!r} is not a scalar or a list of scalars")
    return str(value)


def option_args(name: str, value: Any, action: argparse.Action) -> list[str]:
    flag = next(s for s in action.option_strings if s.startswith("--"))
    if action.nargs == 0:  # store_true / store_false / store_const flags
        if not isinstance(value, bool):
            raise ValueError(
                f"option {name!r} is a flag: its value must be true or false, got {value!r}"
            )
        wanted = value if not isinstance(action, argparse._StoreFalseAction) else not value
        return [flag] if wanted else []
    return [flag, value_text(name, value)]


def command_check(command: str):
    """The command's ``check_args(args)`` (its module's: builds and validates the config
    of parsed arguments, raising ValueError on a combination its parser cannot see), or
    None."""
    import importlib

    return getattr(importlib.import_module(cli.COMMANDS[command][0]), "check_args", None)

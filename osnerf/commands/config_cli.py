"""Command-line options generated from a config dataclass: one default and one help per field.

A config's field is documented once, in the ``Attributes:`` section of its docstring, and
defaulted once, in the dataclass. :func:`add_config_arguments` turns the fields a command
exposes into options with that help and that default (shown once, as "(default: X)"), and
:func:`config_from_args` builds the config back, turning its ``ValueError("crop_px must be
...")`` into the flag's ``--crop-px must be ...`` (exit 2).

    add_config_arguments(p, TrainConfig, ["crop_px", "lr"], types={"crop_px": count(16, 512)})
    cfg = config_from_args(TrainConfig, args, ["crop_px", "lr"])
"""

from __future__ import annotations

import argparse
import dataclasses
import inspect
import re
from collections.abc import Callable, Iterable
from typing import Any

from osnerf.commands import args as checks


def field_docs(cls) -> dict[str, str]:
    """name -> help text, from the ``Attributes:`` section of ``cls``'s docstring.

    An entry ``a, b: text`` documents both fields; continuation lines are joined.
    """
    doc = inspect.getdoc(cls) or ""
    _, _, section = doc.partition("Attributes:\n")
    out: dict[str, str] = {}
    names: list[str] = []
    for line in section.splitlines():
        if line and not line.startswith(" "):  # the next section
            break
        m = re.match(r"^ {4}([a-z_][a-z0-9_, ]*):\s*(.*)$", line)
        if m:
            names = [n.strip() for n in m.group(1).split(",")]
            for n in names:
                out[n] = m.group(2).strip()
        elif names and line.strip():
            for n in names:
                out[n] += " " + line.strip()
    return out


def finite(text: str) -> float:
    """Any finite float (NaN and inf refused); a config's own check bounds it further."""
    return checks.number(-1e300, 1e300)(text)


def _type_of(f: dataclasses.Field) -> Callable | None:
    """The field's argparse type: its declared range (``common.bound`` metadata) when it has
    one, so the command line refuses what the config would; else by its annotation."""
    if "bound" in f.metadata:
        return checks.checked(f.metadata["bound"])
    ann = str(f.type)
    if ann.startswith("float"):
        return finite
    if ann.startswith("int"):
        return int
    return None


def flag_of(name: str, flags: dict[str, str] | None = None) -> str:
    """The option that sets field ``name`` (``--crop-px``, or a rename from ``flags``)."""
    return (flags or {}).get(name) or "--" + name.replace("_", "-")


def add_config_arguments(
    p: argparse.ArgumentParser,
    cls,
    names: Iterable[str],
    *,
    flags: dict[str, str] | None = None,
    types: dict[str, Callable] | None = None,
    choices: dict[str, Iterable] | None = None,
    defaults: dict[str, Any] | None = None,
) -> None:
    """Add one option per field in ``names``: help from the docstring, default from the class.

    Args:
        flags: field -> option where the option is not ``--field-name`` (``num_train_views``
            -> ``--views``).
        types: field -> argparse type; default: the field's declared range
            (``common.bound``), else a finite float for ``float`` fields, ``int`` for ``int``
            fields, text otherwise.
        choices: field -> allowed values.
        defaults: field -> a default other than the class's (a shipped file's path, say).
    """
    docs = field_docs(cls)
    by_name = {f.name: f for f in dataclasses.fields(cls)}
    for name in names:
        f = by_name[name]
        default = (defaults or {}).get(name, f.default)
        if isinstance(default, tuple):
            default_text = ",".join(map(str, default))
        else:
            default_text = (
                "none"
                if default is None
                else f"{default:g}"
                if isinstance(default, float)
                else str(default)
            )
        text = re.sub(r":\w+:`~?([^`]+)`", r"\1", docs.get(name, name))
        text = text.replace("``", "").rstrip(".")
        flag = flag_of(name, flags)
        kwargs: dict[str, Any] = {
            "dest": name,
            "default": default,
            "metavar": flag[2:].upper().replace("-", "_"),
            "help": f"{text} (default: {default_text})".replace("%", "%%"),
        }
        typ = (types or {}).get(name) or _type_of(f)
        if typ is not None:
            kwargs["type"] = typ
        if choices and name in choices:
            kwargs["choices"] = tuple(choices[name])
        p.add_argument(flag, **kwargs)


def config_from_args(cls, args: argparse.Namespace, names: Iterable[str], *, flags=None, **extra):
    """``cls(**{name: args.name}, **extra)``, a value in ``extra`` standing for a name's flag
    as decided by a check (its option still named in errors); a ``ValueError`` naming a field
    becomes a :class:`UsageError` naming its option."""
    names = list(names)
    try:
        return cls(**{n: getattr(args, n) for n in names if n not in extra}, **extra)
    except ValueError as e:
        raise checks.flag_error(e, {n: flag_of(n, flags) for n in names}) from None

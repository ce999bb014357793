"""A sweep spec: the osnerf command each point runs, its fixed options, its axes, its seeds.

A spec is a small YAML or TOML file::

    command: ber
    fixed: {channel: awgn, num_bits: 200000}
    axes: {modulation: [qpsk, 16qam], snr_db: [0, 5, 10]}
    seeds: [0]

An optional ``exclude`` lists combinations of axis values left out of the product
(:mod:`osnerf.sweeps.exclude`)::

    axes: {channel: [awgn, raytraced], drone_speed: [0, 15]}
    exclude: [{channel: awgn, drone_speed: 15}]

Option names are those of the command's command line without the dashes (``snr_db`` or
``snr-db`` both name ``--snr-db``). The spec is checked against the command's own argparse
options (from :func:`osnerf.cli.build_parser`) before anything runs: an unknown option, a
value outside its choices or of the wrong type, a value that names no entry of its table (a
codec, a channel, a scheme: :mod:`osnerf.sweeps.values`), a missing required option, an
empty axis or an empty seed list is a one-line ``ValueError`` naming the field and what is
allowed; so is a point whose command refuses the combination of its values (the command
module's ``check_args``, e.g. ``osnerf run``'s config checks).
"""

from __future__ import annotations

import argparse
import hashlib
import itertools
import json
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from osnerf.sweeps.exclude import check_exclude, matches
from osnerf.sweeps.options import (
    ParseError,
    command_check,
    command_options,
    command_parser,
    option_args,
    option_name,
    value_text,
)

RESERVED = ("out", "seed")  # set by the sweep itself, per point
OUTPUT_OPTIONS = ("plot", "sigmf_dir", "keep_outputs")  # files every point would write alike
SPEC_KEYS = ("command", "fixed", "axes", "seeds", "exclude")
MAX_POINTS = 10_000
"""Points a sweep may have unless ``osnerf sweep --max-points`` raises the bound."""


@dataclass(frozen=True)
class Point:
    """One point of a sweep: the axis values, the seed, and the command line it runs.

    Attributes:
        values: axis name -> value (names as written in the spec).
        seed: the seed passed as ``--seed`` (None when the command has no ``--seed``).
        argv: the command's arguments without ``--out`` (the runner adds it).
    """

    values: dict[str, Any]
    seed: int | None
    argv: tuple[str, ...]

    @property
    def key(self) -> str:
        """Identity of the point in a results file: canonical JSON of (values, seed)."""
        return point_key(self.values, self.seed)


def point_key(values: dict[str, Any], seed: int | None) -> str:
    """Canonical JSON of a point's axis values and seed (what a results line is matched on)."""
    return json.dumps({"point": values, "seed": seed}, sort_keys=True, separators=(",", ":"))


@dataclass(frozen=True)
class SweepSpec:
    """A validated sweep.

    Attributes:
        command: osnerf command each point runs (a key of ``osnerf.cli.COMMANDS``).
        fixed: option -> value, the same for every point.
        axes: option -> non-empty list of values; points are their cartesian product
            (in the spec's order, last axis fastest).
        seeds: seeds each point runs with (``[None]`` for a command without ``--seed``).
        exclude: combinations left out of the product: each entry maps axis names to a
            value or a list of values (any matches); a point matching every axis of an
            entry is dropped. Every entry must drop at least one point.
    """

    command: str
    fixed: dict[str, Any] = field(default_factory=dict)
    axes: dict[str, list[Any]] = field(default_factory=dict)
    seeds: tuple[int | None, ...] = (0,)
    exclude: tuple[dict[str, Any], ...] = ()

    def __post_init__(self):
        if not isinstance(self.command, str) or not self.command:
            raise ValueError(
                f"spec field 'command' must be an osnerf command name, got {self.command!r}"
            )
        if not isinstance(self.fixed, dict):
            raise ValueError(
                "spec field 'fixed' must be a mapping option -> value, got "
                f"{type(self.fixed).__name__}"
            )
        if not isinstance(self.axes, dict):
            raise ValueError(
                "spec field 'axes' must be a mapping option -> list of values, got "
                f"{type(self.axes).__name__}"
            )
        for name, values in self.axes.items():
            if not isinstance(values, list | tuple):
                raise ValueError(f"axis {name!r} must be a list of values, got {values!r}")
            if len(values) == 0:
                raise ValueError(f"empty sweep: axis {name!r} has no values")
        if len(self.seeds) == 0:
            raise ValueError("empty sweep: 'seeds' has no values")
        for s in self.seeds:
            if s is not None and (isinstance(s, bool) or not isinstance(s, int)):
                raise ValueError(f"spec field 'seeds' must hold integers, got {s!r}")
        check_exclude(self.exclude, list(self.axes))
        both = sorted(option_name(k) for k in self.fixed)
        dup = sorted(set(both) & {option_name(k) for k in self.axes})
        if dup:
            raise ValueError(f"option(s) {dup} appear in both 'fixed' and 'axes'; put each in one")

    @property
    def num_points(self) -> int:
        n = len(self.seeds)
        for values in self.axes.values():
            n *= len(values)
        return n

    def to_dict(self) -> dict[str, Any]:
        out = {
            "command": self.command,
            "fixed": dict(self.fixed),
            "axes": {k: list(v) for k, v in self.axes.items()},
            "seeds": list(self.seeds),
        }
        if self.exclude:  # a spec without one keeps its hash (and its results file)
            out["exclude"] = [dict(e) for e in self.exclude]
        return out

    @property
    def sha256(self) -> str:
        """Hash of the canonical spec: a results file belongs to exactly one spec."""
        blob = json.dumps(self.to_dict(), sort_keys=True, separators=(",", ":"), default=str)
        return hashlib.sha256(blob.encode()).hexdigest()


def count_points(d: dict[str, Any]) -> int:
    """Points of a parsed spec mapping, counted without expanding them (seeds as a count or a
    list times the length of every axis); 0 when a field is malformed (checked later)."""
    seeds = d.get("seeds", [0])
    n = seeds if isinstance(seeds, int) and not isinstance(seeds, bool) else None
    if n is None:
        n = len(seeds) if isinstance(seeds, list | tuple) else 0
    axes = d.get("axes") or {}
    for values in axes.values() if isinstance(axes, dict) else ():
        n *= len(values) if isinstance(values, list | tuple) else 1
    return max(int(n), 0)


COUNT_KEPT_LIMIT = 10**6
"""Combinations of axis values that :func:`spec_from_dict` walks to count a spec's points
without its ``exclude`` ones; past it, the count before exclusion stands."""


def _count_kept(d: dict[str, Any], n: int, max_points: int) -> int:
    """The spec's points without those ``exclude`` leaves out (``n``: with them)."""
    axes = d.get("axes") or {}
    combos = 1
    for values in axes.values():
        combos *= len(values) if isinstance(values, list | tuple) else 1
    if not isinstance(axes, dict) or combos == 0 or combos > COUNT_KEPT_LIMIT:
        return n
    try:
        check_exclude(d["exclude"], list(axes))
    except ValueError:
        return n  # refused with its own message when the spec is built
    names = [k for k, v in axes.items() if isinstance(v, list | tuple)]
    kept = sum(
        not any(matches(e, dict(zip(names, combo))) for e in d["exclude"])
        for combo in itertools.product(*(axes[k] for k in names))
    )
    return n // combos * kept


def spec_from_dict(d: dict[str, Any], max_points: int = MAX_POINTS) -> SweepSpec:
    """Build a :class:`SweepSpec` from a parsed YAML/TOML mapping (unknown keys refused).

    Raises:
        ValueError: also when the spec has more than ``max_points`` points (counted first,
            so a huge spec is refused at once, before any memory is spent on it).
    """
    if not isinstance(d, dict):
        raise ValueError(
            f"a sweep spec must be a mapping with keys {list(SPEC_KEYS)}, got {type(d).__name__}"
        )
    unknown = sorted(set(d) - set(SPEC_KEYS))
    if unknown:
        raise ValueError(f"unknown spec field(s) {unknown}; allowed: {list(SPEC_KEYS)}")
    if "command" not in d:
        raise ValueError(f"spec field 'command' is missing; allowed keys: {list(SPEC_KEYS)}")
    n = count_points(d)
    if n > max_points and d.get("exclude"):
        n = _count_kept(d, n, max_points)
    if n > max_points:
        raise ValueError(
            f"the spec has {n} points, more than --max-points {max_points}; "
            "raise --max-points to run it, or shorten its axes and seeds"
        )
    seeds = d.get("seeds", [0])
    if isinstance(seeds, int) and not isinstance(seeds, bool):
        if seeds < 1:
            raise ValueError(
                f"empty sweep: 'seeds' must be a list of integers or a count >= 1, got {seeds}"
            )
        seeds = list(range(seeds))
    exclude = d.get("exclude") or []
    if not isinstance(seeds, list | tuple):
        raise ValueError(f"spec field 'seeds' must be a list of integers or a count, got {seeds!r}")
    return SweepSpec(
        command=d["command"],
        fixed=dict(d.get("fixed") or {}),
        axes=dict(d.get("axes") or {}),
        seeds=tuple(seeds),
        exclude=tuple(exclude) if isinstance(exclude, list) else exclude,
    )


def load_spec(path: str | Path, max_points: int = MAX_POINTS) -> SweepSpec:
    """Read a ``.yaml``/``.yml`` or ``.toml`` spec file (not yet checked against the command).

    Raises:
        ValueError: not valid YAML/TOML (with the line and column), or a bad spec.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"SPEC: no such file {str(path)!r}")
    text = path.read_text()
    try:
        if path.suffix.lower() == ".toml":
            d = tomllib.loads(text)
        elif path.suffix.lower() in (".yaml", ".yml"):
            d = yaml.safe_load(text)
        else:
            raise ValueError(f"SPEC must end in .yaml, .yml or .toml, got {path.name!r}")
    except (yaml.YAMLError, tomllib.TOMLDecodeError) as e:
        raise ValueError(
            f"SPEC {path.name}: not valid {path.suffix[1:].upper()}: {_syntax_error(e)}"
        ) from None
    return spec_from_dict(d, max_points)


def _syntax_error(e: Exception) -> str:
    """One line: what is wrong and where (``line 3, column 7``) in a YAML/TOML error."""
    mark = getattr(e, "problem_mark", None)
    if mark is not None:  # yaml.MarkedYAMLError
        what = getattr(e, "problem", None) or getattr(e, "context", None) or type(e).__name__
        return f"line {mark.line + 1}, column {mark.column + 1}: {what}"
    text = str(e).splitlines()[0] if str(e) else type(e).__name__
    return text  # tomllib says "... (at line 3, column 7)" itself


# --- checking against the command's own argparse options (osnerf.sweeps.options) ----------


def _check_table_values(spec: SweepSpec, opts: dict[str, argparse.Action]) -> None:
    """Every axis and fixed value that names a table entry (a codec, a channel, ...) is
    checked against its table now (:mod:`osnerf.sweeps.values`), before any point runs."""
    from osnerf.sweeps.values import check_values

    options = {}
    for kind, table in (("fixed option", spec.fixed), ("axis", spec.axes)):
        for name, values in table.items():
            action = opts[option_name(name)]
            if action.nargs == 0:  # a flag: true or false, nothing to look up
                continue
            values = values if kind == "axis" else [values]
            options[action.dest] = (f"{kind} {name!r}", [value_text(name, v) for v in values])
    check_values(spec.command, options)


def expand(spec: SweepSpec) -> list[Point]:
    """Check ``spec`` against the command's options and expand it into points.

    Every point's command line is parsed by the command's own parser, so a bad value
    fails here, before anything runs.
    """
    parser = command_parser(spec.command)
    opts = command_options(parser)
    allowed = sorted({option_name(a.dest) for a in opts.values()} - set(RESERVED))
    for kind, names in (("fixed", spec.fixed), ("axes", spec.axes)):
        for name in names:
            n = option_name(name)
            if n in RESERVED:
                raise ValueError(
                    f"option {name!r} in '{kind}' is set by the sweep itself "
                    f"({'use the seeds list' if n == 'seed' else 'use osnerf sweep --out'})"
                )
            if n not in opts:
                raise ValueError(
                    f"unknown option {name!r} in '{kind}' for command "
                    f"{spec.command!r}; allowed: {allowed}"
                )
            if n in OUTPUT_OPTIONS:
                raise ValueError(
                    f"option {name!r} in '{kind}' names an output: every point would write "
                    "the same file; leave it out (osnerf sweep --keep-outputs keeps each "
                    "point's own output)"
                )
    _check_table_values(spec, opts)
    has_seed = "seed" in opts
    if not has_seed and any(s is not None for s in spec.seeds):
        raise ValueError(f"command {spec.command!r} has no --seed option: leave 'seeds' out")
    seeds = spec.seeds if has_seed else (None,)

    fixed_argv: list[str] = []
    for name, value in spec.fixed.items():
        fixed_argv += option_args(name, value, opts[option_name(name)])
    names = list(spec.axes)
    points: list[Point] = []
    seen: dict[str, Point] = {}  # parsed options -> point
    used = [False] * len(spec.exclude)
    check_args = command_check(spec.command)
    for combo in itertools.product(*(spec.axes[n] for n in names)):
        values = dict(zip(names, combo))
        hits = [matches(e, values) for e in spec.exclude]
        used = [u or h for u, h in zip(used, hits)]
        if any(hits):
            continue
        argv = list(fixed_argv)
        for name, value in zip(names, combo):
            argv += option_args(name, value, opts[option_name(name)])
        for seed in seeds:
            full = argv + (["--seed", str(seed)] if seed is not None else [])
            point = Point(values=values, seed=seed, argv=tuple(full))
            parsed = _parse_point(spec.command, parser, point, "out" in opts, check_args)
            if parsed in seen:  # e.g. 0 and 0.0 on a float option
                raise ValueError(
                    f"points {seen[parsed].values} and {point.values} (seed {seed}) parse to the "
                    "same command line: remove the repeated axis value"
                )
            seen[parsed] = point
            points.append(point)
    for entry, u in zip(spec.exclude, used):
        if not u:
            raise ValueError(f"exclude entry {entry} matches no point of the axes: fix its values")
    if not points:
        raise ValueError("empty sweep: the spec expands to no points")
    return points


def _parse_point(command: str, parser, point: Point, has_out: bool, check_args) -> str:
    """``point``'s command line parsed by the command's parser and checked by its
    ``check_args``; returns the parsed options (canonical text). ValueError names the point."""
    check = list(point.argv) + (["--out", "__sweep_check__"] if has_out else [])
    try:
        args = parser.parse_args(check)
    except ParseError as e:
        raise ValueError(
            f"point {point.values} of the spec is not a valid `osnerf {command}` command line: {e}"
        ) from None
    if check_args is not None:
        try:
            check_args(args)
        except (ValueError, KeyError) as e:
            msg = e.args[0] if isinstance(e, KeyError) and e.args else e
            raise ValueError(
                f"point {point.values} of the spec is refused by `osnerf {command}`: {msg}; "
                "an 'exclude' entry leaves such a combination out"
            ) from None
    return repr(sorted(vars(args).items()))

"""The one number check: a value's allowed range declared once, as a config field's metadata,
and read by the config's own validation and by the command line's argparse type alike.

    @dataclass(frozen=True)
    class RunConfig:
        max_views: int | None = field(default=None, metadata=bound(1, 512, integer=True,
                                                                   optional=True))
        def __post_init__(self):
            check_bounds(self)        # "max_views must be an integer in [1, 512], got 0"

    add_config_arguments(...)         # --max-views 0: "must be an integer in [1, 512], got '0'"
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

SEED_RANGE = (0, 2**63 - 1)
"""What ``torch.Generator.manual_seed`` and numpy accept alike."""
MAX_BUDGET_S = 7 * 24 * 3600.0
"""The longest training or time budget a config or flag takes: a week."""


@dataclass(frozen=True)
class Bound:
    """A closed range ``[lo, hi]`` (``(lo, hi]`` with ``low_open``) of finite numbers.

    Attributes:
        lo, hi: the ends.
        unit: shown after the range in messages ("dB", "m/s").
        integer: integers only (``True``/``False`` are not integers here).
        low_open: ``lo`` itself is outside.
        optional: None is allowed (the field's "not set").
    """

    lo: float
    hi: float
    unit: str = ""
    integer: bool = False
    low_open: bool = False
    optional: bool = False

    def describe(self) -> str:
        """``an integer in [1, 512]`` / ``a number in (0, 1e+12] Hz``."""
        kind = "an integer" if self.integer else "a number"
        left = "(" if self.low_open else "["
        lo, hi = (int(self.lo), int(self.hi)) if self.integer else (f"{self.lo:g}", f"{self.hi:g}")
        span = f"{left}{lo}, {hi}]" + (f" {self.unit}" if self.unit else "")
        return f"{kind} in {span}" + (" or none" if self.optional else "")

    def holds(self, value) -> bool:
        """Whether ``value`` (a number, not text) lies in the range."""
        if value is None:
            return self.optional
        if isinstance(value, bool) or not isinstance(value, int | float):
            return False
        if self.integer and not (isinstance(value, int) or float(value).is_integer()):
            return False
        v = float(value)
        if not math.isfinite(v):
            return False
        return (self.lo < v if self.low_open else self.lo <= v) and v <= self.hi

    def check(self, name: str, value):
        """``value`` if it lies in the range (an int for integer ranges), else a ValueError
        naming ``name``, the range and the value."""
        if not self.holds(value):
            raise ValueError(f"{name} must be {self.describe()}, got {value!r}")
        if value is None:
            return None
        return int(value) if self.integer else value

    def parse(self, text: str):
        """``text`` from a command line as a value in the range; ValueError otherwise."""
        try:
            value = int(str(text).strip()) if self.integer else float(text)
        except ValueError:
            value = math.nan
        if not self.holds(value):
            raise ValueError(f"must be {self.describe()}, got {text!r}")
        return value


def bound(
    lo: float,
    hi: float,
    unit: str = "",
    *,
    integer: bool = False,
    low_open: bool = False,
    optional: bool = False,
) -> dict:
    """Field metadata declaring the field's range: ``field(default=..., metadata=bound(...))``."""
    return {"bound": Bound(lo, hi, unit, integer, low_open, optional)}


def bound_of(cls, name: str) -> Bound | None:
    """The :class:`Bound` declared on field ``name`` of dataclass ``cls``, or None."""
    f = {f.name: f for f in dataclasses.fields(cls)}[name]
    return f.metadata.get("bound")


def check_bounds(obj) -> None:
    """Check every field of the dataclass instance ``obj`` that declares a bound (first
    failure raised as a ValueError naming the field)."""
    for f in dataclasses.fields(obj):
        b = f.metadata.get("bound")
        if b is not None:
            b.check(f.name, getattr(obj, f.name))

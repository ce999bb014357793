"""The one number check (``common.bound``): a field's range declared once, refused alike by the
config's own validation and by the command line's argparse type."""

import argparse
import dataclasses
import re

import pytest

from common import Bound, bound, check_bounds
from osnerf.commands import run as run_cmd
from osnerf.run.config import RunConfig


def test_a_bound_says_what_it_allows():
    assert Bound(1, 512, integer=True).describe() == "an integer in [1, 512]"
    assert Bound(0, 1e12, "Hz", low_open=True).describe() == "a number in (0, 1e+12] Hz"
    assert Bound(0, 2**63 - 1, integer=True).describe() == f"an integer in [0, {2**63 - 1}]"
    assert Bound(1, 2, optional=True).describe() == "a number in [1, 2] or none"


@pytest.mark.parametrize(
    "b, value, ok",
    [
        (Bound(0, 1), 0.0, True),
        (Bound(0, 1), 1.0, True),
        (Bound(0, 1, low_open=True), 0.0, False),
        (Bound(0, 1), float("nan"), False),
        (Bound(0, 1), float("inf"), False),
        (Bound(0, 10, integer=True), 2.5, False),
        (Bound(0, 10, integer=True), True, False),  # a bool is not a count
        (Bound(0, 10), None, False),
        (Bound(0, 10, optional=True), None, True),
        (Bound(0, 10), "3", False),  # text is parsed at the command line, not here
    ],
)
def test_a_bound_holds_exactly_its_range(b, value, ok):
    assert b.holds(value) is ok


def test_text_is_parsed_and_refused_with_the_same_words():
    b = Bound(1, 512, integer=True)
    assert b.parse(" 7 ") == 7
    with pytest.raises(ValueError, match=r"^must be an integer in \[1, 512\], got '0'$"):
        b.parse("0")
    with pytest.raises(ValueError, match="got 'x'"):
        Bound(0, 1).parse("x")


def test_check_bounds_names_the_field():
    @dataclasses.dataclass(frozen=True)
    class C:
        n: int = dataclasses.field(default=3, metadata=bound(1, 5, integer=True))

    check_bounds(C())
    with pytest.raises(ValueError, match=r"^n must be an integer in \[1, 5\], got 9$"):
        check_bounds(C(n=9))


BOUNDED = [f for f in dataclasses.fields(RunConfig) if "bound" in f.metadata]


def _outside(b: Bound):
    return b.hi * 2 + 1 if b.hi > 0 else b.hi + 1


@pytest.mark.parametrize("f", BOUNDED, ids=lambda f: f.name)
def test_config_and_command_line_refuse_the_same_values(f):
    """Every declared range of RunConfig: a value outside is refused by the config (naming the
    field) and by ``osnerf run``'s option (naming the same range)."""
    b = f.metadata["bound"]
    bad = _outside(b)
    with pytest.raises(ValueError, match="^" + re.escape(f"{f.name} must be {b.describe()}")):
        RunConfig(**{f.name: int(bad) if b.integer else bad})
    p = argparse.ArgumentParser(exit_on_error=False)
    run_cmd.add_arguments(p)
    flag = run_cmd.FLAGS.get(f.name) or "--" + f.name.replace("_", "-")
    if f.name not in run_cmd.CONFIG_FIELDS:
        pytest.skip(f"{f.name} is not an option of osnerf run")
    with pytest.raises(argparse.ArgumentError, match=re.escape(b.describe())):
        p.parse_args(["--out", "x", flag, str(int(bad) if b.integer else bad)])

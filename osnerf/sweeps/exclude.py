"""A sweep spec's ``exclude``: combinations of axis values left out of the product.

Each entry maps some axes to a value, or to a list of values any of which matches; a point
whose axis values match every axis of an entry is dropped (as in a GitHub Actions matrix)::

    axes: {channel: [awgn, raytraced], drone_speed: [0, 15]}
    exclude: [{channel: awgn, drone_speed: 15}]

Values compare as the command line reads them: ``15`` matches ``15.0`` and ``"8,-6,1.5"``
matches ``[8, -6, 1.5]``.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any


def _norm(name: str) -> str:
    return str(name).replace("-", "_")


def canon(value: Any) -> Any:
    """A value as the command line reads it: numbers as floats, ``"8,-6,1.5"`` the same as
    ``[8, -6, 1.5]``, other text as is."""
    if isinstance(value, bool):
        return value
    if isinstance(value, int | float):
        return float(value)
    if isinstance(value, list | tuple):
        return tuple(canon(v) for v in value)
    if isinstance(value, str):
        try:
            nums = tuple(float(v) for v in value.split(","))
        except ValueError:
            return value
        return nums if len(nums) > 1 else nums[0]
    return value


def check_exclude(exclude: Any, axes: Sequence[str]) -> None:
    """``exclude`` is a list of non-empty mappings whose keys are axes (ValueError if not)."""
    if not isinstance(exclude, list | tuple):
        raise ValueError(
            f"spec field 'exclude' must be a list of mappings axis -> value(s), got {exclude!r}"
        )
    known = {_norm(a) for a in axes}
    for entry in exclude:
        if not isinstance(entry, dict) or not entry:
            raise ValueError(
                f"spec field 'exclude' must hold mappings axis -> value(s), got {entry!r}"
            )
        for name in entry:
            if _norm(name) not in known:
                raise ValueError(
                    f"exclude entry {entry} names {name!r}, which is not an axis; "
                    f"axes: {sorted(axes)}"
                )


def matches(entry: dict[str, Any], values: dict[str, Any]) -> bool:
    """Whether a point's axis ``values`` match every axis of an ``exclude`` entry."""
    by_axis = {_norm(k): v for k, v in values.items()}
    for name, want in entry.items():
        have = canon(by_axis[_norm(name)])
        if canon(want) == have:
            continue
        if not (isinstance(want, list | tuple) and any(canon(w) == have for w in want)):
            return False
    return True

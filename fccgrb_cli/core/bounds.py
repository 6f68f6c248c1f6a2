"""Numbers inside their range: finite (NaN and infinity are in no range), of the right kind,
and the words that say the range in the one-line errors. Shared by the solve options
(``options``), the command line's parameter types (``params``) and the sweep's keys."""

from __future__ import annotations

import math
from typing import Any


def describe_range(kind: type, low: float | None, low_open: bool, high: float | None,
                   unit: str = "") -> str:
    """'a finite number > 0 and ≤ 1 (m and rad)', 'an integer ≥ 1'."""
    def show(v: float) -> str:
        return str(int(v)) if float(v).is_integer() and abs(v) <= 2**32 else f"{v:g}"

    text = "an integer" if kind is int else "a finite number"
    bounds = ([f"{'>' if low_open else '≥'} {show(low)}"] if low is not None else []) + \
        ([f"≤ {show(high)}"] if high is not None else [])
    if bounds:
        text += " " + " and ".join(bounds)
    return text + (f" ({unit})" if unit else "")


def in_range(value: Any, kind: type, low: float | None, low_open: bool,
             high: float | None) -> bool:
    """Whether ``value`` is a ``kind`` (an int for int, not a bool; an int or a finite float for
    float) inside the range; NaN and infinity never are."""
    if isinstance(value, bool) or (kind is int and not isinstance(value, int)):
        return False
    if not isinstance(value, (int, float)) or not math.isfinite(value):
        return False
    if low is not None and (value < low or (low_open and value == low)):
        return False
    return high is None or value <= high

"""Click parameter types of the command line: every number finite and inside its range.

click's FloatRange lets NaN through (every comparison with NaN is false) and infinity where a
bound is open on that side; ``Bounded`` refuses both wherever a number is read, and says the
range in the words of the one-line errors ('--tol: expected a number > 0 and ≤ 1 (m and rad),
got nan').
"""

from __future__ import annotations

from typing import Any

import click

from fccgrb_cli.core.bounds import describe_range, in_range


class Bounded(click.ParamType):
    """A finite float, or an integer, inside [low, high] (``low_open``: low excluded)."""

    def __init__(self, kind: type = float, low: float | None = None, low_open: bool = False,
                 high: float | None = None, unit: str = "") -> None:
        self.kind, self.low, self.low_open, self.high, self.unit = kind, low, low_open, high, unit
        self.name = "integer" if kind is int else "float"

    def convert(self, value: Any, param, ctx) -> Any:
        number = value
        if isinstance(value, str):
            try:
                number = int(value.strip()) if self.kind is int else float(value)
            except ValueError:
                number = None
        bounds = (self.low, self.low_open, self.high)
        if number is None or not in_range(number, self.kind, *bounds):
            expected = describe_range(self.kind, *bounds, self.unit)
            self.fail(f"expected {expected}, got {value!r}", param, ctx)
        return number

    def get_metavar(self, param, ctx=None) -> str:
        return self.name.upper()


class Widths(click.ParamType):
    """One length, or a left,right pair, each a finite float inside (0, high] in ``unit``;
    kept as the text given (the templates read one or two from it)."""

    name = "widths"

    def __init__(self, high: float, unit: str) -> None:
        self.one = Bounded(float, 0.0, True, high, unit)

    def convert(self, value: Any, param, ctx) -> Any:
        parts = str(value).split(",")
        if len(parts) > 2:
            self.fail(f"expected one number or a left,right pair, got {value!r}", param, ctx)
        for part in parts:
            self.one.convert(part, param, ctx)
        return str(value)

"""The syntax of virtual markers (points made from a trial's markers frame by frame; applied to a
trial by ``io/virtual.py``): one function of trial labels,

* ``mid(A, B)``: the midpoint of A and B;
* ``mean(A, B, C, …)``: the mean of two or more markers.

Its canonical text, spaces removed (``mid(LPSI,RPSI)``), is the label the point gets.
"""

from __future__ import annotations

import re

from fccgrb_cli.core.errors import InputError

FUNCTIONS = {"mid": (2, 2), "mean": (2, None)}
_CALL = re.compile(r"^\s*([A-Za-z_]\w*)\s*\((.*)\)\s*$", re.DOTALL)


def is_expression(text: str) -> bool:
    """Whether a label map's value is a virtual marker rather than a label."""
    return "(" in text or ")" in text


def parse(text: str, where: str) -> tuple[str, tuple[str, ...]]:
    """(function, labels) of an expression; an InputError names ``where`` (the option or key
    path) and what was expected."""
    match = _CALL.match(text)
    if match is None:
        raise InputError(f"{where}: expected a virtual marker mid(A, B) or mean(A, B, ...), "
                         f"got {text!r}")
    name, inner = match.group(1), match.group(2)
    if name not in FUNCTIONS:
        raise InputError(f"{where}: expected a function of {', '.join(FUNCTIONS)}, got "
                         f"{name!r} in {text!r}")
    args = tuple(a.strip() for a in inner.split(","))
    if any(not a or "(" in a or ")" in a for a in args):
        raise InputError(f"{where}: expected marker labels separated by commas inside "
                         f"{name}(...), got {text!r}")
    low, high = FUNCTIONS[name]
    if len(args) < low or (high is not None and len(args) > high):
        wanted = f"exactly {low}" if low == high else f"at least {low}"
        raise InputError(f"{where}: {name} takes {wanted} markers, got {len(args)} in {text!r}")
    if len(set(args)) != len(args):
        raise InputError(f"{where}: expected different markers in {text!r}")
    return name, args


def canonical(text: str, where: str) -> str:
    """The expression as the label it is added under (``mid(LPSI,RPSI)``)."""
    name, args = parse(text, where)
    return f"{name}({','.join(args)})"

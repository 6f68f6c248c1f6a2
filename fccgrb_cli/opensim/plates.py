"""Which body each force plate loads, stated by the user (``--plate 1=calcn_r``) as an OpenSim
ExternalLoads file states it for its forces, instead of found by proximity."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import replace

from fccgrb_cli.core.errors import InputError
from fccgrb_cli.model import Model
from fccgrb_cli.model.elements import PlateAssignment

__all__ = ["assigned", "parse_assignment"]


def parse_assignment(pairs: Iterable[str], bodies: Iterable[str],
                     option: str = "--plate") -> tuple[PlateAssignment, ...]:
    """``N=BODY`` pairs as plate assignments, in the order given.

    Parameters
    ----------
    pairs
        Each ``N=BODY``: plate N (1-based, as the trial numbers its plates) on BODY.
    bodies
        The moving bodies of the model.
    option
        How the pairs were given, for messages.

    Returns
    -------
    tuple of PlateAssignment

    Raises
    ------
    InputError
        A pair that is not ``N=BODY``, a plate number that is not a positive whole number or is
        given twice, a body the model does not have.
    """
    known = tuple(bodies)
    out: list[PlateAssignment] = []
    for pair in pairs:
        number, equals, body = (part.strip() for part in pair.partition("="))
        if not equals or not number or not body:
            raise InputError(f"{option}: expected PLATE=BODY (e.g. 1=calcn_r), got {pair!r:.60}")
        if not number.isdigit() or int(number) < 1:
            raise InputError(f"{option}: expected a plate number 1, 2, … before '=', got "
                             f"{number!r:.40}")
        if body not in known:
            raise InputError(f"{option}: expected a body of the model ({', '.join(known)[:200]}),"
                             f" got {body!r:.60}")
        if any(a.plate == int(number) for a in out):
            raise InputError(f"{option}: expected each plate assigned once, got plate {number} "
                             "twice")
        out.append(PlateAssignment(int(number), body))
    return tuple(out)


def assigned(model: Model, pairs: Iterable[str]) -> Model:
    """``model`` with its force plates on the bodies the ``N=BODY`` pairs name, in place of its
    own ``loads.force_plates``."""
    bodies = [body.name for body in model.bodies]
    return replace(model, force_plates=parse_assignment(pairs, bodies))

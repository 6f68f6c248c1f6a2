"""Which coordinates of a model with moving joints its tracked markers can determine.

A coordinate moves the bodies beyond the joints it drives; when none of them (nor any body beyond)
carries a tracked point and no coupling makes another coordinate follow it, no marker can tell
its value — a toe without markers. OpenSim's inverse kinematics leaves such a coordinate where it
starts; :func:`holding_unobserved` holds it at its default value, a coupling row θ = default.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from fccgrb_cli.model.elements import Model
from fccgrb_cli.model.spatial import Coupling, JointCoordinate, Pieces

__all__ = ["Fixed", "holding_unobserved", "unobserved"]


@dataclass(frozen=True)
class Fixed:
    """The constant function f(x) = value (rad or m)."""

    value: float

    def terms(self, x: float) -> tuple[float, float, float]:
        """f, f′, f″."""
        return self.value, 0.0, 0.0

    def pieces(self) -> Pieces:
        """One constant piece."""
        return Pieces.polynomial([self.value])


def unobserved(model: Model) -> list[str]:
    """The coordinates that move no tracked point and that nothing else sets (not held, and
    not the dependent of a coupling: Rajagopal's patella angle ``knee_angle_r_beta`` follows
    the knee angle, so holding it would hold the knee), in the model's order."""
    children: dict[str, list[str]] = {}
    for joint in model.moving_joints:
        children.setdefault(joint.parent, []).append(joint.child)
    tracked = {tp.body for tp in model.tracked_points}

    def seen_beyond(body: str) -> bool:
        return body in tracked or any(seen_beyond(c) for c in children.get(body, []))

    held = {c.dependent for c in model.couplings}  # locked, held or coupled: already set
    moving: set[str | None] = set()  # a coupling's independent may be None (held)
    for joint in model.moving_joints:
        if seen_beyond(joint.child):
            moving.update(joint.transform.coordinates)
    grown = True
    while grown:  # down a chain of couplings, whatever their order
        before = len(moving)
        moving.update(c.independent for c in model.couplings if c.dependent in moving)
        grown = len(moving) > before
    return [c.name for c in model.angles if c.name not in moving and c.name not in held]


def holding_unobserved(model: Model) -> tuple[Model, list[str]]:
    """The model with every :func:`unobserved` coordinate held at its default value, and their
    names."""
    unseen = unobserved(model)
    if not unseen:
        return model, []
    defaults = {c.name: c.default for c in model.angles if isinstance(c, JointCoordinate)}
    held = tuple(Coupling(f"{name} held", name, None, Fixed(defaults[name])) for name in unseen)
    return replace(model, couplings=model.couplings + held), unseen

"""The constraint library of docs/formulation.md §2, compiled into index arrays.

Each constraint becomes either linear vector equations ``F_a − F_b`` (spherical joints, ground
points), tracking equations ``F_a − y(t)`` (TC Eq. 29–36, TOC Eq. 37–38) or scalar dot equations
``F_a · F_b − c`` (rigid body, joint axes, angular relations AR Eq. 23–28 and MCR Eq. 10–22, where
``c`` is g(θ): cos θ for an angle, d itself for a distance coordinate). Rows are labelled so
rank reports and errors can name them.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from fccgrb_cli.core.errors import InputError
from fccgrb_cli.model import GROUND, Joint, Model
from fccgrb_cli.model.elements import DistanceCoordinate
from fccgrb_cli.model.spatial import JointCoordinate
from fccgrb_cli.system.features import FeatureTable, perpendiculars

AXES = ("x", "y", "z")


@dataclass
class ConstraintList:
    """Constraint equations gathered before they are frozen into a System."""

    linear: list[tuple[int, int, str]] = field(default_factory=list)
    tracking: list[tuple[int, int, str, float | None]] = field(default_factory=list)
    dots: list[tuple[int, int, float, str]] = field(default_factory=list)
    angle_dots: list[int] = field(default_factory=list)
    distance_dots: list[bool] = field(default_factory=list)
    sine_dots: list[int] = field(default_factory=list)
    sine_of: list[int] = field(default_factory=list)
    n_base: int = 0

    def dot(self, a: int, b: int, const: float, label: str) -> int:
        self.dots.append((a, b, const, label))
        return len(self.dots) - 1


def rigid_body(features: FeatureTable, out: ConstraintList, model: Model) -> None:
    """u·u = v·v = w·w = 1, u·v = u·w = v·w = 0 (full), or the first three of u, v (reduced)."""
    for body in model.bodies:
        u, v = features.vector(body.name, "u"), features.vector(body.name, "v")
        pairs = [(u, u, 1.0, "u·u"), (v, v, 1.0, "v·v"), (u, v, 0.0, "u·v")]
        if body.form == "full":
            w = features.vector(body.name, "w")
            pairs += [(w, w, 1.0, "w·w"), (u, w, 0.0, "u·w"), (v, w, 0.0, "v·w")]
        for a, b, const, what in pairs:
            out.dot(a, b, const, f"rigid body {body.name}: {what}")


def _axis_parallel(features: FeatureTable, out: ConstraintList, joint: Joint, label: str) -> None:
    """s_i · a_j = 0 and s_i · b_j = 0 with a_j, b_j ⟂ s_j fixed in body j: s_i ∥ s_j."""
    assert joint.axes is not None  # declared by every joint type that keeps axes parallel
    (bi, bj), (si, sj) = joint.bodies, joint.axes
    a_local, b_local = perpendiculars(features.local_of(bj, sj))
    axis_i = features.vector(bi, si)
    out.dot(axis_i, features.body_vector(bj, a_local), 0.0, f"{label}: axis ⟂ a")
    out.dot(axis_i, features.body_vector(bj, b_local), 0.0, f"{label}: axis ⟂ b")


def _on_axis(features: FeatureTable, out: ConstraintList, joint: Joint, label: str,
             axis: str) -> None:
    """(P_j − P_i) · a_i = 0 and (P_j − P_i) · b_i = 0 with a_i, b_i ⟂ body i's ``axis``: P_j
    stays on body i's axis line through P_i (cylindrical, prismatic and line joints)."""
    assert joint.points is not None  # declared by every joint type with a point on a line
    (bi, bj), (pi, pj) = joint.bodies, joint.points
    d = features.difference(features.point(bj, pj), features.point(bi, pi))
    a_local, b_local = perpendiculars(features.local_of(bi, axis))
    out.dot(d, features.body_vector(bi, a_local), 0.0, f"{label}: offset ⟂ a")
    out.dot(d, features.body_vector(bi, b_local), 0.0, f"{label}: offset ⟂ b")


def joint(features: FeatureTable, out: ConstraintList, joint: Joint) -> None:
    """The equations of one joint (docs/formulation.md §2 table)."""
    label = f"joint {joint.name} ({joint.type})"
    (bi, bj) = joint.bodies
    if joint.type in ("spherical", "revolute", "universal"):
        assert joint.points is not None  # the model's loader requires them for these types
        pi, pj = joint.points
        out.linear.append((features.point(bi, pi), features.point(bj, pj), label))
    if joint.type in ("revolute", "cylindrical", "prismatic", "parallel"):
        _axis_parallel(features, out, joint, label)
    if joint.type in ("cylindrical", "prismatic"):
        assert joint.axes is not None  # the model's loader requires them for these types
        _on_axis(features, out, joint, label, joint.axes[0])
    if joint.type == "line":
        assert joint.axis is not None  # the model's loader requires it for a line joint
        _on_axis(features, out, joint, label, joint.axis)
    if joint.type == "universal":
        assert joint.axes is not None  # the model's loader requires them for this type
        si, sj = joint.axes
        out.dot(features.vector(bi, si), features.vector(bj, sj), 0.0, f"{label}: arms ⟂")
    if joint.type == "prismatic":
        assert joint.lock is not None  # the model's loader requires it for this type
        li, lj = joint.lock
        out.dot(features.vector(bi, li), features.vector(bj, lj), 0.0, f"{label}: lock ⟂")


def angular(features: FeatureTable, out: ConstraintList, model: Model, kind: str) -> None:
    """One row per driven / mixed coordinate, F_a · F_b − g(θ_k): an angle's s1 · s2 − cos θ_k,
    a distance's (r_Q − r_P) · s − d_k; AR (kind 'driver', Eq. 23) or MCR ('coordinate',
    Eq. 10). ``out.distance_dots`` marks the distance rows (g(d) = d)."""
    tag = "AR" if kind == "driver" else "MCR"
    for coord in model.angles:
        if isinstance(coord, JointCoordinate):  # held by its moving joint's rows (moving.py)
            continue
        if isinstance(coord, DistanceCoordinate):
            offset = features.difference(features.point(coord.body2, coord.point2),
                                         features.point(coord.body1, coord.point1))
            row = out.dot(offset, features.vector(coord.body1, coord.axis), 0.0,
                          f"distance {coord.name} ({tag})")
        else:
            row = out.dot(features.vector(coord.body1, coord.vector1),
                          features.vector(coord.body2, coord.vector2), 0.0,
                          f"angle {coord.name} ({tag})")
            if coord.full:
                out.sine_dots.append(_sine_row(features, out, model, coord, tag))
                out.sine_of.append(len(out.angle_dots))
        out.angle_dots.append(row)
        out.distance_dots.append(coord.kind == "distance")


def _sine_row(features: FeatureTable, out: ConstraintList, model: Model, coord,
              tag: str) -> int:
    """The row (s1 × s2)·n − sin θ of a signed angle, written as a dot product of two body
    vectors (docs/signed_angles.md): s1·t with t = s2 × n when the axis n is fixed in body 2,
    t·s2 with t = n × s1 when it is fixed in body 1 (a rigid body carries cross products of its
    vectors along, so t's local components are the cross product of the local ones)."""
    axis_body, axis_name = coord.axis
    n = features.local_of(axis_body, axis_name)
    s1 = features.local_of(coord.body1, coord.vector1)
    s2 = features.local_of(coord.body2, coord.vector2)
    same = s2 if axis_body == coord.body2 else s1
    if abs(n @ same) > 1e-6 * np.linalg.norm(n) * np.linalg.norm(same):
        k = model.angles.index(coord)
        raise InputError(f"{model.source}: angles[{k}].axis: expected a vector perpendicular to "
                         f"{axis_body}'s vector of the angle {coord.name}, got "
                         f"{axis_name}·{coord.vector2 if same is s2 else coord.vector1} = "
                         f"{n @ same:.3g}")
    if axis_body == coord.body2:
        a = features.vector(coord.body1, coord.vector1)
        b = features.body_vector(coord.body2, np.cross(s2, n))
    else:
        a = features.body_vector(coord.body1, np.cross(n, s1))
        b = features.vector(coord.body2, coord.vector2)
    return out.dot(a, b, 0.0, f"angle {coord.name} ({tag}, sine)")


def tracking(features: FeatureTable, out: ConstraintList, model: Model) -> None:
    """TC for each tracked point, then TOC for each tracked vector; targets in that order."""
    slot = 0
    for tp in model.tracked_points:
        out.tracking.append((features.point(tp.body, tp.point), slot, f"track {tp.marker}",
                             tp.weight))
        slot += 1
    for tv in model.tracked_vectors:
        out.tracking.append((features.vector(tv.body, tv.vector), slot, f"track {tv.marker}",
                             tv.weight))
        slot += 1


def joint_neighbours(model: Model) -> dict[str, set[str]]:
    """Every body (and the ground) → the bodies a joint connects it to."""
    neighbours: dict[str, set[str]] = {GROUND: set(), **{b.name: set() for b in model.bodies}}
    pairs = [j.bodies for j in model.joints] + [(m.parent, m.child) for m in model.moving_joints]
    for a, b in pairs:
        neighbours[a].add(b)
        neighbours[b].add(a)
    return neighbours


def reachable(neighbours: dict[str, set[str]], start: str, seen: set[str]) -> set[str]:
    """The bodies reached from ``start`` through joints without entering ``seen`` (updated)."""
    seen.add(start)
    reached, stack = {start}, [start]
    while stack:
        for other in neighbours[stack.pop()] - seen:
            seen.add(other)
            reached.add(other)
            stack.append(other)
    return reached


def floating_bases(model: Model) -> tuple[str, ...]:
    """The first body of every group of bodies that no chain of joints ties to the ground: a
    floating base, whose 6 degrees of freedom the markers (MC) or base drivers (AD) determine."""
    return model.floating_bases


def base_drivers(features: FeatureTable, out: ConstraintList, model: Model) -> None:
    """Drivers of each floating base's coordinates, r − r*(t), u − u*(t), v − v*(t) (and w for
    a fully-defined body): the classical model's base, driven by its solved trajectory
    (docs/formulation.md §10). Written as tracking rows with targets after the markers'."""
    slot = len(out.tracking)
    for name in floating_bases(model):
        body = model.body(name)
        items = [("r", features._fixed(name, (0.0, 0.0, 0.0), True, ("origin", name)))]
        items += [(axis, features.vector(name, axis))
                  for axis in ("u", "v", "w")[: 3 if body.form == "full" else 2]]
        for what, feature in items:
            out.tracking.append((feature, slot, f"base {name}: {what}", None))
            slot += 1
            out.n_base += 1


def collect(model: Model, features: FeatureTable, *, angles: str, track: bool,
            base: bool = False) -> ConstraintList:
    """All constraint equations of the model for the given use of its angles; ``base`` adds
    the drivers of floating bases."""
    out = ConstraintList()
    rigid_body(features, out, model)
    for j in model.joints:
        joint(features, out, j)
    angular(features, out, model, angles)
    if track:
        tracking(features, out, model)
    if base:
        base_drivers(features, out, model)
    return out


__all__ = ["AXES", "GROUND", "ConstraintList", "collect"]

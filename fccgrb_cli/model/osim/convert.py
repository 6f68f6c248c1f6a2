"""An OpenSim model as a fccgrb :class:`Model` with mixed coordinates.

Each OpenSim body becomes a fully-defined body whose reference point and unit vectors are the
OpenSim body frame's origin and axes (so marker locations and the centre of mass keep their
numbers); its inertia is OpenSim's, about the centre of mass in the body frame. Each joint
becomes a moving joint (:mod:`fccgrb_cli.model.spatial`) between the joint frames, each fixed
in its body as a point (the origin) and three vectors (the axes); each coordinate becomes a
mixed coordinate of the solve, solved with the bodies. Markers are tracked points under their
own names; coupler constraints and locked coordinates become coupling rows; the initial pose is
the bodies placed by the coordinates' default values.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from fccgrb_cli.model.elements import (
    GROUND,
    Body,
    Ground,
    Inertia,
    Model,
    Point,
    Pose,
    TrackedPoint,
    Vector,
    _frozen,
)
from fccgrb_cli.model.observed import holding_unobserved
from fccgrb_cli.model.osim.document import OsimFrame, OsimJoint, OsimModel, parse_osim, read_osim
from fccgrb_cli.model.osim.functions import Constant
from fccgrb_cli.model.spatial import (
    Coupling,
    JointCoordinate,
    MovingJoint,
    SpatialTransform,
)

__all__ = ["body_poses", "for_trial", "load_osim", "model_from_osim", "parse_osim_model",]

AXES = ("x", "y", "z")


def _origin(joint: OsimJoint, side: str) -> str:
    return f"{joint.name}:{side}"


def _axis(joint: OsimJoint, side: str, k: int) -> str:
    return f"{joint.name}:{side}:{AXES[k]}"


def body_poses(osim: OsimModel, values: dict[str, float]
               ) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Every body's rotation (3 × 3, columns its axes) and origin (m) in the ground at the
    coordinates' ``values`` (rad, m): forward kinematics down the joint tree."""
    pose = {GROUND: (np.eye(3), np.zeros(3))}
    pending = list(osim.joints)
    while pending:
        joint = next(j for j in pending if j.parent.body in pose)
        pending.remove(joint)
        R_body, r_body = pose[joint.parent.body]
        R_P = R_body @ np.asarray(joint.parent.rotation)
        o_P = r_body + R_body @ np.asarray(joint.parent.translation)
        transform = SpatialTransform(joint.axes)
        h = transform.terms(np.array([values[c] for c in transform.coordinates]))[0]
        R_C, o_C = R_P @ h[:9].reshape(3, 3), o_P + R_P @ h[9:]
        R_BC, p_BC = np.asarray(joint.child.rotation), np.asarray(joint.child.translation)
        R_child = R_C @ R_BC.T
        pose[joint.child.body] = (R_child, o_C - R_child @ p_BC)
    return pose


def _frame_members(frame: OsimFrame, joint: OsimJoint, side: str
                   ) -> tuple[dict[str, Point], dict[str, Vector]]:
    """The joint frame's origin and axes as a point and vectors of its body (local), or of the
    ground (global, at the ground's fixed pose)."""
    R, p = np.asarray(frame.rotation), np.asarray(frame.translation)
    points = {_origin(joint, side): Point(_origin(joint, side), _vec(p))}
    vectors = {_axis(joint, side, k): Vector(_axis(joint, side, k), _vec(R[:, k]))
               for k in range(3)}
    return points, vectors


def _axes(names: str) -> dict[str, Vector]:
    """A body's own unit vectors u, v, w (the ground's x, y, z), as every model has them."""
    return {n: Vector(n, _vec(np.eye(3)[k])) for k, n in enumerate(names)}


def _vec(a: np.ndarray) -> tuple[float, float, float]:
    return (float(a[0]), float(a[1]), float(a[2]))


def model_from_osim(osim: OsimModel, text: str = "") -> Model:
    """The fccgrb model of an OpenSim model.

    Parameters
    ----------
    osim
        The model read by :func:`fccgrb_cli.model.osim.document.read_osim`.
    text
        The ``.osim`` document, kept so that worker processes rebuild the same model.

    Returns
    -------
    Model
        Fully-defined bodies at the default pose, moving joints, the OpenSim coordinates as
        mixed coordinates (rad, m), the markers as tracked points, couplings for coupler
        constraints and locked coordinates.
    """
    defaults = {c.name: c.default for c in osim.coordinates}
    for coupler in osim.couplers:  # assembled as OpenSim assembles: dependents follow
        defaults[coupler.dependent] = coupler.function.terms(defaults[coupler.independent])[0]
    pose = body_poses(osim, defaults)
    points: dict[str, dict[str, Point]] = {b.name: {} for b in osim.bodies}
    vectors: dict[str, dict[str, Vector]] = {b.name: _axes("uvw") for b in osim.bodies}
    points[GROUND], vectors[GROUND] = {}, _axes("xyz")
    moving = []
    for joint in osim.joints:
        for side, frame in (("parent", joint.parent), ("child", joint.child)):
            p, v = _frame_members(frame, joint, side)
            points[frame.body].update(p)
            vectors[frame.body].update(v)
        moving.append(MovingJoint(
            name=joint.name, parent=joint.parent.body, child=joint.child.body,
            parent_origin=_origin(joint, "parent"),
            parent_axes=(_axis(joint, "parent", 0), _axis(joint, "parent", 1),
                         _axis(joint, "parent", 2)),
            child_origin=_origin(joint, "child"),
            child_axes=(_axis(joint, "child", 0), _axis(joint, "child", 1),
                        _axis(joint, "child", 2)),
            transform=SpatialTransform(joint.axes)))
    for marker in osim.markers:
        points[marker.body][marker.name] = Point(marker.name, marker.location)
    bodies = []
    for b in osim.bodies:
        R, r = pose[b.name]
        bodies.append(Body(
            name=b.name, form="full", points=_frozen(points[b.name]),
            vectors=_frozen(vectors[b.name]),
            pose=Pose(r=_vec(r), u=_vec(R[:, 0]), v=_vec(R[:, 1]), w=_vec(R[:, 2])),
            inertia=Inertia(b.mass, b.com, b.inertia)))
    couplings = [Coupling(c.name, c.dependent, c.independent, c.function) for c in osim.couplers]
    couplings += [Coupling(f"{c.name} locked", c.name, None, Constant(c.default))
                  for c in osim.coordinates if c.locked]
    return Model(
        name=osim.name or Path(osim.source).stem,
        gravity=osim.gravity,
        ground=Ground(points=_frozen(points[GROUND]), vectors=_frozen(vectors[GROUND])),
        bodies=tuple(bodies),
        joints=(),
        angles=tuple(JointCoordinate(c.name, c.motion == "translational", defaults[c.name],
                                     c.range, c.clamped) for c in osim.coordinates),
        tracked_points=tuple(TrackedPoint(m.body, m.name, m.name) for m in osim.markers
                             if m.body != GROUND),
        source=osim.source,
        text=text,
        moving_joints=tuple(moving),
        couplings=tuple(couplings),
    )


def for_trial(model: Model, trial, mapping: dict[str, str]) -> Model:
    """The model as OpenSim's inverse kinematics uses it on ``trial``: tracking only its
    markers the trial has (by name, or by a ``mapping`` name → label), and holding at its
    default every coordinate that moves none of them (no marker beyond its joint: a toe without
    markers), which the markers cannot determine; a note on stderr names each."""
    present = tuple(m for m in model.marker_labels if trial.find(mapping.get(m, m)) is not None)
    left = [m for m in model.marker_labels if m not in present]
    if left and present:
        sys.stderr.write(f"fccgrb: note: {model.source}: {len(left)} model markers are not in "
                         f"{trial.path} and are not tracked: {', '.join(left)}\n")
        model = model.with_tracked(present)
    model, unseen = holding_unobserved(model)
    if unseen:
        sys.stderr.write(f"fccgrb: note: {model.source}: no tracked marker moves with "
                         f"{', '.join(unseen)}: held at the default value\n")
    return model


def parse_osim_model(text: str, source: str) -> Model:
    """The model of an ``.osim`` document given as text (a worker rebuilding a run's model)."""
    return model_from_osim(parse_osim(text.encode("utf-8"), source), text)


def load_osim(path: str | Path) -> Model:
    """Read an ``.osim`` file as a model; one note on stderr names what it ignores (muscles,
    wrapping, geometry, controllers, probes: no part of kinematics or inverse dynamics)."""
    osim = read_osim(path)
    if osim.ignored:
        sys.stderr.write(f"fccgrb: note: {path}: ignored {', '.join(osim.ignored)} (forces, "
                         f"wrapping, geometry, controllers and probes play no part in the "
                         f"kinematics and inverse dynamics)\n")
    return model_from_osim(osim, Path(path).read_text(encoding="utf-8", errors="replace"))

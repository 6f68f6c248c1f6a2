"""OpenSim model files (``.osim``) read into a typed, immutable description.

Both layouts are read: OpenSim 4.x (``BodySet``, ``JointSet``, ``Ground``, joints whose
``socket_parent_frame``/``socket_child_frame`` name ``PhysicalOffsetFrame`` s, markers with a
``socket_parent_frame``) and 3.x (each ``Body`` holds its ``Joint``, with ``parent_body``,
``location_in_parent``, ``orientation_in_parent``, ``location``, ``orientation``). Every joint
becomes the SpatialTransform OpenSim gives it: three rotations applied one after the other about
axes of the turning frame (body-fixed), then a translation along axes of the parent's joint frame,
each amount a function of one coordinate or a constant (docs/opensim.md). Muscles, wrapping,
geometry, controllers, probes and contact geometry are ignored (one note); any other element the
formulation cannot represent is refused in one line naming the file and the element's path.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path
from typing import NoReturn

import numpy as np

from fccgrb_cli.core.errors import InputError
from fccgrb_cli.core.xml import element_path, number, numbers, parse, parse_bytes
from fccgrb_cli.model.osim.functions import (
    Constant,
    Function,
    LinearFunction,
    Multiplier,
    NaturalSpline,
    PiecewiseLinear,
    Polynomial,
    SimmSpline,
)
from fccgrb_cli.model.spatial import SpatialAxis as TransformAxis
from fccgrb_cli.model.spatial import axis_rotation

__all__ = ["Coupler", "OsimBody", "OsimCoordinate", "OsimFrame", "OsimJoint", "OsimMarker",
           "OsimModel", "parse_osim", "read_osim", "rotation_xyz"]

Vec3 = tuple[float, float, float]
Mat3 = tuple[Vec3, Vec3, Vec3]
GROUND = "ground"

# Elements that carry nothing the kinematics and inverse dynamics use: ignored with one note.
IGNORED = frozenset({"ForceSet", "ControllerSet", "ProbeSet", "ContactGeometrySet",
                     "ComponentSet", "WrapObjectSet", "VisibleObject", "attached_geometry",
                     "ModelVisualPreferences", "credits", "publications", "defaults",
                     "FrameGeometry", "GeometrySet", "AnalysisSet"})
FUNCTION_TAGS = ("Constant", "LinearFunction", "SimmSpline", "NaturalCubicSpline", "natCubicSpline",
                 "GCVSpline", "PiecewiseLinearFunction", "PolynomialFunction",
                 "MultiplierFunction")
# Old names OpenSim reads as a SimmSpline (Object::renameType in its osimCommon registration:
# the old NaturalCubicSpline was not a natural spline), so a 2.x/3.x knee evaluates as there.
SIMM_SPLINE_TAGS = ("SimmSpline", "NaturalCubicSpline", "natCubicSpline")
# OpenSim refuses a CustomJoint two of whose rotation (or translation) axes have a cross product
# shorter than this (CustomJoint::extendFinalizeFromProperties).
COLLINEAR = 1e-5
# Standard joints as SpatialTransforms: per coordinate, (rotation or translation, axis).
X, Y, Z = (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)
STANDARD_JOINTS: dict[str, tuple[tuple[str, Vec3], ...]] = {
    "WeldJoint": (),
    "PinJoint": (("rotation", Z),),
    "SliderJoint": (("translation", X),),
    "UniversalJoint": (("rotation", X), ("rotation", Y)),
    "BallJoint": (("rotation", X), ("rotation", Y), ("rotation", Z)),
    "GimbalJoint": (("rotation", X), ("rotation", Y), ("rotation", Z)),
    "FreeJoint": (("rotation", X), ("rotation", Y), ("rotation", Z),
                  ("translation", X), ("translation", Y), ("translation", Z)),
    "PlanarJoint": (("rotation", Z), ("translation", X), ("translation", Y)),
}


@dataclass(frozen=True)
class OsimBody:
    """A body: mass (kg), centre of mass in the body frame (m), inertia about the centre of mass
    in the body frame (kg·m², 3 × 3)."""

    name: str
    mass: float
    com: Vec3
    inertia: tuple[Vec3, Vec3, Vec3]


@dataclass(frozen=True)
class OsimFrame:
    """A frame fixed in ``body`` (or the ground): its origin (m) and axes (columns of
    ``rotation``) in the body frame."""

    body: str
    translation: Vec3
    rotation: Mat3


@dataclass(frozen=True)
class OsimCoordinate:
    """A generalized coordinate: rad for rotational, m for translational."""

    name: str
    joint: str
    motion: str
    default: float
    range: tuple[float, float]
    locked: bool
    clamped: bool


@dataclass(frozen=True)
class OsimJoint:
    """The child's joint frame moves in the parent's joint frame by the ``axes`` (a
    CustomJoint's six; a standard joint's, one per coordinate)."""

    name: str
    type: str
    parent: OsimFrame
    child: OsimFrame
    axes: tuple[TransformAxis, ...]


@dataclass(frozen=True)
class Coupler:
    """CoordinateCouplerConstraint: ``dependent = function(independent)``."""

    name: str
    independent: str
    dependent: str
    function: Function


@dataclass(frozen=True)
class OsimMarker:
    """A marker at ``location`` (m) in ``body``'s frame."""

    name: str
    body: str
    location: Vec3


@dataclass(frozen=True)
class OsimModel:
    """What an ``.osim`` file holds that the kinematics and inverse dynamics use."""

    name: str
    source: str
    gravity: Vec3
    bodies: tuple[OsimBody, ...]
    joints: tuple[OsimJoint, ...]
    coordinates: tuple[OsimCoordinate, ...]
    markers: tuple[OsimMarker, ...]
    couplers: tuple[Coupler, ...]
    ignored: tuple[str, ...]


def rotation_xyz(angles: Vec3) -> np.ndarray:
    """OpenSim's ``orientation``: body-fixed X-Y-Z rotations, R = Rx(a) Ry(b) Rz(c) (3 × 3)."""
    out = np.eye(3)
    for axis, angle in zip(np.eye(3), angles, strict=True):
        out = out @ axis_rotation(axis, angle)
    return out


class _Reader:
    """Walks the document keeping each element's ancestors, for one-line messages."""

    def __init__(self, source: str):
        self.source = source
        self.ignored: set[str] = set()

    def fail(self, where: str, what: str) -> NoReturn:
        raise InputError(f"{self.source}: {where}: {what}")

    def where(self, parents: list[ET.Element], element: ET.Element) -> str:
        return element_path(parents, element)

    def text(self, element: ET.Element, tag: str, parents: list[ET.Element],
             default: str | None = None) -> str:
        found = element.find(tag)
        if found is None or found.text is None or not found.text.strip():
            if default is not None:
                return default
            self.fail(self.where(parents, element), f"expected a <{tag}>")
        return found.text.strip()

    def vec3(self, element: ET.Element, tag: str, parents: list[ET.Element],
             default: Vec3 | None = None) -> Vec3:
        found = element.find(tag)
        if found is None:
            if default is not None:
                return default
            self.fail(self.where(parents, element), f"expected a <{tag}>")
        values = numbers(found.text, f"{self.source}: {self.where([*parents, element], found)}", 3)
        return (values[0], values[1], values[2])

    def scalar(self, element: ET.Element, tag: str, parents: list[ET.Element],
               default: float | None = None) -> float:
        found = element.find(tag)
        if found is None:
            if default is not None:
                return default
            self.fail(self.where(parents, element), f"expected a <{tag}>")
        return number(found.text, f"{self.source}: {self.where([*parents, element], found)}")

    def flag(self, element: ET.Element, tag: str, parents: list[ET.Element]) -> bool:
        value = self.text(element, tag, parents, "false").lower()
        if value not in ("true", "false"):
            found = element.find(tag)
            assert found is not None  # the default, "false", is valid: the value is the tag's
            self.fail(self.where([*parents, element], found),
                      f"expected true or false, got {value!r:.40}")
        return value == "true"


def _name(element: ET.Element) -> str:
    return (element.get("name") or "").strip()


def _last(path: str) -> str:
    """The name a socket path ends in: '/bodyset/femur_r', '../femur_r' and 'femur_r' alike."""
    return path.strip().rstrip("/").split("/")[-1]


# --- functions ---------------------------------------------------------------------------------
def _function(r: _Reader, holder: ET.Element, parents: list[ET.Element]) -> Function:
    """The one function element inside ``holder`` (a <function> or coupler function holder)."""
    kids = list(holder)
    if len(kids) != 1:
        r.fail(r.where(parents, holder), f"expected one function element, got {len(kids)}")
    return _function_element(r, kids[0], [*parents, holder])


def _property_function(r: _Reader, element: ET.Element, name: str, parents: list[ET.Element]
                       ) -> Function | None:
    """The function held by ``element``'s property ``name``: 3.x wraps it
    (``<function><SimmSpline>…``), 4.x names it (``<SimmSpline name="function">…``); None when
    there is neither."""
    holder = element.find(name)
    if holder is not None:
        return _function(r, holder, [*parents, element])
    for child in element:
        if child.get("name") == name:
            return _function_element(r, child, [*parents, element])
    return None


def _knots(r: _Reader, element: ET.Element, parents: list[ET.Element]
           ) -> tuple[tuple[float, ...], tuple[float, ...]]:
    where = f"{r.source}: {r.where(parents, element)}"
    x = numbers(r.text(element, "x", parents), f"{where}/x")
    y = numbers(r.text(element, "y", parents), f"{where}/y")
    if len(x) != len(y) or len(x) < 2:
        r.fail(r.where(parents, element), f"expected as many x as y values and at least 2, got "
                                          f"{len(x)} and {len(y)}")
    if np.any(np.diff(x) <= 0):
        r.fail(r.where(parents, element), "expected strictly increasing x values")
    return x, y


def _function_element(r: _Reader, element: ET.Element, parents: list[ET.Element]) -> Function:
    tag, where = element.tag, r.where(parents, element)
    if tag == "Constant":
        return Constant(r.scalar(element, "value", parents))
    if tag == "LinearFunction":
        c = numbers(r.text(element, "coefficients", parents), f"{r.source}: {where}", 2)
        return LinearFunction(c[0], c[1])
    if tag == "PolynomialFunction":
        c = numbers(r.text(element, "coefficients", parents), f"{r.source}: {where}")
        if not c:
            r.fail(where, "expected at least one coefficient")
        return Polynomial(c)
    if tag == "MultiplierFunction":
        inner = _property_function(r, element, "function", parents)
        if inner is None:
            r.fail(where, "expected a function")
        return Multiplier(inner, r.scalar(element, "scale", parents, 1.0))
    if tag in (*SIMM_SPLINE_TAGS, "PiecewiseLinearFunction", "GCVSpline"):
        x, y = _knots(r, element, parents)
        if tag in SIMM_SPLINE_TAGS:
            return SimmSpline(x, y)
        if tag == "PiecewiseLinearFunction":
            return PiecewiseLinear(x, y)
        # OpenSim writes the degree as half_order m (degree 2m − 1) and has no default for it
        half_order = r.scalar(element, "half_order", parents)
        smoothing = r.scalar(element, "error_variance", parents, 0.0)
        if half_order not in (1, 2, 3, 4) or smoothing != 0.0:
            r.fail(where, f"expected half_order 1, 2, 3 or 4 (degree 1, 3, 5 or 7) and no "
                          f"smoothing (error_variance 0), got half_order {half_order:g}, "
                          f"error_variance {smoothing:g}")
        degree = 2 * int(half_order) - 1
        if len(x) < degree + 1:  # OpenSim's gcvspl needs 2m points
            r.fail(where, f"expected at least {degree + 1} points for half_order "
                          f"{int(half_order)}, got {len(x)}")
        return NaturalSpline(x, y, degree)
    r.fail(where, f"unknown function type {tag} (known: {', '.join(FUNCTION_TAGS)})")


# --- bodies, frames, coordinates -----------------------------------------------------------------
def _body(r: _Reader, element: ET.Element, parents: list[ET.Element]) -> OsimBody:
    name = _name(element)
    mass = r.scalar(element, "mass", parents, 0.0)
    com = r.vec3(element, "mass_center", parents, (0.0, 0.0, 0.0))
    six = element.find("inertia")
    if six is not None:
        xx, yy, zz, xy, xz, yz = numbers(six.text, f"{r.source}: "
                                         f"{r.where([*parents, element], six)}", 6)
    else:
        xx, yy, zz, xy, xz, yz = (r.scalar(element, f"inertia_{k}", parents, 0.0)
                                  for k in ("xx", "yy", "zz", "xy", "xz", "yz"))
    if mass < 0:
        r.fail(r.where(parents, element), f"expected a mass ≥ 0, got {mass:g}")
    return OsimBody(name, mass, com, ((xx, xy, xz), (xy, yy, yz), (xz, yz, zz)))


def _coordinate(r: _Reader, element: ET.Element, parents: list[ET.Element], joint: str,
                default_motion: str) -> OsimCoordinate:
    motion = r.text(element, "motion_type", parents, default_motion)
    if motion not in ("rotational", "translational", "coupled"):
        r.fail(r.where(parents, element), f"expected motion_type rotational, translational or "
                                          f"coupled, got {motion!r:.40}")
    low, high = numbers(r.text(element, "range", parents, "-1e6 1e6"),
                        f"{r.source}: {r.where(parents, element)}/range", 2)
    return OsimCoordinate(_name(element), joint, motion,
                          r.scalar(element, "default_value", parents, 0.0), (low, high),
                          r.flag(element, "locked", parents), r.flag(element, "clamped", parents))


def _frame(body: str, translation: Vec3, orientation: Vec3) -> OsimFrame:
    R = rotation_xyz(orientation)
    return OsimFrame(body, translation, _mat3(R))


def _compose(outer: OsimFrame, translation: Vec3, orientation: Vec3) -> OsimFrame:
    """A frame given in ``outer``, expressed in outer's body."""
    R0 = np.asarray(outer.rotation)
    R = R0 @ rotation_xyz(orientation)
    p = np.asarray(outer.translation) + R0 @ np.asarray(translation)
    return OsimFrame(outer.body, _vec3(p), _mat3(R))


def _vec3(p: np.ndarray) -> Vec3:
    """A 3-vector as a tuple of Python floats."""
    return (float(p[0]), float(p[1]), float(p[2]))


def _mat3(R: np.ndarray) -> Mat3:
    """A 3 × 3 matrix as a tuple of rows of Python floats."""
    return (_vec3(R[0]), _vec3(R[1]), _vec3(R[2]))


# --- joints ------------------------------------------------------------------------------------
def _spatial_transform(r: _Reader, joint: ET.Element, parents: list[ET.Element],
                       coordinate_names: tuple[str, ...]) -> tuple[TransformAxis, ...]:
    """The six TransformAxis of a CustomJoint (rotation1–3, translation1–3), in that order."""
    where = r.where(parents, joint)
    transform = joint.find("SpatialTransform")
    if transform is None:
        r.fail(where, "expected a <SpatialTransform>")
    inside = [*parents, joint, transform]
    found = {_name(a): a for a in transform.findall("TransformAxis")}
    out = []
    for kind in ("rotation", "translation"):
        for k in (1, 2, 3):
            element = found.get(f"{kind}{k}")
            if element is None:
                r.fail(r.where([*parents, joint], transform), f"expected a TransformAxis named "
                                                              f"{kind}{k}")
            out.append(_transform_axis(r, element, inside, kind, coordinate_names))
    for first in (0, 3):  # as OpenSim's CustomJoint checks them, constant axes included
        for a, b in ((0, 1), (0, 2), (1, 2)):
            if np.linalg.norm(np.cross(out[first + a].axis, out[first + b].axis)) < COLLINEAR:
                kind = out[first].kind
                r.fail(r.where([*parents, joint], transform),
                       f"{kind}{a + 1} and {kind}{b + 1} have collinear axes, which OpenSim "
                       f"refuses (|a × b| < {COLLINEAR:g})")
    return tuple(out)


def _transform_axis(r: _Reader, element: ET.Element, parents: list[ET.Element], kind: str,
                    coordinate_names: tuple[str, ...]) -> TransformAxis:
    where = r.where(parents, element)
    axis = np.asarray(r.vec3(element, "axis", parents))
    if np.linalg.norm(axis) < 1e-9:
        r.fail(f"{where}/axis", "expected a non-zero axis")
    names = tuple((element.findtext("coordinates") or "").split())
    found = _property_function(r, element, "function", parents)
    if found is None and names:  # no default is assumed for a moving axis
        r.fail(where, f"expected a function of {names[0]}")
    function = Constant(0.0) if found is None else found
    if len(names) > 1:
        r.fail(where, f"expected at most one coordinate per transform axis, got {len(names)}")
    if names and names[0] not in coordinate_names:
        r.fail(where, f"coordinate {names[0]!r} is not one of the joint's coordinates")
    if not names and not function.constant:
        r.fail(where, "expected a Constant function for an axis without a coordinate")
    unit = axis / np.linalg.norm(axis)
    return TransformAxis(kind, (float(unit[0]), float(unit[1]), float(unit[2])),
                         names[0] if names else None, function)


def _standard_axes(r: _Reader, tag: str, where: str, names: tuple[str, ...]
                   ) -> tuple[TransformAxis, ...]:
    plan = STANDARD_JOINTS[tag]
    if len(names) != len(plan):
        r.fail(where, f"expected {len(plan)} coordinates for a {tag}, got {len(names)}")
    axes = [TransformAxis(kind, axis, name, LinearFunction(1.0, 0.0))
            for (kind, axis), name in zip(plan, names, strict=True)]
    return tuple(axes)


def _joint_axes(r: _Reader, element: ET.Element, parents: list[ET.Element],
                names: tuple[str, ...]) -> tuple[TransformAxis, ...]:
    if element.tag == "CustomJoint":
        return _spatial_transform(r, element, parents, names)
    if element.tag in STANDARD_JOINTS:
        return _standard_axes(r, element.tag, r.where(parents, element), names)
    r.fail(r.where(parents, element), f"unknown joint type {element.tag} (known: CustomJoint, "
                                      f"{', '.join(STANDARD_JOINTS)})")


def _coordinates_of(r: _Reader, element: ET.Element, parents: list[ET.Element]
                    ) -> list[OsimCoordinate]:
    """A joint's coordinates: 3.x ``CoordinateSet/objects/Coordinate``, 4.x ``coordinates``."""
    holder = element.find("CoordinateSet/objects")
    if holder is not None:
        coordinate_set = element.find("CoordinateSet")
        assert coordinate_set is not None  # it holds the <objects> found
        inside = [*parents, element, coordinate_set, holder]
    else:
        holder = element.find("coordinates")
        if holder is None:
            return []
        inside = [*parents, element, holder]
    plan = STANDARD_JOINTS.get(element.tag, ())
    drives = _custom_motions(element)
    out = []
    for k, c in enumerate(holder.findall("Coordinate")):
        default = plan[k][0] + "al" if k < len(plan) else drives.get(_name(c), "rotational")
        out.append(_coordinate(r, c, inside, _name(element), default))
    return out


def _custom_motions(joint: ET.Element) -> dict[str, str]:
    """A CustomJoint's coordinates' motion types as OpenSim 4 derives them (a 4.x Coordinate
    states none): rotational when the coordinate drives a rotation axis of the
    SpatialTransform, translational when it drives translation axes only (``pelvis_tx`` of a
    planar gait model), coupled when it drives both. An explicit ``motion_type`` (3.x) wins."""
    transform = joint.find("SpatialTransform")
    if transform is None:
        return {}
    kinds: dict[str, set[str]] = {}
    for axis in transform.findall("TransformAxis"):
        kind = "rotation" if _name(axis).startswith("rotation") else "translation"
        for coordinate in (axis.findtext("coordinates") or "").split():
            kinds.setdefault(coordinate, set()).add(kind)
    return {name: "coupled" if len(found) > 1 else
            ("rotational" if "rotation" in found else "translational")
            for name, found in kinds.items()}


def _check_reverse(r: _Reader, element: ET.Element, parents: list[ET.Element]) -> None:
    if r.flag(element, "reverse", parents):
        r.fail(r.where(parents, element), "a reversed joint (reverse true) is not supported")


# --- the two layouts ---------------------------------------------------------------------------
def _read_3x(r: _Reader, model: ET.Element, top: list[ET.Element], bodies: list[OsimBody],
             joints: list[OsimJoint], coordinates: list[OsimCoordinate]) -> None:
    """3.x: each Body holds its Joint (``parent_body``, ``location_in_parent`` …)."""
    body_set = model.find("BodySet")
    objects = body_set.find("objects") if body_set is not None else None
    if body_set is None or objects is None:
        r.fail(element_path(top[:-1], model), "expected a <BodySet> with <objects>")
    parents = [*top, body_set, objects]
    for element in objects:
        if element.tag != "Body":
            r.fail(r.where(parents, element), f"expected a Body, got {element.tag}")
        body = _body(r, element, parents)
        holder = element.find("Joint")
        kids = list(holder) if holder is not None else []
        if body.name == GROUND:
            if kids:
                r.fail(r.where(parents, element), "the ground cannot have a joint")
            continue
        bodies.append(body)
        if len(kids) != 1:
            r.fail(r.where(parents, element), f"expected one joint inside <Joint>, got "
                                              f"{len(kids)}")
        assert holder is not None  # it holds the one joint
        inside = [*parents, element, holder]
        joint = kids[0]
        _check_reverse(r, joint, inside)
        found = _coordinates_of(r, joint, inside)
        coordinates.extend(found)
        names = tuple(c.name for c in found)
        axes = _joint_axes(r, joint, inside, names)
        parent = r.text(joint, "parent_body", inside)
        parent_frame = _frame(parent, r.vec3(joint, "location_in_parent", inside, (0, 0, 0)),
                              r.vec3(joint, "orientation_in_parent", inside, (0, 0, 0)))
        child_frame = _frame(body.name, r.vec3(joint, "location", inside, (0, 0, 0)),
                             r.vec3(joint, "orientation", inside, (0, 0, 0)))
        joints.append(OsimJoint(_name(joint), joint.tag, parent_frame, child_frame, axes))


def _offset_frames(r: _Reader, joint: ET.Element, parents: list[ET.Element]
                   ) -> dict[str, tuple[str, Vec3, Vec3, str]]:
    """A 4.x joint's PhysicalOffsetFrames: name → (parent path, translation, orientation, where)."""
    holder = joint.find("frames")
    out: dict[str, tuple[str, Vec3, Vec3, str]] = {}
    if holder is None:
        return out
    inside = [*parents, joint, holder]
    for frame in holder:
        where = r.where(inside, frame)
        if frame.tag != "PhysicalOffsetFrame":
            r.fail(where, f"expected a PhysicalOffsetFrame, got {frame.tag}")
        out[_name(frame)] = (r.text(frame, "socket_parent", inside),
                             r.vec3(frame, "translation", inside, (0, 0, 0)),
                             r.vec3(frame, "orientation", inside, (0, 0, 0)), where)
    return out


def _resolve(r: _Reader, path: str, frames: dict, known: set[str], where: str,
             depth: int = 0) -> OsimFrame:
    """The frame a socket path names: a joint's offset frame (its parent resolved in turn), a
    body or the ground."""
    name = _last(path)
    if name in frames and depth < 8:
        parent, translation, orientation, inner = frames[name]
        outer = _resolve(r, parent, {k: v for k, v in frames.items() if k != name}, known, inner,
                         depth + 1)
        return _compose(outer, translation, orientation)
    if name in known:
        return OsimFrame(name, (0.0, 0.0, 0.0), ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)))
    r.fail(where, f"frame {path!r} is neither one of the joint's frames, a body nor the ground")


def _read_4x(r: _Reader, model: ET.Element, top: list[ET.Element], bodies: list[OsimBody],
             joints: list[OsimJoint], coordinates: list[OsimCoordinate]) -> None:
    """4.x: BodySet and JointSet apart; joints connect offset frames by socket paths."""
    body_set = model.find("BodySet/objects")
    if body_set is not None:
        set_element = model.find("BodySet")
        assert set_element is not None  # it holds the <objects> found
        parents = [*top, set_element, body_set]
        for element in body_set:
            if element.tag != "Body":
                r.fail(r.where(parents, element), f"expected a Body, got {element.tag}")
            bodies.append(_body(r, element, parents))
    _unique(r, [b.name for b in bodies] + [GROUND], "body", element_path(top[:-1], model))
    known = {b.name for b in bodies} | {GROUND}
    joint_set = model.find("JointSet/objects")
    if joint_set is None:
        return
    set_element = model.find("JointSet")
    assert set_element is not None  # it holds the <objects> found
    parents = [*top, set_element, joint_set]
    for joint in joint_set:
        where = r.where(parents, joint)
        _check_reverse(r, joint, parents)
        found = _coordinates_of(r, joint, parents)
        coordinates.extend(found)
        axes = _joint_axes(r, joint, parents, tuple(c.name for c in found))
        frames = _offset_frames(r, joint, parents)
        parent = _resolve(r, r.text(joint, "socket_parent_frame", parents), frames, known,
                          f"{where}/socket_parent_frame")
        child = _resolve(r, r.text(joint, "socket_child_frame", parents), frames, known,
                         f"{where}/socket_child_frame")
        if child.body == GROUND:
            r.fail(where, "the ground cannot be a joint's child")
        joints.append(OsimJoint(_name(joint), joint.tag, parent, child, axes))


def _unique(r: _Reader, names: list[str], what: str, where: str) -> None:
    seen: set[str] = set()
    for name in names:
        if not name:
            r.fail(where, f"a {what} without a name")
        if name in seen:
            r.fail(where, f"{what} {name!r} is named twice")
        seen.add(name)


def _markers(r: _Reader, model: ET.Element, top: list[ET.Element], known: set[str]
             ) -> list[OsimMarker]:
    holder = model.find("MarkerSet/objects")
    if holder is None:
        return []
    set_element = model.find("MarkerSet")
    assert set_element is not None  # it holds the <objects> found
    parents = [*top, set_element, holder]
    out = []
    for element in holder:
        where = r.where(parents, element)
        if element.tag != "Marker":
            r.fail(where, f"expected a Marker, got {element.tag}")
        body = element.findtext("socket_parent_frame") or element.findtext("body") or ""
        name = _last(body)
        if name not in known:
            r.fail(where, f"marker on {body.strip()!r}, which is not a body of the model")
        out.append(OsimMarker(_name(element), name, r.vec3(element, "location", parents)))
    _unique(r, [m.name for m in out], "marker", r.where(top[:-1], model))
    return out


def _couplers(r: _Reader, model: ET.Element, top: list[ET.Element]) -> list[Coupler]:
    holder = model.find("ConstraintSet/objects")
    if holder is None:
        return []
    set_element = model.find("ConstraintSet")
    assert set_element is not None  # it holds the <objects> found
    parents = [*top, set_element, holder]
    out = []
    for element in holder:
        where = r.where(parents, element)
        if element.tag != "CoordinateCouplerConstraint":
            r.fail(where, f"cannot represent a {element.tag} (only CoordinateCouplerConstraint)")
        if not r.flag(element, "isDisabled", parents) and \
                r.text(element, "isEnforced", parents, "true").lower() != "false":
            independent = r.text(element, "independent_coordinate_names", parents).split()
            if len(independent) != 1:
                r.fail(where, f"expected one independent coordinate, got {len(independent)}")
            function = _property_function(r, element, "coupled_coordinates_function", parents)
            if function is None:
                r.fail(where, "expected a coupled_coordinates_function")
            out.append(Coupler(_name(element), independent[0],
                               r.text(element, "dependent_coordinate_name", parents), function))
    return out


KNOWN_MODEL_CHILDREN = frozenset({"BodySet", "JointSet", "Ground", "ConstraintSet", "MarkerSet",
                                  "gravity", "length_units", "force_units", "defaults",
                                  "ContactGeometrySet", "ForceSet", "ControllerSet", "ProbeSet",
                                  "ComponentSet", "credits", "publications",
                                  "ModelVisualPreferences", "AnalysisSet",
                                  "assembly_accuracy", "validate_dynamics"})


def read_osim(path: str | Path) -> OsimModel:
    """Read an OpenSim model file (3.x or 4.x layout): :func:`parse_osim` of its bytes."""
    return parse_osim_root(parse(path), str(path))


def parse_osim(data: bytes, source: str) -> OsimModel:
    """An OpenSim model document given as bytes; ``source`` names it in messages."""
    return parse_osim_root(parse_bytes(data, source), source)


def parse_osim_root(root: ET.Element, source: str) -> OsimModel:
    """The model of a parsed ``.osim`` document.

    Parameters
    ----------
    root
        The document's root element (``OpenSimDocument``).
    source
        The file's name, for messages.

    Returns
    -------
    OsimModel
        Bodies, joints (as SpatialTransforms), coordinates, markers and coupler constraints;
        ``ignored`` lists the element kinds left out (muscles, wrapping, geometry …).

    Raises
    ------
    InputError
        One line naming the file and the element: unknown joint or function types, a body
        named twice, a marker on a missing body, a joint with an unknown parent, non-finite
        numbers, units other than metres, other constraints.
    """
    r = _Reader(source)
    model = root.find("Model") if root.tag == "OpenSimDocument" else None
    if model is None:
        r.fail(root.tag, "expected an OpenSimDocument holding a <Model>")
    top = [root, model]  # every element's ancestors, for messages
    for child in model:
        if child.tag not in KNOWN_MODEL_CHILDREN:
            r.fail(r.where(top, child), f"cannot represent a {child.tag}")
        if child.tag in IGNORED and any(len(part) for part in child):
            r.ignored.add(child.tag)
    units = (model.findtext("length_units") or "meters").strip().lower()
    if units not in ("meters", "m"):
        r.fail(f"{r.where([root], model)}/length_units", f"expected meters, got {units!r:.20}")
    gravity = r.vec3(model, "gravity", [root], (0.0, -9.80665, 0.0))
    bodies: list[OsimBody] = []
    joints: list[OsimJoint] = []
    coordinates: list[OsimCoordinate] = []
    if model.find("JointSet") is not None or model.find("Ground") is not None:
        _read_4x(r, model, top, bodies, joints, coordinates)
    else:
        _read_3x(r, model, top, bodies, joints, coordinates)
    where = r.where([root], model)
    _unique(r, [b.name for b in bodies] + [GROUND], "body", where)
    _unique(r, [c.name for c in coordinates], "coordinate", where)
    known = {b.name for b in bodies} | {GROUND}
    for joint in joints:
        if joint.parent.body not in known:
            r.fail(f"{where}/joint {joint.name}", f"parent {joint.parent.body!r} is not a body "
                                                  f"of the model")
    _tree(r, joints, bodies, where)
    couplers = _couplers(r, model, top)
    names = {c.name for c in coordinates}
    for coupler in couplers:
        for name in (coupler.independent, coupler.dependent):
            if name not in names:
                r.fail(f"{where}/ConstraintSet/{coupler.name}", f"coordinate {name!r} is not "
                                                               f"one of the model's")
    couplers = _chain_order(r, couplers, f"{where}/ConstraintSet")
    return OsimModel(_name(model), source, gravity, tuple(bodies), tuple(joints),
                     tuple(coordinates), tuple(_markers(r, model, top, known)), tuple(couplers),
                     tuple(sorted(r.ignored)))


def _chain_order(r: _Reader, couplers: list[Coupler], where: str) -> list[Coupler]:
    """The couplers in document order, except that each comes after the coupler that sets its
    independent coordinate: one pass in this order sets every dependent of a chain from values
    already set, as OpenSim's assembly sets them. Refuses a coordinate that two couplers set
    and couplers that form a loop (no pass can set them)."""
    setter: dict[str, Coupler] = {}
    for coupler in couplers:
        if coupler.dependent in setter:
            r.fail(f"{where}/{coupler.name}", f"coordinate {coupler.dependent!r} is already the "
                                              f"dependent of {setter[coupler.dependent].name}")
        setter[coupler.dependent] = coupler
    out: list[Coupler] = []
    for coupler in couplers:
        chain: list[Coupler] = []  # this coupler, then the ones it waits for, not yet placed
        at: Coupler | None = coupler
        while at is not None and at not in out:
            if at in chain:
                loop = [c.name for c in chain[chain.index(at):]]
                r.fail(f"{where}/{at.name}", f"the coupler constraints form a loop: "
                                             f"{' → '.join([*loop, loop[0]])}")
            chain.append(at)
            at = setter.get(at.independent)
        out.extend(reversed(chain))
    return out


def _tree(r: _Reader, joints: list[OsimJoint], bodies: list[OsimBody], where: str) -> None:
    """Every body is the child of exactly one joint, and the joints form a tree from the ground
    (closed loops are for constraints, which only couplers may add)."""
    children: dict[str, str] = {}
    for joint in joints:
        if joint.child.body in children:
            r.fail(f"{where}/joint {joint.name}", f"body {joint.child.body!r} is already the "
                                                  f"child of joint {children[joint.child.body]}")
        children[joint.child.body] = joint.name
    parent_of = {j.child.body: j.parent.body for j in joints}
    for body in bodies:
        if body.name not in children:
            r.fail(f"{where}/BodySet/{body.name}", "no joint connects this body to the model")
        seen, at = set(), body.name
        while at != GROUND:
            if at in seen:
                r.fail(f"{where}/joint {children[body.name]}", "the joints form a closed loop")
            seen.add(at)
            at = parent_of[at]

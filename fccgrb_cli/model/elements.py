"""Immutable model elements, named as in the FCC-GRB formulation (paper §2)."""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field, replace
from typing import Literal

import numpy as np

from fccgrb_cli.model.motion import BaseMotion, Motion
from fccgrb_cli.model.spatial import Coupling, JointCoordinate, MovingJoint
from fccgrb_cli.model.subject import SubjectMeasurements

GROUND = "ground"
Form = Literal["full", "reduced"]
Vec3 = tuple[float, float, float]

# Scalar equations each joint type contributes (docs/formulation.md §2).
JOINT_EQUATIONS: dict[str, int] = {
    "spherical": 3,
    "revolute": 5,
    "universal": 4,
    "cylindrical": 4,
    "prismatic": 5,
    "parallel": 2,
    "line": 2,
}
JOINTS_WITH_POINTS = frozenset({"spherical", "revolute", "universal", "cylindrical", "prismatic",
                                "line"})
JOINTS_WITH_AXES = frozenset({"revolute", "universal", "cylindrical", "prismatic", "parallel"})


@dataclass(frozen=True)
class Point:
    """A body-fixed point with local coordinates (a, b, c) along (u, v, w): r_P = C_P q (Eq. 2)."""

    name: str
    local: Vec3


@dataclass(frozen=True)
class Vector:
    """A body-fixed unit vector with local components (α, β, γ): s = C_s q (Eq. 3)."""

    name: str
    local: Vec3


@dataclass(frozen=True)
class Pose:
    """A body's reference point r and unit vectors u, v, w in the global frame (metres)."""

    r: Vec3 = (0.0, 0.0, 0.0)
    u: Vec3 = (1.0, 0.0, 0.0)
    v: Vec3 = (0.0, 1.0, 0.0)
    w: Vec3 = (0.0, 0.0, 1.0)

    def as_array(self) -> np.ndarray:
        """The fully-defined coordinates [r, u, v, w] (12,)."""
        return np.concatenate([self.r, self.u, self.v, self.w]).astype(float)


@dataclass(frozen=True)
class Inertia:
    """Mass (kg), centre of mass in local coordinates (m), inertia tensor about the CoM in the
    body frame (kg·m²)."""

    mass: float
    com: Vec3
    tensor: tuple[Vec3, Vec3, Vec3]


class FrozenMap(Mapping):
    """A read-only mapping that pickles (a model travels to worker processes once each)."""

    __slots__ = ("_items",)
    _items: dict

    def __init__(self, items: Mapping | None = None):
        object.__setattr__(self, "_items", dict(items or {}))

    def __getitem__(self, key):
        return self._items[key]

    def __iter__(self) -> Iterator:
        return iter(self._items)

    def __len__(self) -> int:
        return len(self._items)

    def __setattr__(self, name, value):
        raise AttributeError("FrozenMap is read-only")

    def __getstate__(self) -> dict:
        return self._items

    def __setstate__(self, state: dict) -> None:
        object.__setattr__(self, "_items", state)

    def __repr__(self) -> str:
        return f"FrozenMap({self._items!r})"


def _frozen(mapping: Mapping) -> FrozenMap:
    return FrozenMap(mapping)


@dataclass(frozen=True)
class Body:
    """A generic rigid body, fully-defined q = [r, u, v, w] or reduced q = [r, u, v] (Eq. 1, 4)."""

    name: str
    form: Form
    points: FrozenMap
    vectors: FrozenMap
    pose: Pose = field(default_factory=Pose)
    inertia: Inertia | None = None
    motion: BaseMotion | None = None

    @property
    def ncoord(self) -> int:
        return 12 if self.form == "full" else 9


@dataclass(frozen=True)
class Ground:
    """The fixed frame: named points (m) and unit vectors in global coordinates."""

    points: FrozenMap
    vectors: FrozenMap


@dataclass(frozen=True)
class Joint:
    """A kinematic joint between bodies i and j (either may be the ground).

    ``points`` name the coincident point on each body; ``axes`` the joint axes (revolute,
    cylindrical, prismatic, parallel: s_i ∥ s_j) or the perpendicular arms (universal: s_i ⟂ s_j);
    ``lock`` two vectors kept perpendicular to stop a prismatic joint's rotation; ``axis`` (line
    joints) body i's vector along which body j's point stays on the line through body i's point
    (a spherical joint that also slides along that line: 3 rotations and a slide).
    """

    name: str
    type: str
    bodies: tuple[str, str]
    points: tuple[str, str] | None = None
    axes: tuple[str, str] | None = None
    lock: tuple[str, str] | None = None
    axis: str | None = None


@dataclass(frozen=True)
class AngularCoordinate:
    """θ_k, the angle between vector s1 of body 1 and vector s2 of body 2: s1·s2 = cos θ_k.

    Used as an angular driver (AR, Eq. 23–26) or as a mixed coordinate (MCR, Eq. 10–22).
    With an ``axis`` (a unit vector n of body 1 or body 2 along the joint axis, s1 ⟂ n ⟂ s2) the
    angle is signed and turns without limit (``range: full``): (s1 × s2)·n = sin θ_k joins the
    cosine relation (docs/signed_angles.md).
    """

    name: str
    body1: str
    vector1: str
    body2: str
    vector2: str
    motion: Motion | None = None
    clinical_sign: int | None = None
    axis: tuple[str, str] | None = None
    clinical_range: tuple[float, float] | None = None

    @property
    def full(self) -> bool:
        """A signed angle that may take any value (cos θ and sin θ both pinned)."""
        return self.axis is not None

    @property
    def kind(self) -> str:
        """"angle": the row is s1·s2 − g(θ) with g = cos (docs/formulation.md §2)."""
        return "angle"

    def clinical(self, theta: np.ndarray) -> np.ndarray | None:
        """The clinical angle in degrees, sign·(θ − 90°), or None when none is declared. A
        signed angle counts turns from wherever its solve started, so its clinical series is
        moved by whole turns to put its mean in (−180°, 180°] (a joint, not a crank)."""
        if self.clinical_sign is None:
            return None
        degrees = self.clinical_sign * (np.degrees(theta) - 90.0)
        if self.full and np.isfinite(degrees).any():
            degrees = degrees - 360.0 * np.ceil((np.nanmean(degrees) - 180.0) / 360.0)
        return degrees


@dataclass(frozen=True)
class DistanceCoordinate:
    """d_k, the distance from point P of body 1 to point Q of body 2 along the unit vector s of
    body 1: (r_Q − r_P)·s = d_k (metres). The translational analog of an angle (g(d) = d for
    cos θ), needed to drive or solve the slides of prismatic, cylindrical and parallel joints;
    its conjugate "moment" is the joint force (N) that pushes d to increase."""

    name: str
    body1: str
    point1: str
    body2: str
    point2: str
    axis: str
    motion: Motion | None = None
    clinical_sign: None = None
    clinical_range: None = None

    @property
    def kind(self) -> str:
        """"distance": the row is (F_Q − F_P)·s − g(d) with g(d) = d."""
        return "distance"

    def clinical(self, theta: np.ndarray) -> None:
        """A distance has no clinical angle."""
        return None


Coordinate = AngularCoordinate | DistanceCoordinate | JointCoordinate


def in_metres(coordinate: Coordinate) -> bool:
    """Whether a coordinate is a length (m): a distance, or a moving joint's translation."""
    return coordinate.kind == "distance" or getattr(coordinate, "translational", False)


@dataclass(frozen=True)
class TrackedPoint:
    """A model point that follows a marker (tracking constraint TC, Eq. 29–36)."""

    body: str
    point: str
    marker: str
    weight: float | None = None


@dataclass(frozen=True)
class TrackedVector:
    """A body vector that follows the unit vector from one marker to another (TOC, Eq. 37–38)."""

    body: str
    vector: str
    from_marker: str
    to_marker: str
    weight: float | None = None

    @property
    def marker(self) -> str:
        return f"{self.from_marker}->{self.to_marker}"


@dataclass(frozen=True)
class PlateAssignment:
    """Force platform ``plate`` (1-based, as numbered in the trial) acts on ``body``."""

    plate: int
    body: str


@dataclass(frozen=True)
class CalibrationRecord:
    """What ``fccgrb calibrate`` wrote of a personalized model (its ``calibrated`` key): the
    trial and frame indices [A, B) it came from, how closely the segment frames carried the
    tracked markers over those frames (mean and largest distance of a marker from its mean
    place in its segment, mm) and the implausibilities it warned of (empty when none)."""

    trial: str
    frames: tuple[int, int]
    fit_mm: tuple[float, float]
    warnings: tuple[str, ...] = ()


@dataclass(frozen=True)
class Model:
    """A validated multibody model. Build it with :func:`fccgrb_cli.model.load_model`."""

    name: str
    gravity: Vec3
    ground: Ground
    bodies: tuple[Body, ...]
    joints: tuple[Joint, ...]
    angles: tuple[Coordinate, ...]
    tracked_points: tuple[TrackedPoint, ...] = ()
    tracked_vectors: tuple[TrackedVector, ...] = ()
    force_plates: tuple[PlateAssignment, ...] = ()
    plate_threshold: float = 20.0
    contact_bodies: tuple[str, ...] = ()
    subject_mass: float | None = None
    landmarks: FrozenMap = field(default_factory=FrozenMap)
    calibration_method: str | None = None
    measurements: SubjectMeasurements = field(default_factory=SubjectMeasurements)
    virtual_markers: FrozenMap = field(default_factory=FrozenMap)
    source: str = "<model>"
    text: str = ""
    calibrated: CalibrationRecord | None = None
    moving_joints: tuple[MovingJoint, ...] = ()
    couplings: tuple[Coupling, ...] = ()

    @property
    def template(self) -> bool:
        """A model that names calibration landmarks but was not personalized by ``fccgrb
        calibrate`` (no ``calibrated`` record, nor the header calibrate wrote before there was
        one): its segments are a generic adult's."""
        return bool(self.landmarks) and self.calibrated is None and \
            "personalized by `fccgrb calibrate`" not in self.text

    @property
    def has_inertia(self) -> bool:
        return all(b.inertia is not None for b in self.bodies)

    def body(self, name: str) -> Body:
        for body in self.bodies:
            if body.name == name:
                return body
        raise KeyError(name)

    @property
    def floating_bases(self) -> tuple[str, ...]:
        """The first body of every group of bodies no chain of joints ties to the ground."""
        return floating_bases(self.bodies, self.joints, self.moving_joints)

    @property
    def marker_labels(self) -> tuple[str, ...]:
        return tuple(tp.marker for tp in self.tracked_points)

    def with_form(self, form: Form) -> Model:
        """The same model with every body in the given form (paper Eq. 1 or Eq. 4)."""
        return replace(self, bodies=tuple(replace(b, form=form) for b in self.bodies))

    def with_gravity(self, gravity: Vec3) -> Model:
        """The same model under another gravity (m/s²): the lab's vertical found from a trial."""
        return replace(self, gravity=(float(gravity[0]), float(gravity[1]), float(gravity[2])))

    def with_tracked(self, markers: tuple[str, ...]) -> Model:
        """The same model tracking only the named markers (points and vectors)."""
        keep = set(markers)
        return replace(
            self,
            tracked_points=tuple(t for t in self.tracked_points if t.marker in keep),
            tracked_vectors=tuple(t for t in self.tracked_vectors if t.marker in keep),
        )


def floating_bases(bodies: tuple[Body, ...], joints: tuple[Joint, ...],
                   moving: tuple[MovingJoint, ...] = ()) -> tuple[str, ...]:
    """The first body of every group of bodies that no chain of joints (``moving`` ones
    included) ties to the ground: a floating base, whose 6 degrees of freedom the markers (MC)
    or base drivers (AD) determine."""
    neighbours: dict[str, set[str]] = {GROUND: set(), **{b.name: set() for b in bodies}}
    pairs = [j.bodies for j in joints] + [(m.parent, m.child) for m in moving]
    for a, b in pairs:
        neighbours[a].add(b)
        neighbours[b].add(a)
    seen: set[str] = set()
    bases = []
    for start in (GROUND, *(b.name for b in bodies)):
        if start in seen:
            continue
        if start != GROUND:
            bases.append(start)
        seen.add(start)
        stack = [start]
        while stack:
            for other in neighbours[stack.pop()] - seen:
                seen.add(other)
                stack.append(other)
    return tuple(bases)


__all__ = [
    "GROUND",
    "JOINTS_WITH_AXES",
    "JOINTS_WITH_POINTS",
    "JOINT_EQUATIONS",
    "AngularCoordinate",
    "Body",
    "Coordinate",
    "DistanceCoordinate",
    "Form",
    "FrozenMap",
    "Ground",
    "Inertia",
    "Joint",
    "Model",
    "PlateAssignment",
    "Point",
    "Pose",
    "TrackedPoint",
    "TrackedVector",
    "Vector",
    "_frozen",
    "floating_bases",
    "in_metres",
]

"""YAML → validated, immutable :class:`Model`.

Every rejection is one :class:`InputError` line: ``FILE: KEY.PATH: expected …, got …``.
"""

from __future__ import annotations

import collections
import dataclasses
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any, NoReturn

import numpy as np
import yaml

from fccgrb_cli.core.errors import InputError
from fccgrb_cli.core.inputs import load_yaml, read_text, shown
from fccgrb_cli.model.elements import (
    GROUND,
    JOINT_EQUATIONS,
    JOINTS_WITH_AXES,
    JOINTS_WITH_POINTS,
    AngularCoordinate,
    Body,
    CalibrationRecord,
    DistanceCoordinate,
    FrozenMap,
    Ground,
    Inertia,
    Joint,
    Model,
    PlateAssignment,
    Point,
    Pose,
    TrackedPoint,
    TrackedVector,
    Vector,
    _frozen,
    floating_bases,
)
from fccgrb_cli.model.motion import BaseMotion, Motion
from fccgrb_cli.model.ranges import physiological_range
from fccgrb_cli.model.subject import SubjectMeasurements, from_yaml, yaml_keys
from fccgrb_cli.model.virtual import canonical

UNIT_TOL = 1e-6
LARGEST = 1e9          # the largest magnitude of any number in a model file
FREQUENCY_MAX = 1e4    # Hz: a motion term's frequency (its acceleration ∝ frequency²)
CALIBRATION_METHODS = ("plugin-gait",)  # besides the landmark-chosen ones (anatomy/calibrate)
BODY_AXES = {"u": (1.0, 0.0, 0.0), "v": (0.0, 1.0, 0.0), "w": (0.0, 0.0, 1.0)}
GROUND_AXES = {"x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0)}
TOP_KEYS = {"name", "units", "gravity", "form", "ground", "bodies", "joints", "angles",
            "distances", "tracking", "loads", "subject", "calibration", "calibrated",
            "virtual_markers"}


class _UniqueKeyLoader(getattr(yaml, "CSafeLoader", yaml.SafeLoader)):  # type: ignore[misc]
    """A safe loader that refuses duplicate mapping keys instead of keeping the last one
    (libyaml's parser where PyYAML has it: 10× faster on a model file than the pure-Python
    one, the same documents and error positions)."""


def _construct_mapping(loader: _UniqueKeyLoader, node: yaml.MappingNode, deep: bool = False):
    seen: dict = {}
    for key_node, _ in node.value:
        key = loader.construct_object(key_node, deep=deep)
        mark = key_node.start_mark
        if not isinstance(key, (str, int, float, bool)) and key is not None:
            raise yaml.constructor.ConstructorError(
                None, None, "a mapping key must be a name, not a list or mapping", mark)
        if key in seen:
            raise yaml.constructor.ConstructorError(
                None, None, f"duplicate key {key!r}, first given on line {seen[key] + 1}", mark)
        seen[key] = mark.line
    return loader.construct_mapping(node, deep=deep)


_UniqueKeyLoader.add_constructor(
    yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _construct_mapping
)


class _Reader:
    """Reads values out of the parsed YAML, naming the file and key path in every error."""

    def __init__(self, source: str):
        self.source = source

    def fail(self, path: str, expected: str, got: Any = None, *, show_got: bool = True) -> NoReturn:
        tail = f", got {shown(got)}" if show_got else ""
        raise InputError(f"{self.source}: {path or '(top level)'}: expected {expected}{tail}")

    def mapping(self, value: Any, path: str, *, required: frozenset = frozenset(),
                allowed: set | None = None) -> dict:
        if not isinstance(value, dict):
            self.fail(path, "a mapping", value)
        for key in value:
            if not isinstance(key, str):
                self.fail(path, "string keys", key)
            if allowed is not None and key not in allowed:
                self.fail(f"{path}.{key}" if path else key,
                          f"one of the keys {sorted(allowed)}", key, show_got=False)
        for key in required:
            if key not in value:
                self.fail(f"{path}.{key}" if path else key, "this key to be present", None,
                          show_got=False)
        return value

    def number(self, value: Any, path: str) -> float:
        """A finite number of magnitude at most ``LARGEST`` (squares and products of model
        numbers stay finite)."""
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            self.fail(path, "a finite number", value)
        try:
            number = float(value)
        except OverflowError:
            number = math.inf
        if not math.isfinite(number):
            self.fail(path, "a finite number", value if isinstance(value, float) else "too large")
        if abs(number) > LARGEST:
            self.fail(path, f"a number of magnitude at most {LARGEST:g}", value)
        return number

    def string(self, value: Any, path: str) -> str:
        if not isinstance(value, str) or not value:
            self.fail(path, "a non-empty string", value)
        return value

    def vec3(self, value: Any, path: str) -> tuple[float, float, float]:
        if not isinstance(value, list) or len(value) != 3:
            self.fail(path, "a list of 3 numbers", value)
        x, y, z = (self.number(c, f"{path}[{k}]") for k, c in enumerate(value))
        return (x, y, z)

    def unit3(self, value: Any, path: str) -> tuple[float, float, float]:
        vec = self.vec3(value, path)
        norm = float(np.linalg.norm(vec))
        if abs(norm - 1.0) > UNIT_TOL:
            self.fail(path, f"a unit vector (norm 1 ± {UNIT_TOL:g}), got norm {norm:.6g}", None,
                      show_got=False)
        return vec

    def pair(self, value: Any, path: str) -> tuple[str, str]:
        if not isinstance(value, list) or len(value) != 2:
            self.fail(path, "a list of 2 names", value)
        return (self.string(value[0], f"{path}[0]"), self.string(value[1], f"{path}[1]"))

    def items(self, value: Any, path: str) -> list:
        if value is None:
            return []
        if not isinstance(value, list):
            self.fail(path, "a list", value)
        return value


def _angle_scale(r: _Reader, doc: dict) -> float:
    units = r.mapping(doc.get("units", {}), "units", allowed={"angle"})
    angle = units.get("angle", "deg")
    if angle not in ("deg", "rad"):
        r.fail("units.angle", "'deg' or 'rad'", angle)
    return math.pi / 180.0 if angle == "deg" else 1.0


def _pose(r: _Reader, value: Any, path: str, form: str) -> Pose:
    spec = r.mapping(value, path, required=frozenset({"r", "u", "v"}), allowed={"r", "u", "v", "w"})
    origin = r.vec3(spec["r"], f"{path}.r")
    u = np.array(r.unit3(spec["u"], f"{path}.u"))
    v = np.array(r.unit3(spec["v"], f"{path}.v"))
    w = np.array(r.unit3(spec["w"], f"{path}.w")) if "w" in spec else np.cross(u, v)
    if "w" not in spec and form == "full":
        r.fail(f"{path}.w", "w for a fully-defined body", None, show_got=False)
    frame = np.column_stack([u, v, w])
    error = float(np.abs(frame.T @ frame - np.eye(3)).max())
    if error > UNIT_TOL:
        r.fail(path, f"u, v, w unit and mutually orthogonal (within {UNIT_TOL:g}), "
               f"got |UᵀU − I| = {error:.3g}", None, show_got=False)
    if np.linalg.det(frame) < 0:
        r.fail(path, "a right-handed frame (w = u × v)", None, show_got=False)
    return Pose(origin, tuple(u), tuple(v), tuple(w))


def _inertia(r: _Reader, spec: dict, path: str) -> Inertia | None:
    if "mass" not in spec:
        for key in ("com", "inertia"):
            if key in spec:
                r.fail(f"{path}.mass", f"a mass when {key} is given", None, show_got=False)
        return None
    mass = r.number(spec["mass"], f"{path}.mass")
    if mass <= 0:
        r.fail(f"{path}.mass", "a positive mass (kg)", mass)
    com = r.vec3(spec.get("com", [0.0, 0.0, 0.0]), f"{path}.com")
    raw = spec.get("inertia")
    ipath = f"{path}.inertia"
    if raw is None:
        r.fail(ipath, "the inertia (kg·m²) when a mass is given", None, show_got=False)
    if isinstance(raw, list) and len(raw) == 3 and all(not isinstance(x, list) for x in raw):
        tensor = np.diag(r.vec3(raw, ipath))
    elif isinstance(raw, list) and len(raw) == 3:
        tensor = np.array([r.vec3(row, f"{ipath}[{k}]") for k, row in enumerate(raw)])
    else:
        r.fail(ipath, "3 principal moments [Iu, Iv, Iw] or a 3×3 tensor", raw)
    if not np.allclose(tensor, tensor.T, atol=1e-12):
        r.fail(ipath, "a symmetric tensor", raw)
    moments = np.linalg.eigvalsh(tensor)
    # a slender segment's tensor (none about its long axis, as Plug-in Gait's) written to 12
    # decimals in an axis-free frame: its eigenvalues may miss by the entries' rounding
    slack = 1e-10 * max(moments[2], 1.0)
    if moments[0] < -slack:
        r.fail(ipath, "non-negative principal moments", raw)
    if moments[2] > moments[0] + moments[1] + slack:
        r.fail(ipath, "principal moments satisfying the triangle inequality "
               f"(largest ≤ sum of the other two), got {np.round(moments, 9).tolist()}", None,
               show_got=False)
    rows = tensor.tolist()
    return Inertia(mass, com, (tuple(rows[0]), tuple(rows[1]), tuple(rows[2])))


def _named_vectors(r: _Reader, value: Any, path: str, builtin: dict) -> dict:
    spec = r.mapping(value or {}, path)
    out = {name: Vector(name, loc) for name, loc in builtin.items()}
    for name, loc in spec.items():
        if name in builtin:
            r.fail(f"{path}.{name}", f"a name other than the built-in {sorted(builtin)}", name)
        out[name] = Vector(name, r.unit3(loc, f"{path}.{name}"))
    return out


def _named_points(r: _Reader, value: Any, path: str) -> dict:
    spec = r.mapping(value or {}, path)
    return {name: Point(name, r.vec3(loc, f"{path}.{name}")) for name, loc in spec.items()}


def _bodies(r: _Reader, doc: dict, scale: float) -> tuple[Body, ...]:
    default_form = doc.get("form", "full")
    if default_form not in ("full", "reduced"):
        r.fail("form", "'full' or 'reduced'", default_form)
    spec = r.mapping(doc["bodies"], "bodies")
    if not spec:
        r.fail("bodies", "at least one body", spec)
    bodies = []
    allowed = {"form", "mass", "com", "inertia", "points", "vectors", "pose", "motion"}
    for name, body in spec.items():
        path = f"bodies.{name}"
        if name == GROUND:
            r.fail(path, f"a body name other than {GROUND!r} (the ground is its own section)", name)
        body = r.mapping(body, path, allowed=allowed)
        form = body.get("form", default_form)
        if form not in ("full", "reduced"):
            r.fail(f"{path}.form", "'full' or 'reduced'", form)
        pose = _pose(r, body["pose"], f"{path}.pose", form) if "pose" in body else Pose()
        bodies.append(Body(
            name=name,
            form=form,
            points=_frozen(_named_points(r, body.get("points"), f"{path}.points")),
            vectors=_frozen(_named_vectors(r, body.get("vectors"), f"{path}.vectors", BODY_AXES)),
            pose=pose,
            inertia=_inertia(r, body, path),
            motion=_base_motion(r, body["motion"], f"{path}.motion", scale)
            if "motion" in body else None,
        ))
    return tuple(bodies)


def _base_motion(r: _Reader, value: Any, path: str, scale: float) -> BaseMotion:
    """A floating base's motion: ``translation`` (m) and ``rotation`` (the file's angle unit),
    each a list of 3 motions along / about the ground's x, y, z; either may be left out."""
    spec = r.mapping(value, path, allowed={"translation", "rotation"})
    parts: dict[str, tuple[Motion, Motion, Motion]] = {}
    for key, size in (("translation", 1.0), ("rotation", scale)):
        if key not in spec:
            continue
        items = spec[key]
        if not isinstance(items, list) or len(items) != 3:
            r.fail(f"{path}.{key}", "a list of 3 motions (x, y, z)", items)
        x, y, z = (_motion(r, item, f"{path}.{key}[{k}]", size, scale)
                   for k, item in enumerate(items))
        parts[key] = (x, y, z)
    return BaseMotion(**parts)


class _Names:
    """Resolves ``body.point`` and ``body.vector`` references, naming what exists when unknown."""

    def __init__(self, r: _Reader, ground: Ground, bodies: tuple[Body, ...]):
        self.r = r
        self.points = {GROUND: ground.points, **{b.name: b.points for b in bodies}}
        self.vectors = {GROUND: ground.vectors, **{b.name: b.vectors for b in bodies}}

    def body(self, name: str, path: str) -> str:
        if name not in self.points:
            self.r.fail(path, f"a body name (one of {sorted(self.points)})", name)
        return name

    def _member(self, table: dict, body: str, name: str, path: str, kind: str) -> str:
        if name not in table[body]:
            self.r.fail(path, f"a {kind} of {body} (one of {sorted(table[body])})", name)
        return name

    def point(self, body: str, name: str, path: str) -> str:
        return self._member(self.points, body, name, path, "point")

    def vector(self, body: str, name: str, path: str) -> str:
        return self._member(self.vectors, body, name, path, "vector")

    def dotted(self, value: Any, path: str, kind: str) -> tuple[str, str]:
        text = self.r.string(value, path)
        if text.count(".") != 1:
            self.r.fail(path, f"'body.{kind}'", text)
        body, member = text.split(".")
        self.body(body, path)
        lookup = self.point if kind == "point" else self.vector
        return body, lookup(body, member, path)


def _joints(r: _Reader, doc: dict, names: _Names) -> tuple[Joint, ...]:
    joints = []
    seen: set[str] = set()
    for k, spec in enumerate(r.items(doc.get("joints"), "joints")):
        path = f"joints[{k}]"
        spec = r.mapping(spec, path, required=frozenset({"type", "bodies"}),
                         allowed={"name", "type", "bodies", "points", "axes", "lock", "axis"})
        jtype = spec["type"]
        if not isinstance(jtype, str) or jtype not in JOINT_EQUATIONS:
            r.fail(f"{path}.type", f"a joint type (one of {sorted(JOINT_EQUATIONS)})", jtype)
        name = r.string(spec.get("name", f"{jtype}{k}"), f"{path}.name")
        if name in seen:
            r.fail(f"{path}.name", "a joint name not used before", name)
        seen.add(name)
        bodies = r.pair(spec["bodies"], f"{path}.bodies")
        for side, body in enumerate(bodies):
            names.body(body, f"{path}.bodies[{side}]")
        if bodies[0] == bodies[1]:
            r.fail(f"{path}.bodies", "two different bodies", list(bodies))
        if bodies[0] == GROUND and bodies[1] == GROUND:
            r.fail(f"{path}.bodies", "at least one moving body", list(bodies))

        def members(key: str, lookup: Callable[[str, str, str], str], needed: bool,
                    path: str = path, spec: dict = spec, bodies: tuple = bodies, jtype: str = jtype
                    ) -> tuple[str, str] | None:
            if key not in spec:
                if needed:
                    r.fail(f"{path}.{key}", f"{key} for a {jtype} joint", None, show_got=False)
                return None
            if not needed:
                r.fail(f"{path}.{key}", f"no {key} for a {jtype} joint", spec[key])
            pair = r.pair(spec[key], f"{path}.{key}")
            return (lookup(bodies[0], pair[0], f"{path}.{key}[0]"),
                    lookup(bodies[1], pair[1], f"{path}.{key}[1]"))

        axis = None
        if jtype == "line" and "axis" not in spec:
            r.fail(f"{path}.axis", "axis for a line joint (a vector of its first body)", None,
                   show_got=False)
        if "axis" in spec:
            if jtype != "line":
                r.fail(f"{path}.axis", f"no axis for a {jtype} joint (axes: [s_i, s_j])",
                       spec["axis"])
            axis = names.vector(bodies[0], r.string(spec["axis"], f"{path}.axis"),
                                f"{path}.axis")
        joints.append(Joint(
            name=name,
            type=jtype,
            bodies=bodies,
            points=members("points", names.point, jtype in JOINTS_WITH_POINTS),
            axes=members("axes", names.vector, jtype in JOINTS_WITH_AXES),
            lock=members("lock", names.vector, jtype == "prismatic"),
            axis=axis,
        ))
    return tuple(joints)


def _motion(r: _Reader, value: Any, path: str, size: float, scale: float,
            kind: str | None = None) -> Motion:
    """mean + Σ amplitude·sin(2π·frequency·t + phase): ``size`` converts mean and amplitude to
    SI (the angle unit, or 1 for metres), ``scale`` the phase; an angle (``kind``) must stay
    inside (0, 180) deg, where s1·s2 = cos θ is invertible."""
    spec = r.mapping(value, path, required=frozenset({"mean"}),
                     allowed={"mean", "rate", "terms"})
    terms = []
    for k, term in enumerate(r.items(spec.get("terms"), f"{path}.terms")):
        tpath = f"{path}.terms[{k}]"
        term = r.mapping(term, tpath, required=frozenset({"amplitude", "frequency"}),
                         allowed={"amplitude", "frequency", "phase"})
        frequency = r.number(term["frequency"], f"{tpath}.frequency")
        if not 0 <= frequency <= FREQUENCY_MAX:
            r.fail(f"{tpath}.frequency", f"a frequency from 0 to {FREQUENCY_MAX:g} Hz",
                   frequency)
        terms.append((r.number(term["amplitude"], f"{tpath}.amplitude") * size,
                      frequency,
                      r.number(term.get("phase", 0.0), f"{tpath}.phase") * scale))
    motion = Motion(r.number(spec["mean"], f"{path}.mean") * size, tuple(terms),
                    r.number(spec.get("rate", 0.0), f"{path}.rate") * size)
    low, high = motion.bounds()
    if kind == "angle" and (low <= 0.0 or high >= math.pi):
        r.fail(path, "a motion that stays inside (0, 180) deg, where s1·s2 = cos θ is "
               f"invertible (or an angle with 'range: full' and an 'axis' to sign it); it can "
               f"reach [{math.degrees(low):.4g}, {math.degrees(high):.4g}] deg",
               None, show_got=False)
    return motion


def _angles(r: _Reader, doc: dict, names: _Names, scale: float, seen: set[str]
            ) -> tuple[AngularCoordinate, ...]:
    angles = []
    for k, spec in enumerate(r.items(doc.get("angles"), "angles")):
        path = f"angles[{k}]"
        spec = r.mapping(spec, path, required=frozenset({"name", "vectors"}),
                         allowed={"name", "vectors", "motion", "clinical", "range", "axis"})
        name = r.string(spec["name"], f"{path}.name")
        if name in seen:
            r.fail(f"{path}.name", "an angle name not used before", name)
        seen.add(name)
        pair = r.pair(spec["vectors"], f"{path}.vectors")
        body1, vec1 = names.dotted(pair[0], f"{path}.vectors[0]", "vector")
        body2, vec2 = names.dotted(pair[1], f"{path}.vectors[1]", "vector")
        if body1 == body2:
            r.fail(f"{path}.vectors", "vectors of two different bodies", list(pair))
        axis = _angle_axis(r, spec, path, names, (body1, body2))
        motion = (_motion(r, spec["motion"], f"{path}.motion", scale, scale,
                          "full angle" if axis else "angle")
                  if "motion" in spec else None)
        sign, extent = _clinical(r, spec, path, name)
        angles.append(AngularCoordinate(name, body1, vec1, body2, vec2, motion, sign, axis,
                                        extent))
    return tuple(angles)


def _distances(r: _Reader, doc: dict, names: _Names, scale: float, seen: set[str]
               ) -> tuple[DistanceCoordinate, ...]:
    """d = (r_Q − r_P)·s (m): P on the first body (or the ground), Q on the second, s a unit
    vector of the first body; the motion in metres, its phase in the file's angle unit."""
    distances = []
    for k, spec in enumerate(r.items(doc.get("distances"), "distances")):
        path = f"distances[{k}]"
        spec = r.mapping(spec, path, required=frozenset({"name", "points", "axis"}),
                         allowed={"name", "points", "axis", "motion"})
        name = r.string(spec["name"], f"{path}.name")
        if name in seen:
            r.fail(f"{path}.name", "a coordinate name not used before (angles and distances)",
                   name)
        seen.add(name)
        pair = r.pair(spec["points"], f"{path}.points")
        body1, point1 = names.dotted(pair[0], f"{path}.points[0]", "point")
        body2, point2 = names.dotted(pair[1], f"{path}.points[1]", "point")
        if body1 == body2:
            r.fail(f"{path}.points", "points of two different bodies", list(pair))
        axis_body, axis = names.dotted(spec["axis"], f"{path}.axis", "vector")
        if axis_body != body1:
            r.fail(f"{path}.axis", f"a vector of {body1}, the body of the first point",
                   spec["axis"])
        motion = (_motion(r, spec["motion"], f"{path}.motion", 1.0, scale, "distance")
                  if "motion" in spec else None)
        distances.append(DistanceCoordinate(name, body1, point1, body2, point2, axis, motion))
    return tuple(distances)


def _check_base_motions(r: _Reader, bodies: tuple[Body, ...], joints: tuple[Joint, ...]) -> None:
    """A prescribed base motion belongs to a floating base only (the joints move the others)."""
    bases = floating_bases(bodies, joints)
    for body in bodies:
        if body.motion is not None and body.name not in bases:
            r.fail(f"bodies.{body.name}.motion", "a motion on a floating base only (the first "
                   "body of a group that no joint ties to the ground; in this model: "
                   f"{', '.join(bases) or 'none'})", None, show_got=False)


def _angle_axis(r: _Reader, spec: dict, path: str, names: _Names,
                bodies: tuple[str, str]) -> tuple[str, str] | None:
    """``range: full`` with ``axis: BODY.VECTOR`` (a vector of one of the angle's two bodies
    along the joint axis): a signed angle that turns without limit; ``range: half`` (the default)
    the paper's (0°, 180°)."""
    extent = spec.get("range", "half")
    if extent not in ("half", "full"):
        r.fail(f"{path}.range", "'full' (a signed angle, any number of turns) or 'half' "
               "(0–180°, the default)", extent)
    if extent == "half":
        if "axis" in spec:
            r.fail(f"{path}.axis", "an axis only with 'range: full' (it signs the angle)",
                   spec["axis"])
        return None
    if "axis" not in spec:
        r.fail(f"{path}.axis", "the joint axis that signs a 'range: full' angle: a vector of "
               f"{bodies[0]} or {bodies[1]} perpendicular to both of the angle's vectors "
               "(e.g. a revolute joint's axis)", None, show_got=False)
    body, vector = names.dotted(spec["axis"], f"{path}.axis", "vector")
    if body not in bodies:
        r.fail(f"{path}.axis", f"a vector of {bodies[0]} or {bodies[1]}", spec["axis"])
    return body, vector


def _clinical(r: _Reader, spec: dict, path: str, name: str
              ) -> tuple[int | None, tuple[float, float] | None]:
    """The clinical sign and the physiological range (deg): ``range_deg: [min, max]`` where
    given, else the table's for the angle's name (model/ranges.py)."""
    if "clinical" not in spec:
        return None, None
    clinical = r.mapping(spec["clinical"], f"{path}.clinical", required=frozenset({"sign"}),
                         allowed={"sign", "range_deg"})
    sign = clinical["sign"]
    if isinstance(sign, bool) or sign not in (1, -1):
        r.fail(f"{path}.clinical.sign", "1 or -1 (clinical angle = sign·(θ − 90 deg))", sign)
    if "range_deg" not in clinical:
        return int(sign), physiological_range(name)
    key = f"{path}.clinical.range_deg"
    extent = clinical["range_deg"]
    if not isinstance(extent, list) or len(extent) != 2:
        r.fail(key, "[min, max] in degrees of the clinical angle", extent)
    low, high = (r.number(v, f"{key}[{k}]") for k, v in enumerate(extent))
    if not low < high:
        r.fail(key, "min < max", extent)
    return int(sign), (low, high)


def _weight(r: _Reader, spec: dict, path: str) -> float | None:
    if "weight" not in spec:
        return None
    weight = r.number(spec["weight"], f"{path}.weight")
    if weight <= 0:
        r.fail(f"{path}.weight", "a positive weight", weight)
    return weight


def _tracking(r: _Reader, doc: dict, names: _Names
              ) -> tuple[tuple[TrackedPoint, ...], tuple[TrackedVector, ...]]:
    spec = r.mapping(doc.get("tracking") or {}, "tracking", allowed={"points", "vectors"})
    points, vectors, labels = [], [], set()
    for k, item in enumerate(r.items(spec.get("points"), "tracking.points")):
        path = f"tracking.points[{k}]"
        item = r.mapping(item, path, required=frozenset({"marker", "point"}),
                         allowed={"marker", "point", "weight"})
        marker = r.string(item["marker"], f"{path}.marker")
        if marker in labels:
            r.fail(f"{path}.marker", "a marker label not tracked before", marker)
        labels.add(marker)
        body, point = names.dotted(item["point"], f"{path}.point", "point")
        if body == GROUND:
            r.fail(f"{path}.point", "a point of a moving body", item["point"])
        points.append(TrackedPoint(body, point, marker, _weight(r, item, path)))
    for k, item in enumerate(r.items(spec.get("vectors"), "tracking.vectors")):
        path = f"tracking.vectors[{k}]"
        item = r.mapping(item, path, required=frozenset({"vector", "from", "to"}),
                         allowed={"vector", "from", "to", "weight"})
        body, vector = names.dotted(item["vector"], f"{path}.vector", "vector")
        if body == GROUND:
            r.fail(f"{path}.vector", "a vector of a moving body", item["vector"])
        vectors.append(TrackedVector(body, vector, r.string(item["from"], f"{path}.from"),
                                     r.string(item["to"], f"{path}.to"), _weight(r, item, path)))
    return tuple(points), tuple(vectors)


def _loads(r: _Reader, doc: dict, names: _Names
           ) -> tuple[tuple[PlateAssignment, ...], float, tuple[str, ...]]:
    spec = r.mapping(doc.get("loads") or {}, "loads",
                     allowed={"force_plates", "threshold", "contact"})
    threshold = r.number(spec.get("threshold", 20.0), "loads.threshold")
    if threshold < 0:
        r.fail("loads.threshold", "a non-negative vertical force (N)", threshold)
    plates, seen = [], set()
    for k, item in enumerate(r.items(spec.get("force_plates"), "loads.force_plates")):
        path = f"loads.force_plates[{k}]"
        item = r.mapping(item, path, required=frozenset({"plate", "body"}),
                         allowed={"plate", "body"})
        plate = item["plate"]
        if isinstance(plate, bool) or not isinstance(plate, int) or plate < 1:
            r.fail(f"{path}.plate", "a plate number (1, 2, …) as in the trial", plate)
        if plate in seen:
            r.fail(f"{path}.plate", "a plate not assigned before", plate)
        seen.add(plate)
        body = names.body(r.string(item["body"], f"{path}.body"), f"{path}.body")
        if body == GROUND:
            r.fail(f"{path}.body", "a moving body", body)
        plates.append(PlateAssignment(plate, body))
    contact = []
    for k, item in enumerate(r.items(spec.get("contact"), "loads.contact")):
        path = f"loads.contact[{k}]"
        body = names.body(r.string(item, path), path)
        if body == GROUND or body in contact:
            r.fail(path, "a moving body not listed before", body)
        contact.append(body)
    return tuple(plates), threshold, tuple(contact)


def _subject(r: _Reader, doc: dict, angle_scale: float) -> SubjectMeasurements:
    """The ``subject:`` section: body mass and the measurements of model/subject.py."""
    spec = r.mapping(doc.get("subject") or {}, "subject", allowed=yaml_keys())
    return from_yaml(spec, angle_scale, r.fail)


def _virtual_markers(r: _Reader, doc: dict) -> FrozenMap:
    """``virtual_markers: {NAME: mid(A, B)}``: model marker names made from trial labels."""
    spec = r.mapping(doc.get("virtual_markers") or {}, "virtual_markers")
    return _frozen({name: canonical(r.string(text, f"virtual_markers.{name}"),
                                    f"{r.source}: virtual_markers.{name}")
                    for name, text in spec.items()})


def _calibration(r: _Reader, doc: dict) -> tuple[FrozenMap, str | None]:
    spec = r.mapping(doc.get("calibration") or {}, "calibration",
                     allowed={"landmarks", "method"})
    landmarks = r.mapping(spec.get("landmarks") or {}, "calibration.landmarks")
    method = spec.get("method")
    if method is not None and method not in CALIBRATION_METHODS:
        r.fail("calibration.method", f"one of {', '.join(CALIBRATION_METHODS)}", method)
    return _frozen({r.string(k, "calibration.landmarks"):
                    r.string(v, f"calibration.landmarks.{k}") for k, v in landmarks.items()}), \
        method


def _calibrated(r: _Reader, doc: dict) -> CalibrationRecord | None:
    """The record ``fccgrb calibrate`` writes (``calibrated: {trial, frames, fit_mm,
    warnings}``), or None."""
    if "calibrated" not in doc:
        return None
    spec = r.mapping(doc["calibrated"], "calibrated",
                     required=frozenset({"trial", "frames", "fit_mm"}),
                     allowed={"trial", "frames", "fit_mm", "warnings"})
    frames = spec["frames"]
    if not isinstance(frames, list) or len(frames) != 2 or \
            not all(isinstance(f, int) and not isinstance(f, bool) for f in frames):
        r.fail("calibrated.frames", "[A, B], frame indices", frames)
    fit = spec["fit_mm"]
    if not isinstance(fit, list) or len(fit) != 2:
        r.fail("calibrated.fit_mm", "[mean, max] in mm", fit)
    mean, largest = (r.number(v, f"calibrated.fit_mm[{k}]") for k, v in enumerate(fit))
    warnings = tuple(r.string(w, f"calibrated.warnings[{k}]")
                     for k, w in enumerate(r.items(spec.get("warnings"), "calibrated.warnings")))
    return CalibrationRecord(r.string(str(spec["trial"]), "calibrated.trial"),
                             (int(frames[0]), int(frames[1])), (mean, largest), warnings)


def parse_model(text: str, source: str = "<model>") -> Model:
    """Validate a model given as YAML text (or an OpenSim ``.osim`` document, which a run
    stores as its model text); ``source`` names it in error messages (and is the model's
    ``source``). The same text is parsed once per process (a Model is immutable; :func:`kept`):
    a solve loads its model file and then rebuilds the run's model from its copy of the text
    when it writes, and a study's worker parses the same subject's model for each of its trials
    (~25 ms each for a calibrated lower-limb model or an OpenSim gait model)."""
    model = _PARSED.get(text)
    if model is None:
        model = kept(_parse_model(text, source))
    return model if model.source == source else dataclasses.replace(model, source=source)


_PARSED: collections.OrderedDict[str, Model] = collections.OrderedDict()  # text -> model


def kept(model: Model) -> Model:
    """``model``, remembered by its text for :func:`parse_model` (the last 8 texts)."""
    _PARSED[model.text] = model
    _PARSED.move_to_end(model.text)
    while len(_PARSED) > 8:
        _PARSED.popitem(last=False)
    return model


def _parse_model(text: str, source: str) -> Model:
    if text.lstrip().startswith("<"):
        from fccgrb_cli.model.osim.convert import parse_osim_model

        return parse_osim_model(text, source)
    doc = load_yaml(text, source, _UniqueKeyLoader)
    r = _Reader(source)
    doc = r.mapping(doc, "", required=frozenset({"bodies"}), allowed=TOP_KEYS)
    scale = _angle_scale(r, doc)
    gravity = r.vec3(doc.get("gravity", [0.0, 0.0, -9.81]), "gravity")
    gspec = r.mapping(doc.get("ground") or {}, "ground", allowed={"points", "vectors"})
    ground = Ground(
        points=_frozen(_named_points(r, gspec.get("points"), "ground.points")),
        vectors=_frozen(_named_vectors(r, gspec.get("vectors"), "ground.vectors", GROUND_AXES)),
    )
    bodies = _bodies(r, doc, scale)
    names = _Names(r, ground, bodies)
    joints = _joints(r, doc, names)
    _check_base_motions(r, bodies, joints)
    seen: set[str] = set()
    angles = _angles(r, doc, names, scale, seen)
    distances = _distances(r, doc, names, scale, seen)
    tracked_points, tracked_vectors = _tracking(r, doc, names)
    plates, threshold, contact = _loads(r, doc, names)
    subject = _subject(r, doc, scale)
    landmarks, method = _calibration(r, doc)
    return Model(
        name=r.string(doc.get("name", Path(source).stem), "name"),
        gravity=gravity,
        ground=ground,
        bodies=bodies,
        joints=joints,
        angles=angles + distances,
        tracked_points=tracked_points,
        tracked_vectors=tracked_vectors,
        force_plates=plates,
        plate_threshold=threshold,
        contact_bodies=contact,
        subject_mass=subject.body_mass,
        landmarks=landmarks,
        calibration_method=method,
        measurements=subject,
        virtual_markers=_virtual_markers(r, doc),
        source=source,
        text=text,
        calibrated=_calibrated(r, doc),
    )


def load_model(path: str | Path) -> Model:
    """Read and validate a model file (static checks; see ``system.structure`` for rank): a
    fccgrb YAML model, or an OpenSim ``.osim`` model (``fccgrb_cli.model.osim.convert``)."""
    if str(path).lower().endswith(".osim"):
        from fccgrb_cli.model.osim.convert import load_osim

        return kept(load_osim(path))
    return parse_model(read_text(path, "model file"), str(path))

"""Random open-tree models for the property-based tests (tests/test_generated.py).

A case is drawn in two steps: hypothesis draws the structure (:class:`Structure`: how many
bodies, each body's parent, each joint's type, a fixed or a floating base, the body form) and a
seed; the seed draws the numbers (geometry, inertia, motions) with numpy. :func:`build_case`
turns both into a :class:`Case`: the model as YAML text, loaded by the package exactly like a
user's file, and everything the test's own kinematics and Newton–Euler (tests/rne.py) need,
none of it taken from the package.

Each joint of body c (child) to its parent p is parametrized by its own joint variables φ:
slides s_k along axes ê_k fixed in the parent, then elementary rotations about axes ℓ_k taken in
order (each about the frame reached so far, Cardan style),

    Q = P + R_p Σ ê_k s_k,     R_c = R_p · Rot(ℓ_1, φ_1) Rot(ℓ_2, φ_2) … · R_p0ᵀ R_c0,

with P the parent's joint point, Q the child's, R_p0, R_c0 the neutral orientations (φ = 0,
slides at their mean). The joint's axes e1, e2, e3 (a random orthonormal frame at the neutral
pose) are written into both bodies as named vectors, so that the package's joint equations and
coordinates (README "The model file"; fccgrb_cli/system/constraints.py) name them:

========== ============ ============== =========================================================
type       rotations    slides         package coordinates (cos θ = s1·s2; d = (r_Q − r_P)·s)
========== ============ ============== =========================================================
spherical  e1, e2, e3   –              (−e3_p, e2_c), (−e1_p, e3_c), (−e2_p, e1_c)
revolute   e1           –              (e2_p, e3_c) = 90° + φ
universal  e1, e2       –              (−e3_p, e2_c) = 90° + φ1, (−e1_p, e3_c) = 90° + φ2
cylindrical e1          e1             (e2_p, e3_c); d along e1_p
prismatic  –            e1             d along e1_p (lock: e2_p ⟂ e3_c)
parallel   e1           e1, e2, e3     (e2_p, e3_c); d along e1_p, e2_p, e3_p
line       e1, e2, e3   e1             as spherical; d along e1_p
========== ============ ============== =========================================================

Every angle is 90° at the neutral pose and the rotations stay within ±30°, so every angle keeps
inside (0°, 180°) and θ(φ) stays invertible. A floating base (no ground joint) moves as the
README's ``bodies.NAME.motion`` says: r = r₀ + t(t), R = Rz(az) Ry(ay) Rx(ax) R₀.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import yaml
from hypothesis import strategies as st

JOINT_TYPES = ("spherical", "revolute", "universal", "cylindrical", "prismatic", "parallel")
# A line joint (a spherical joint sliding along a line of its parent) is not drawn (adding a type
# would change every drawn case); tests/test_generated.py features it.
ROTATIONS = {"spherical": (0, 1, 2), "revolute": (0,), "universal": (0, 1),
             "cylindrical": (0,), "prismatic": (), "parallel": (0,), "line": (0, 1, 2)}
SLIDES = {"spherical": (), "revolute": (), "universal": (), "cylindrical": (0,),
          "prismatic": (0,), "parallel": (0, 1, 2), "line": (0,)}
MAX_ROTATION = np.radians(30.0)   # |φ| of any rotation, mean and amplitudes together
MAX_FREQUENCY = 1.5               # Hz, every motion term (joint variables and base)
MARKERS_PER_BODY = 3


@dataclass(frozen=True)
class Structure:
    """What hypothesis draws: parent of each body (−1: the ground), the type of each body's
    joint to its parent (None for a floating base's root), the body form, and a seed."""

    parents: tuple[int, ...]
    joints: tuple[str | None, ...]
    form: str
    seed: int

    @property
    def floating(self) -> bool:
        return self.joints[0] is None


@st.composite
def structures(draw: st.DrawFn, floating: bool, max_bodies: int = 6) -> Structure:
    """2 to ``max_bodies`` bodies, serial or branched, every joint type possible."""
    n = draw(st.integers(2, max_bodies))
    serial = draw(st.booleans())
    parents = [-1] + [i - 1 if serial else draw(st.integers(0, i - 1)) for i in range(1, n)]
    joints = [None if floating else draw(st.sampled_from(JOINT_TYPES))]
    joints += [draw(st.sampled_from(JOINT_TYPES)) for _ in range(1, n)]
    form = draw(st.sampled_from(("full", "reduced")))
    return Structure(tuple(parents), tuple(joints), form, draw(st.integers(0, 2**31 - 1)))


# --- the numbers ---------------------------------------------------------------------------

def random_rotation(rng: np.random.Generator) -> np.ndarray:
    """A uniformly random proper rotation (QR of a Gaussian matrix, signs fixed)."""
    Q, R = np.linalg.qr(rng.normal(size=(3, 3)))
    Q = Q @ np.diag(np.sign(np.diag(R)))
    if np.linalg.det(Q) < 0:
        Q[:, 2] = -Q[:, 2]
    return Q


def rot(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rotation by ``angle`` about the unit vector ``axis`` (Rodrigues)."""
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * (K @ K)


def random_terms(rng: np.random.Generator, budget: float) -> tuple[tuple[float, float, float], ...]:
    """Two sinusoids (amplitude, Hz, phase rad) whose amplitudes add up to at most ``budget``."""
    amplitudes = rng.uniform(0.3, 1.0, 2)
    amplitudes *= budget * rng.uniform(0.5, 1.0) / amplitudes.sum()
    return tuple((float(a), float(rng.uniform(0.3, MAX_FREQUENCY)),
                  float(rng.uniform(0, 2 * np.pi))) for a in amplitudes)


@dataclass(frozen=True)
class Signal:
    """mean + Σ A sin(2π f t + p), with exact first and second derivatives."""

    mean: float
    terms: tuple[tuple[float, float, float], ...]

    def at(self, t: np.ndarray) -> np.ndarray:
        """(3, len(t)): value, first and second derivative."""
        t = np.asarray(t, dtype=float)
        out = np.zeros((3, *t.shape))
        out[0] += self.mean
        for a, f, p in self.terms:
            w = 2 * np.pi * f
            out[0] += a * np.sin(w * t + p)
            out[1] += a * w * np.cos(w * t + p)
            out[2] -= a * w * w * np.sin(w * t + p)
        return out

    def yaml(self) -> dict:
        return {"mean": self.mean, "terms": [{"amplitude": a, "frequency": f, "phase": p}
                                             for a, f, p in self.terms]}


@dataclass
class JointData:
    """The joint of ``child`` to ``parent`` (−1: the ground)."""

    name: str
    type: str
    parent: int
    child: int
    frame: np.ndarray            # neutral global joint axes e1, e2, e3 (columns)
    p_point: np.ndarray          # P, local to the parent (global for the ground)
    q_point: np.ndarray          # Q, local to the child
    rel0: np.ndarray             # R_p0ᵀ R_c0
    slide_mean: np.ndarray       # 3 neutral slides along e1, e2, e3 (zero where none)
    rotations: tuple[int, ...]   # which of e1, e2, e3 it turns about, in order
    slides: tuple[int, ...]      # which of e1, e2, e3 it slides along
    variables: list[Signal] = field(default_factory=list)  # slides first, then rotations


@dataclass
class BodyData:
    name: str
    parent: int
    mass: float
    com: np.ndarray              # local
    tensor: np.ndarray           # about the CoM, body frame, full (not diagonal)
    R0: np.ndarray               # neutral orientation (columns u, v, w)
    r0: np.ndarray               # neutral origin
    points: dict[str, np.ndarray] = field(default_factory=dict)
    vectors: dict[str, np.ndarray] = field(default_factory=dict)


@dataclass(frozen=True)
class Coordinate:
    """A package coordinate, as the test computes it: an angle between the vectors
    (body, local) ``a`` and ``b``, or a distance (r_Q − r_P)·s with points a, b and axis s."""

    name: str
    kind: str
    a: tuple[int, np.ndarray]
    b: tuple[int, np.ndarray]
    axis: np.ndarray | None = None
    joint: int = -1                     # the body whose joint it measures
    refs: tuple[str, str] = ("", "")    # the YAML's names of a and b
    axis_ref: str = ""


@dataclass
class Case:
    structure: Structure
    bodies: list[BodyData]
    joints: list[JointData]                    # joints[i] is body i's joint (None: floating)
    coordinates: list[Coordinate]
    markers: list[tuple[str, int, np.ndarray]]  # label, body, local point
    base_translation: tuple[Signal, Signal, Signal] | None
    base_rotation: tuple[Signal, Signal, Signal] | None
    load_body: int
    load_point: np.ndarray                     # local to the load body
    load_terms: np.ndarray                     # (6, 3): force / moment amplitude, Hz, phase
    gravity: np.ndarray
    spec: dict

    @property
    def floating(self) -> bool:
        return self.structure.floating

    @property
    def n_phi(self) -> int:
        return sum(len(j.variables) for j in self.joints if j is not None)

    @property
    def text(self) -> str:
        return yaml.safe_dump(self.spec, sort_keys=False)

    def load(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """External force (N) and free moment (N·m) on the load body, frames × 3."""
        t = np.asarray(t, dtype=float)[:, None]
        a, f, p = self.load_terms[:, 0], self.load_terms[:, 1], self.load_terms[:, 2]
        values = a * np.sin(2 * np.pi * f * t + p) + 0.5 * a
        return values[:, :3], values[:, 3:]


def _inertia(rng: np.random.Generator) -> tuple[float, np.ndarray]:
    """Mass and a full inertia tensor about the CoM: a box's principal moments (so the triangle
    inequality holds strictly) turned by a random rotation."""
    mass = float(rng.uniform(0.5, 4.0))
    a, b, c = rng.uniform(0.05, 0.4, 3)
    principal = mass / 12 * np.array([b * b + c * c, a * a + c * c, a * a + b * b])
    assert principal.max() < principal.sum() - principal.max()  # triangle inequality, strict
    R = random_rotation(rng)
    return mass, R @ np.diag(principal) @ R.T


def _vec(x: np.ndarray) -> list[float]:
    return [float(v) for v in x]


def build_case(s: Structure) -> Case:
    """Geometry, inertia and motions from the structure's seed; the YAML the package loads."""
    rng = np.random.default_rng(s.seed)
    n = len(s.parents)
    bodies: list[BodyData] = []
    joints: list[JointData | None] = []
    ground_points: dict[str, np.ndarray] = {}
    ground_vectors: dict[str, np.ndarray] = {}
    for i in range(n):
        mass, tensor = _inertia(rng)
        body = BodyData(f"B{i}", s.parents[i], mass, rng.uniform(-0.05, 0.05, 3), tensor,
                        random_rotation(rng), np.zeros(3))
        jtype = s.joints[i]
        if jtype is None:                      # a floating root
            body.r0 = rng.uniform(-0.3, 0.3, 3) + np.array([0.0, 0.0, 1.0])
            bodies.append(body)
            joints.append(None)
            continue
        p = s.parents[i]
        frame = random_rotation(rng)
        if p < 0:
            R_p0, r_p0 = np.eye(3), np.zeros(3)
            p_point = rng.uniform(-0.2, 0.2, 3)
        else:
            R_p0, r_p0 = bodies[p].R0, bodies[p].r0
            p_point = rng.uniform(-0.25, 0.25, 3)
        q_point = rng.uniform(-0.2, 0.2, 3)
        slide_mean = np.zeros(3)
        for k in SLIDES[jtype]:
            slide_mean[k] = rng.uniform(0.05, 0.25) * rng.choice((-1.0, 1.0))
        J0 = r_p0 + R_p0 @ p_point + frame @ slide_mean
        body.r0 = J0 - body.R0 @ q_point
        joint = JointData(f"J{i}", jtype, p, i, frame, p_point, q_point, R_p0.T @ body.R0,
                          slide_mean, ROTATIONS[jtype], SLIDES[jtype])
        for k in joint.slides:
            joint.variables.append(Signal(float(slide_mean[k]), random_terms(rng, 0.08)))
        for _ in joint.rotations:
            mean = float(rng.uniform(-0.3, 0.3) * MAX_ROTATION)
            joint.variables.append(Signal(mean, random_terms(rng, MAX_ROTATION - abs(mean))))
        # the joint's axes and points, named in both bodies (local components)
        for k, e in enumerate(frame.T):
            for sign, tag in ((1.0, "e"), (-1.0, "me")):
                local_p = R_p0.T @ (sign * e)
                (ground_vectors if p < 0 else bodies[p].vectors)[f"{joint.name}p_{tag}{k + 1}"] \
                    = local_p
                body.vectors[f"{joint.name}c_{tag}{k + 1}"] = body.R0.T @ (sign * e)
        (ground_points if p < 0 else bodies[p].points)[f"{joint.name}P"] = p_point
        body.points[f"{joint.name}Q"] = q_point
        bodies.append(body)
        joints.append(joint)
    for body in bodies:                        # markers: 3 non-collinear points per body
        while True:
            pts = rng.uniform(-0.15, 0.15, (MARKERS_PER_BODY, 3))
            if np.linalg.svd(pts - pts.mean(axis=0), compute_uv=False)[1] > 0.03:
                break
        for k, pt in enumerate(pts):
            body.points[f"{body.name}_m{k}"] = pt
    base_translation = base_rotation = None
    if s.floating:
        base_translation = tuple(Signal(0.0, random_terms(rng, 0.25)) for _ in range(3))
        base_rotation = tuple(Signal(float(rng.uniform(-0.2, 0.2)),
                                     random_terms(rng, np.radians(30.0))) for _ in range(3))
    coordinates = _coordinates(joints, bodies, ground_vectors)
    load_body = int(rng.integers(0, n))
    load_point = rng.uniform(-0.1, 0.1, 3)
    bodies[load_body].points["H"] = load_point
    load_terms = np.column_stack([np.r_[rng.uniform(2, 10, 3), rng.uniform(0.1, 0.5, 3)],
                                  rng.uniform(0.2, 1.2, 6), rng.uniform(0, 2 * np.pi, 6)])
    gravity = np.array([0.0, 0.0, -9.81])
    markers = [(name, i, pt) for i, b in enumerate(bodies) for name, pt in b.points.items()
               if "_m" in name]
    case = Case(s, bodies, joints, coordinates, markers, base_translation, base_rotation,
                load_body, load_point, load_terms, gravity, {})
    case.spec = _spec(case, ground_points, ground_vectors)
    return case


def angle_pairs(jtype: str) -> list[tuple[str, str]]:
    """The (parent, child) vector names of a joint's angles (table in the module docstring)."""
    spherical = [("me3", "e2"), ("me1", "e3"), ("me2", "e1")]
    return {"spherical": spherical, "line": spherical,
            "universal": [("me3", "e2"), ("me1", "e3")]}.get(
        jtype, [("e2", "e3")] if ROTATIONS[jtype] else [])


def _coordinates(joints: list[JointData | None], bodies: list[BodyData],
                 ground_vectors: dict[str, np.ndarray]) -> list[Coordinate]:
    """The package's coordinates of every joint, with the names the YAML gives them."""
    out = []

    def owner(i: int) -> str:
        return "ground" if i < 0 else bodies[i].name

    for j in joints:
        if j is None:
            continue
        p, c = j.parent, j.child
        vectors = ground_vectors if p < 0 else bodies[p].vectors
        for k, (a, b) in enumerate(angle_pairs(j.type)):
            pa, cb = f"{j.name}p_{a}", f"{j.name}c_{b}"
            out.append(Coordinate(f"{j.name}_a{k}", "angle", (p, vectors[pa]),
                                  (c, bodies[c].vectors[cb]), joint=c,
                                  refs=(f"{owner(p)}.{pa}", f"{owner(c)}.{cb}")))
        for k in j.slides:
            axis = f"{j.name}p_e{k + 1}"
            out.append(Coordinate(f"{j.name}_d{k + 1}", "distance", (p, j.p_point),
                                  (c, j.q_point), vectors[axis], joint=c,
                                  refs=(f"{owner(p)}.{j.name}P", f"{owner(c)}.{j.name}Q"),
                                  axis_ref=f"{owner(p)}.{axis}"))
    return sorted(out, key=lambda c: c.kind != "angle")  # the package's order: angles first


def _spec(case: Case, ground_points: dict, ground_vectors: dict) -> dict:
    """The model as the dict the YAML loader reads (angles in rad)."""
    bodies = {}
    for b in case.bodies:
        entry = {
            "mass": b.mass, "com": _vec(b.com), "inertia": [_vec(row) for row in b.tensor],
            "points": {k: _vec(v) for k, v in b.points.items()},
            "vectors": {k: _vec(v) for k, v in b.vectors.items()},
            "pose": {"r": _vec(b.r0), "u": _vec(b.R0[:, 0]), "v": _vec(b.R0[:, 1]),
                     "w": _vec(b.R0[:, 2])},
        }
        if b.parent < 0 and case.floating:
            entry["motion"] = {"translation": [m.yaml() for m in case.base_translation],
                               "rotation": [m.yaml() for m in case.base_rotation]}
        bodies[b.name] = entry

    joints = []
    for j in case.joints:
        if j is None:
            continue
        parent = "ground" if j.parent < 0 else case.bodies[j.parent].name
        entry = {"name": j.name, "type": j.type, "bodies": [parent, case.bodies[j.child].name]}
        if j.type != "parallel":
            entry["points"] = [f"{j.name}P", f"{j.name}Q"]
        if j.type == "line":
            entry["axis"] = f"{j.name}p_e1"
        elif j.type != "spherical":
            entry["axes"] = [f"{j.name}p_e1", f"{j.name}c_e{2 if j.type == 'universal' else 1}"]
        if j.type == "prismatic":
            entry["lock"] = [f"{j.name}p_e2", f"{j.name}c_e3"]
        joints.append(entry)
    angles = [{"name": c.name, "vectors": list(c.refs)}
              for c in case.coordinates if c.kind == "angle"]
    distances = [{"name": c.name, "points": list(c.refs), "axis": c.axis_ref}
                 for c in case.coordinates if c.kind == "distance"]
    spec = {
        "name": "generated", "units": {"angle": "rad"}, "gravity": _vec(case.gravity),
        "form": case.structure.form,
        "ground": {"points": {k: _vec(v) for k, v in ground_points.items()},
                   "vectors": {k: _vec(v) for k, v in ground_vectors.items()}},
        "bodies": bodies, "joints": joints, "angles": angles,
    }
    if distances:
        spec["distances"] = distances
    spec["tracking"] = {"points": [{"marker": label, "point": f"B{i}.{label}"}
                                   for label, i, _ in case.markers]}
    return spec


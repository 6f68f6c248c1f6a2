"""The bundled five-bar (configs/models/five_bar.yaml) in minimal coordinates, written here
independently of the package: an oracle for tests that need the exact optimum of a problem posed
on the mechanism's topology (tests/test_regression.py).

Only numbers are read from the YAML (``yaml.safe_load``: joint points, angle vectors, prescribed
motions); the topology is hand-coded in ``CHAIN`` and checked against the YAML's joint list by
:func:`check_topology`. Each joint's relative rotation is a product of elementary rotations about
axes of the frame reached so far, one per joint variable φ:

    B1 = Rz(φ1)                       J1, revolute about ground z ≡ B1 w
    B2 = B1 Rz(φ2) Ry(φ3)             J2, universal: about the arm B1.w, then about the arm B2.v
    B3 = B2 Rz(φ4)                    J3, revolute about B2.w ≡ B3.w
    B4 = B3 Rx(φ5) Ry(φ6) Rz(φ7)      J4, spherical (Cardan x–y–z)
    B5 = B4 Rz(φ8) Ry(φ9)             J5, universal: about the arm B4.w, then about the arm B5.v

(the YAML states that every body frame is aligned with the ground's at the neutral pose, φ = 0;
:func:`check_topology` checks that too). A universal joint keeps its arms s_i ⟂ s_j: with
R_rel = Rz(α) Ry(β), R_rel e_y = Rz(α) e_y stays ⟂ e_z for every α, β, and the two parameters
cover the two-dimensional set of such rotations. Every configuration of these 9 variables
satisfies the topology exactly, so problems "subject to the topology" become unconstrained.

Positions follow the chain: the joint centre is where the parent's joint point is, and the body's
origin is that centre minus R_body times the body's own joint point. Jacobians are analytic:
∂r_P/∂φ_k = z_k × (r_P − c_k) for every elementary rotation k upstream of P's body (z_k its global
axis, c_k its joint centre), and ∂(s1·s2)/∂φ_k = (z_k × s1)·s2 + s1·(z_k × s2) over the vectors it
moves.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
MODEL = ROOT / "configs" / "models" / "five_bar.yaml"
SPEC = yaml.safe_load(MODEL.read_text(encoding="utf-8"))
DEG = np.pi / 180.0
AXIS = {"u": 0, "v": 1, "w": 2, "x": 0, "y": 1, "z": 2}
BUILTIN = {"u": (1.0, 0.0, 0.0), "v": (0.0, 1.0, 0.0), "w": (0.0, 0.0, 1.0),
           "x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0)}

# (body, parent, parent's joint point, body's joint point, local axes of the elementary
# rotations in order, the joint's type and axes as the YAML must state them)
CHAIN = (
    ("B1", "ground", "O", "P1", ("w",), "revolute", ["z", "w"]),
    ("B2", "B1", "P2", "P2", ("w", "v"), "universal", ["w", "v"]),
    ("B3", "B2", "P3", "P3", ("w",), "revolute", ["w", "w"]),
    ("B4", "B3", "P4", "P4", ("u", "v", "w"), "spherical", None),
    ("B5", "B4", "P5", "P5", ("w", "v"), "universal", ["w", "v"]),
)
BODIES = tuple(c[0] for c in CHAIN)
N_PHI = sum(len(c[4]) for c in CHAIN)
BODY_INDEX = {body: k for k, body in enumerate(BODIES)}
# serial chain: body k is moved by the elementary rotations 0 … ELEM_END[k] − 1
ELEM_END = np.cumsum([len(c[4]) for c in CHAIN])


def check_topology(spec: dict = SPEC) -> None:
    """The YAML's joints, in order, are the chain hand-coded above; every body starts aligned
    with the ground frame (φ = 0 is the stated neutral pose)."""
    joints = spec["joints"]
    assert len(joints) == len(CHAIN), joints
    for joint, (body, parent, on_parent, on_body, _, kind, axes) in zip(joints, CHAIN,
                                                                         strict=True):
        assert joint["type"] == kind, joint
        assert joint["bodies"] == [parent, body], joint
        assert joint["points"] == [on_parent, on_body], joint
        assert joint.get("axes") == axes, joint
    for body in BODIES:
        pose = spec["bodies"][body]["pose"]
        assert np.array_equal(np.array([pose["u"], pose["v"], pose["w"]], float), np.eye(3))
    assert spec["units"]["angle"] == "deg"


def local_point(body: str, name: str) -> np.ndarray:
    points = SPEC["ground"]["points"] if body == "ground" else SPEC["bodies"][body]["points"]
    return np.array(points[name], dtype=float)


def local_vector(body: str, name: str) -> np.ndarray:
    if name in BUILTIN:
        return np.array(BUILTIN[name])
    where = SPEC["ground"] if body == "ground" else SPEC["bodies"][body]
    return np.array(where["vectors"][name], dtype=float)


def rotation(axis: int, angle: float) -> np.ndarray:
    """Elementary rotation about coordinate axis 0, 1 or 2."""
    c, s = np.cos(angle), np.sin(angle)
    i, j = ((1, 2), (2, 0), (0, 1))[axis]
    out = np.eye(3)
    out[i, i] = out[j, j] = c
    out[i, j], out[j, i] = -s, s
    return out


_STEPS = tuple((local_point(parent, on_parent), local_point(body, on_body),
                tuple(AXIS[a] for a in axes), BODY_INDEX.get(parent, -1))
               for body, parent, on_parent, on_body, axes, _, _ in CHAIN)


def pose(phi: np.ndarray) -> tuple[list[np.ndarray], list[np.ndarray], np.ndarray, np.ndarray]:
    """Every body's rotation R (columns u, v, w) and origin r, and each elementary rotation's
    global axis z_k and joint centre c_k (N_PHI × 3 each)."""
    rotations: list[np.ndarray] = []
    origins: list[np.ndarray] = []
    z, c = np.empty((N_PHI, 3)), np.empty((N_PHI, 3))
    k = 0
    for on_parent, on_body, axes, parent in _STEPS:
        R_parent = np.eye(3) if parent < 0 else rotations[parent]
        r_parent = np.zeros(3) if parent < 0 else origins[parent]
        centre = r_parent + R_parent @ on_parent
        R = R_parent
        for axis in axes:
            R = R @ rotation(axis, phi[k])
            z[k], c[k] = R[:, axis], centre
            k += 1
        rotations.append(R)
        origins.append(centre - R @ on_body)
    return rotations, origins, z, c


class Points:
    """Global positions of named body points (``which``: (body, point) pairs) and their
    Jacobian (points × 3 × N_PHI) at φ."""

    def __init__(self, which: list[tuple[str, str]]):
        self.body = np.array([BODY_INDEX[b] for b, _ in which])
        self.local = np.array([local_point(b, p) for b, p in which])
        self.moved = np.arange(N_PHI)[None, :] < ELEM_END[self.body][:, None]

    def __call__(self, phi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        rotations, origins, z, c = pose(phi)
        R, r = np.array(rotations)[self.body], np.array(origins)[self.body]
        P = r + np.einsum("pij,pj->pi", R, self.local)
        J = np.cross(z[None], P[:, None, :] - c[None]) * self.moved[:, :, None]
        return P, np.transpose(J, (0, 2, 1))


def tracked(markers: list[str] | tuple[str, ...]) -> list[tuple[str, str]]:
    """(body, point) of the YAML's tracked markers, in the order given."""
    by_marker = {tp["marker"]: tuple(tp["point"].split(".")) for tp in SPEC["tracking"]["points"]}
    return [by_marker[m] for m in markers]


ANGLE_VECTORS = tuple(tuple(tuple(s.split(".")) for s in a["vectors"]) for a in SPEC["angles"])


def angles(phi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """θ_k = acos(s1·s2) of the YAML's angles (rad) and ∂θ/∂φ."""
    rotations, _, z, _ = pose(phi)
    theta = np.empty(len(ANGLE_VECTORS))
    J = np.zeros((len(ANGLE_VECTORS), N_PHI))
    for i, ((b1, n1), (b2, n2)) in enumerate(ANGLE_VECTORS):
        s = []
        for body, name in ((b1, n1), (b2, n2)):
            R = np.eye(3) if body == "ground" else rotations[BODY_INDEX[body]]
            s.append(R @ local_vector(body, name))
        theta[i] = np.arccos(np.clip(s[0] @ s[1], -1.0, 1.0))
        for k in range(N_PHI):
            d = 0.0
            if b1 != "ground" and k < ELEM_END[BODY_INDEX[b1]]:
                d += np.cross(z[k], s[0]) @ s[1]
            if b2 != "ground" and k < ELEM_END[BODY_INDEX[b2]]:
                d += s[0] @ np.cross(z[k], s[1])
            J[i, k] = -d / np.sin(theta[i])
    return theta, J


def closed_form(t: np.ndarray) -> np.ndarray:
    """θ(t) (frames × angles, rad) of the YAML's prescribed motions, mean + Σ A sin(2πft + p)."""
    out = []
    for angle in SPEC["angles"]:
        motion = angle["motion"]
        theta = np.full(len(t), motion["mean"] * DEG)
        for term in motion.get("terms", []):
            theta += term["amplitude"] * DEG * np.sin(2 * np.pi * term["frequency"] * t
                                                      + term.get("phase", 0.0) * DEG)
        out.append(theta)
    return np.column_stack(out)


def joint_variables(theta: np.ndarray) -> np.ndarray:
    """φ (frames × N_PHI) with angles(φ) = θ in every frame: Newton from the previous frame's φ,
    the first from the neutral pose (every angle's branch is the one continuous with it)."""
    phi = np.zeros(N_PHI)
    out = np.empty((len(theta), N_PHI))
    for f, target in enumerate(theta):
        for _ in range(50):
            value, J = angles(phi)
            step = np.linalg.solve(J, target - value)
            phi = phi + step
            if np.abs(step).max() < 1e-14:
                break
        assert np.abs(angles(phi)[0] - target).max() < 1e-12, f
        out[f] = phi
    return out

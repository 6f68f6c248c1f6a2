"""Joint moments of a spatial open chain against an independent recursive Newton–Euler (RNE).

The chain hangs from the ground: ground–B1 revolute (about ground x), B1–B2 universal (arms
B1.u and B2.v), B2–B3 spherical, B3–B4 revolute (about B3.v), seven angular degrees of freedom.
Every body's centre of mass is off its reference point (YAML ``com``); B2 and B3 have full
(non-diagonal) inertia tensors. An external force at a point of B3 and a free moment on B3 are
applied as well.

What is independent of the package: the expectation is computed in this file from the YAML text
(read with ``yaml.safe_load``, only numbers: points, vectors, masses, inertias) and a hand-coded
topology. Each joint's relative rotation is parametrised by its own joint variables φ,

    R1 = Rx(φ1),  R2 = R1 Rx(φ2) Ry(φ3),  R3 = R2 Rx(φ4) Ry(φ5) Rz(φ6),  R4 = R3 Ry(φ7),

prescribed as sums of sinusoids. The forward pass of a textbook RNE (one elementary revolute per
joint variable, massless intermediate frames) gives ω, α and the accelerations of the centres of
mass; the backward pass gives each joint's force and moment (Newton and Euler about the centre of
mass, with gravity and the external load). The moment conjugate to φ_k is z_k · n_joint, and the
chain rule through θ(φ) turns it into the moment conjugate to the model's angles θ_k
(cos θ_k = s1 · s2). θ, θ̇ and θ̈ fed to the package come from the same closed form. None of the
package's loader output, constraint equations, mass matrices or solvers is used for the
expectation; the package (parse_model → compile_system → solve_ad → inverse_dynamics) only
produces what is under test. The forward pass itself is checked against 8th-order central
differences of the closed-form motion.
"""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from fccgrb_cli.dynamics import ExternalLoad, inverse_dynamics
from fccgrb_cli.model import parse_model
from fccgrb_cli.solvers import solve_ad
from fccgrb_cli.solvers.ad.solve import stacked_drives
from fccgrb_cli.system import compile_system

MODEL_YAML = """
name: chain
units: {angle: deg}
gravity: [0, 0, -9.81]
form: full
ground:
  points: {O: [0, 0, 0]}
  vectors: {down: [0, 0, -1]}
bodies:
  B1:                                    # 0.35 m link, its top point A at the ground point O
    mass: 2.0
    com: [0.01, -0.015, 0.02]
    inertia: [0.025, 0.024, 0.002]
    points: {A: [0, 0, 0.15], P1: [0, 0, -0.2]}
    vectors: {minus_u: [-1, 0, 0], minus_w: [0, 0, -1]}
    pose: {r: [0, 0, -0.15], u: [1, 0, 0], v: [0, 1, 0], w: [0, 0, 1]}
  B2:                                    # 0.45 m link
    mass: 1.5
    com: [0.0, 0.02, -0.03]
    inertia: [[0.026, 0.002, -0.001], [0.002, 0.025, 0.0015], [-0.001, 0.0015, 0.005]]
    points: {C: [0, 0, 0.2], D: [0, 0, -0.25]}
    vectors: {minus_u: [-1, 0, 0], minus_v: [0, -1, 0], minus_w: [0, 0, -1]}
    pose: {r: [0, 0, -0.55], u: [1, 0, 0], v: [0, 1, 0], w: [0, 0, 1]}
  B3:                                    # 0.3 m link carrying the external load at H
    mass: 1.0
    com: [0.02, 0.01, -0.02]
    inertia: [[0.008, -0.0006, 0.0004], [-0.0006, 0.0085, -0.0005], [0.0004, -0.0005, 0.0025]]
    points: {E: [0, 0, 0.15], F: [0.05, 0, -0.15], H: [0.03, 0.04, -0.1]}
    vectors: {minus_u: [-1, 0, 0]}
    pose: {r: [0, 0, -0.95], u: [1, 0, 0], v: [0, 1, 0], w: [0, 0, 1]}
  B4:                                    # 0.2 m end link
    mass: 0.5
    com: [0.0, 0.01, -0.06]
    inertia: [0.002, 0.0021, 0.0003]
    points: {G: [0, 0, 0.1], T: [0, 0, -0.1]}
    pose: {r: [0.05, 0, -1.2], u: [1, 0, 0], v: [0, 1, 0], w: [0, 0, 1]}
joints:
  - {name: hip, type: revolute, bodies: [ground, B1], points: [O, A], axes: [x, u]}
  - {name: knee, type: universal, bodies: [B1, B2], points: [P1, C], axes: [u, v]}
  - {name: ankle, type: spherical, bodies: [B2, B3], points: [D, E]}
  - {name: toe, type: revolute, bodies: [B3, B4], points: [F, G], axes: [v, v]}
angles:                                  # cos θ = s1·s2; all 90° at the neutral pose
  - {name: hip_x, vectors: [ground.down, B1.v]}      # θ = 90° + φ1
  - {name: knee_a, vectors: [B1.minus_w, B2.v]}      # θ = 90° + φ2
  - {name: knee_b, vectors: [B1.minus_u, B2.w]}      # θ = 90° + φ3
  - {name: ankle_1, vectors: [B2.minus_w, B3.v]}     # θ = acos(−e_z·Rx Ry Rz e_y) ≈ 90° + φ4
  - {name: ankle_2, vectors: [B2.minus_u, B3.w]}     # θ = acos(−e_x·Rx Ry Rz e_z) ≈ 90° + φ5
  - {name: ankle_3, vectors: [B2.minus_v, B3.u]}     # θ = acos(−e_y·Rx Ry Rz e_x) ≈ 90° + φ6
  - {name: toe_y, vectors: [B3.minus_u, B4.w]}       # θ = 90° + φ7
"""
SPEC = yaml.safe_load(MODEL_YAML)
GRAVITY = np.array(SPEC["gravity"], dtype=float)
BUILTIN = {"u": (1.0, 0.0, 0.0), "v": (0.0, 1.0, 0.0), "w": (0.0, 0.0, 1.0),
           "x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0)}

# Hand-coded topology: (body, parent, parent's joint point, body's joint point, the local axes of
# the elementary rotations, in order). Each elementary rotation turns about an axis of the frame
# reached so far (Rx then Ry …), so its global direction is z = R_so_far[:, axis].
CHAIN = (
    ("B1", "ground", "O", "A", (0,)),       # revolute about ground x ≡ B1 u
    ("B2", "B1", "P1", "C", (0, 1)),        # universal: about arm B1.u, then about arm B2.v
    ("B3", "B2", "D", "E", (0, 1, 2)),      # spherical: Cardan x–y–z
    ("B4", "B3", "F", "G", (1,)),           # revolute about B3 v ≡ B4 v
)
BODIES = tuple(c[0] for c in CHAIN)
N_PHI = sum(len(c[4]) for c in CHAIN)

# φ_k(t) = Σ A sin(2π f t + p): (A in degrees, f in Hz, p in rad); |φ_k| ≤ 30° throughout.
PHI_TERMS = (
    ((25.0, 0.5, 0.0), (5.0, 1.3, 0.4)),
    ((20.0, 0.7, 0.5),),
    ((18.0, 0.6, 1.0), (4.0, 1.7, 0.0)),
    ((20.0, 0.8, 0.3),),
    ((15.0, 0.55, 2.0), (5.0, 1.1, 0.2)),
    ((22.0, 0.9, 1.2),),
    ((25.0, 0.75, 0.7), (5.0, 1.9, 1.5)),
)

# External load on B3: force at its point H (moves with the body) and a free moment.
LOAD_BODY, LOAD_POINT = "B3", "H"

# 20 comparison frames, each the centre of a 9-point stencil (step H_STEP) for d(T+V)/dt.
BASE_TIMES = 0.1 + 0.095 * np.arange(20)
H_STEP = 2e-3
STENCIL = np.arange(-4, 5)
D1_WEIGHTS = np.array([1 / 280, -4 / 105, 1 / 5, -4 / 5, 0.0, 4 / 5, -1 / 5, 4 / 105, -1 / 280])
TIME = (BASE_TIMES[:, None] + STENCIL * H_STEP).ravel()
BASE = np.flatnonzero(np.tile(STENCIL == 0, len(BASE_TIMES)))

# Measured (both forms): τ 7e-16, T and V 9e-16, P_ext 1e-15, power balance 1.4e-13 relative.
TOL_TAU = 1e-6          # the done-when: joint moments within 1e-6 relative
TOL_ENERGY = 1e-10      # T, V, P_ext from Newton-converged q, q̇ (tol 1e-12): rounding only
# d(T+V)/dt by the 9-point stencil: truncation ~ (2π·1.9 Hz·h)⁸ ≈ 1e-13, rounding and solver
# error ~ 1.6·(1e-13 J)/h ≈ 1e-10 W, against |d(T+V)/dt| up to 32 W; 1e-9 relative is enough.
TOL_POWER = 1e-9


# --- closed-form motion and independent kinematics ---------------------------------------------

def phi_motion(t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """φ, φ̇, φ̈ (len(t) × N_PHI, rad) at times t."""
    t = np.asarray(t, dtype=float)
    out = [np.zeros((len(t), N_PHI)) for _ in range(3)]
    for k, terms in enumerate(PHI_TERMS):
        for amp, freq, phase in terms:
            a, w = np.radians(amp), 2 * np.pi * freq
            arg = w * t + phase
            out[0][:, k] += a * np.sin(arg)
            out[1][:, k] += a * w * np.cos(arg)
            out[2][:, k] -= a * w * w * np.sin(arg)
    return out[0], out[1], out[2]


def rot(axis: int, angle: float) -> np.ndarray:
    """Rotation matrix about local axis 0 (x), 1 (y) or 2 (z)."""
    c, s = np.cos(angle), np.sin(angle)
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    R = np.eye(3)
    R[i, i] = R[j, j] = c
    R[i, j], R[j, i] = -s, s
    return R


def local_point(body: str, name: str) -> np.ndarray:
    table = SPEC["ground"]["points"] if body == "ground" else SPEC["bodies"][body]["points"]
    return np.array(table[name], dtype=float)


def local_vector(body: str, name: str) -> np.ndarray:
    if name in BUILTIN:
        return np.array(BUILTIN[name])
    table = SPEC["ground"]["vectors"] if body == "ground" else SPEC["bodies"][body]["vectors"]
    return np.array(table[name], dtype=float)


def mass_properties(body: str) -> tuple[float, np.ndarray, np.ndarray]:
    """Mass, local centre of mass and the inertia tensor about it (body frame)."""
    spec = SPEC["bodies"][body]
    tensor = np.array(spec["inertia"], dtype=float)
    if tensor.ndim == 1:
        tensor = np.diag(tensor)
    return float(spec["mass"]), np.array(spec.get("com", [0, 0, 0]), dtype=float), tensor


def forward(phi: np.ndarray, phid: np.ndarray, phidd: np.ndarray) -> dict:
    """RNE forward pass at one instant: per body R, ω, α, origin r, v, a, the joint point J
    (global) and the global axes z of its elementary rotations."""
    zero = np.zeros(3)
    state = {"ground": dict(R=np.eye(3), w=zero, al=zero, r=zero, v=zero, a=zero)}
    k = 0
    for body, parent, p_point, b_point, axes in CHAIN:
        p = state[parent]
        rho = p["R"] @ local_point(parent, p_point)
        J = p["r"] + rho
        vJ = p["v"] + np.cross(p["w"], rho)
        aJ = p["a"] + np.cross(p["al"], rho) + np.cross(p["w"], np.cross(p["w"], rho))
        R, w, al, zs = p["R"], p["w"], p["al"], []
        for ax in axes:
            z = R[:, ax]
            al = al + z * phidd[k] + np.cross(w, z) * phid[k]
            w = w + z * phid[k]
            R = R @ rot(ax, phi[k])
            zs.append(z)
            k += 1
        rho_b = -R @ local_point(body, b_point)
        state[body] = dict(
            R=R, w=w, al=al, r=J + rho_b, v=vJ + np.cross(w, rho_b),
            a=aJ + np.cross(al, rho_b) + np.cross(w, np.cross(w, rho_b)), J=J, z=zs)
    return state


def point_motion(s: dict, local: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Global position, velocity and acceleration of a body point."""
    rho = s["R"] @ local
    return (s["r"] + rho, s["v"] + np.cross(s["w"], rho),
            s["a"] + np.cross(s["al"], rho) + np.cross(s["w"], np.cross(s["w"], rho)))


def angle_vectors(state: dict, ref: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    body, name = ref.split(".")
    s = state[body]["R"] @ local_vector(body, name)
    w, al = state[body]["w"], state[body]["al"]
    return s, np.cross(w, s), np.cross(al, s) + np.cross(w, np.cross(w, s))


def model_angles(state: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """θ, θ̇, θ̈ of the model's angles: c = s1·s2 = cos θ, ċ = −θ̇ sin θ, c̈ = −θ̇² cos θ − θ̈ sin θ."""
    out = np.zeros((3, len(SPEC["angles"])))
    for k, angle in enumerate(SPEC["angles"]):
        s1, s1d, s1dd = angle_vectors(state, angle["vectors"][0])
        s2, s2d, s2dd = angle_vectors(state, angle["vectors"][1])
        c = s1 @ s2
        cd = s1d @ s2 + s1 @ s2d
        cdd = s1dd @ s2 + 2 * s1d @ s2d + s1 @ s2dd
        th = np.arccos(c)
        thd = -cd / np.sin(th)
        out[:, k] = th, thd, -(cdd + thd**2 * c) / np.sin(th)
    return out[0], out[1], out[2]


def angle_jacobian(phi: np.ndarray) -> np.ndarray:
    """∂θ/∂φ (n_angles × N_PHI): column j is θ̇ for φ̇ = e_j."""
    cols = [model_angles(forward(phi, e, np.zeros(N_PHI)))[1] for e in np.eye(N_PHI)]
    return np.column_stack(cols)


def load_history(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """External force (N) and free moment (N·m) on B3, frames × 3."""
    t = np.asarray(t)[:, None]
    force = np.hstack([6 * np.sin(2 * np.pi * 0.4 * t), -4 + 3 * np.cos(2 * np.pi * 0.9 * t),
                       5 + 2 * np.sin(2 * np.pi * 1.2 * t + 0.3)])
    moment = np.hstack([0.4 * np.cos(2 * np.pi * 0.6 * t), 0.3 * np.sin(2 * np.pi * 0.5 * t),
                        -0.2 + 0.1 * np.sin(2 * np.pi * 1.5 * t)])
    return force, moment


def backward(state: dict, force: np.ndarray, moment: np.ndarray,
             mass_scale: dict | None = None) -> dict:
    """RNE backward pass at one instant: force f and moment n (about the joint point J) that
    each body's parent exerts on it, from tip to base. Newton: f_i − f_{i+1} + m g + F = m a_G.
    Euler about G: n_i − n_{i+1} + (J_i − G) × f_i − (J_{i+1} − G) × f_{i+1} + (H − G) × F + N
    = I_G α + ω × I_G ω (I_G rotated to the global frame)."""
    mass_scale = mass_scale or {}
    out: dict = {}
    f_next, n_next, J_next = np.zeros(3), np.zeros(3), np.zeros(3)
    for body in reversed(BODIES):
        s = state[body]
        m, com, tensor = mass_properties(body)
        m *= mass_scale.get(body, 1.0)
        G, _, aG = point_motion(s, com)
        I_G = s["R"] @ tensor @ s["R"].T
        ext_f, ext_n, arm = np.zeros(3), np.zeros(3), np.zeros(3)
        if body == LOAD_BODY:
            ext_f, ext_n = force, moment
            arm = point_motion(s, local_point(body, LOAD_POINT))[0] - G
        f = m * aG - m * GRAVITY - ext_f + f_next
        n = (I_G @ s["al"] + np.cross(s["w"], I_G @ s["w"]) - np.cross(s["J"] - G, f)
             + n_next + np.cross(J_next - G, f_next) - np.cross(arm, ext_f) - ext_n)
        out[body] = (f, n)
        f_next, n_next, J_next = f, n, s["J"]
    return out


def rne_moments(t: np.ndarray, mass_scale: dict | None = None,
                moment_scale: float = 1.0) -> np.ndarray:
    """Joint moments conjugate to the model's angles (frames × n_angles) by RNE.

    Q_φk = z_k · n_j is the moment about the axis of elementary rotation k that the parent of
    joint j applies on its child (constraint moments of the revolute and universal joints are
    normal to every z of their joint and drop out). Virtual power: Σ Q_φ δφ = Σ τ_θ δθ with
    δθ = (∂θ/∂φ) δφ, so τ_θ = (∂θ/∂φ)⁻ᵀ Q_φ = (∂φ/∂θ)ᵀ Q_φ.

    Sign: n_j is what the actuator has to supply (parent on child) for the motion to happen, and
    τ_θ is its generalized force on θ_k, positive where it pushes θ_k up. The package's
    τ_k = λ_k sin θ_k is the same quantity: the driver s1·s2 − cos θ_k adds −Φ_qᵀ λ to the bodies,
    and a moment τ conjugate to θ = acos(s1·s2) adds τ ∂θ/∂q = −(τ / sin θ) Φ_q; they agree for
    τ = λ sin θ. So the expected relation is τ_pkg = +τ_RNE, no sign flip."""
    phi, phid, phidd = phi_motion(t)
    force, moment = load_history(t)
    out = np.zeros((len(t), len(SPEC["angles"])))
    for f in range(len(t)):
        state = forward(phi[f], phid[f], phidd[f])
        joint = backward(state, force[f], moment_scale * moment[f], mass_scale)
        q_phi = np.array([z @ joint[body][1] for body, *_ in CHAIN for z in state[body]["z"]])
        out[f] = np.linalg.solve(angle_jacobian(phi[f]).T, q_phi)
    return out


def reference(t: np.ndarray) -> dict:
    """Everything the test knows about the motion from its own closed form, frames first."""
    phi, phid, phidd = phi_motion(t)
    force, moment = load_history(t)
    keys = ("theta", "theta_d", "theta_dd", "x", "xd", "kinetic", "potential", "point",
            "ext_power", "cond")
    ref: dict = {k: [] for k in keys}
    for f in range(len(t)):
        state = forward(phi[f], phid[f], phidd[f])
        for key, value in zip(keys[:3], model_angles(state), strict=True):
            ref[key].append(value)
        ref["x"].append(np.concatenate([np.concatenate([state[b]["r"], *state[b]["R"].T])
                                        for b in BODIES]))
        ref["xd"].append(np.concatenate([
            np.concatenate([state[b]["v"], *np.cross(state[b]["w"], state[b]["R"].T)])
            for b in BODIES]))
        kinetic = potential = 0.0
        for b in BODIES:
            m, com, tensor = mass_properties(b)
            G, vG, _ = point_motion(state[b], com)
            w_local = state[b]["R"].T @ state[b]["w"]
            kinetic += 0.5 * m * vG @ vG + 0.5 * w_local @ tensor @ w_local
            potential -= m * GRAVITY @ G
        ref["kinetic"].append(kinetic)
        ref["potential"].append(potential)
        H, vH, _ = point_motion(state[LOAD_BODY], local_point(LOAD_BODY, LOAD_POINT))
        ref["point"].append(H)
        ref["ext_power"].append(force[f] @ vH + moment[f] @ state[LOAD_BODY]["w"])
        ref["cond"].append(np.linalg.cond(angle_jacobian(phi[f])))
    return {k: np.array(v) for k, v in ref.items()}


REF = reference(TIME)
FORCE, MOMENT = load_history(TIME)
LOAD = ExternalLoad(name="push", body=LOAD_BODY, force=FORCE, point=REF["point"], moment=MOMENT)


def derivative(f, t: float, h: float = 1e-3) -> np.ndarray:
    """8th-order central difference of a function of time."""
    return sum(wk * np.asarray(f(t + k * h)) for k, wk in zip(STENCIL, D1_WEIGHTS, strict=True)) / h


def rel_error(actual: np.ndarray, expected: np.ndarray) -> float:
    return float(np.abs(actual - expected).max() / max(1.0, np.abs(expected).max()))


# --- the package under test --------------------------------------------------------------------

@pytest.fixture(scope="module", params=["full", "reduced"])
def package(request):
    """(result of solve_ad, inverse dynamics, layout) for one body form."""
    model = parse_model(MODEL_YAML, "chain.yaml").with_form(request.param)
    system = compile_system(model, angles="driver")
    drives = stacked_drives(system, REF["theta"], REF["theta_d"], REF["theta_dd"], None)
    res = solve_ad(system, TIME, drives, system.layout.pose_q(model), tol=1e-12)
    idr = inverse_dynamics(system, res, [LOAD])
    return res, idr, system.layout


@pytest.fixture(scope="module")
def tau_rne() -> np.ndarray:
    return rne_moments(TIME[BASE])


# --- the independent reference checked on its own ----------------------------------------------

def test_reference_motion_is_well_posed():
    """Joint variables within ±35°, angles away from 0 and π, θ(φ) locally invertible."""
    phi = phi_motion(np.linspace(0, 2.2, 500))[0]
    assert np.degrees(np.abs(phi)).max() < 35
    theta = np.degrees(REF["theta"])
    assert theta.min() > 40 and theta.max() < 140
    assert REF["cond"].max() < 10


def test_forward_pass_matches_differentiated_closed_form():
    """ω, α, a_G, θ̇, θ̈ of the forward pass against 8th-order central differences of R(t),
    ω(t), r_G(t), v_G(t) and θ(t) (truncation ~ (2π f h)⁸, rounding ~ 1e-16 / h)."""
    def at(t):
        return forward(*(x[0] for x in phi_motion([t])))

    worst = 0.0
    for t in (0.13, 0.77, 1.41, 1.96):
        s = at(t)
        for b in BODIES:
            com = mass_properties(b)[1]
            Rd = derivative(lambda tt, b=b: at(tt)[b]["R"], t)
            W = Rd @ s[b]["R"].T
            omega_fd = np.array([W[2, 1], W[0, 2], W[1, 0]])
            checks = [
                (omega_fd, s[b]["w"]),
                (derivative(lambda tt, b=b: at(tt)[b]["w"], t), s[b]["al"]),
                (derivative(lambda tt, b=b, c=com: point_motion(at(tt)[b], c)[0], t),
                 point_motion(s[b], com)[1]),
                (derivative(lambda tt, b=b, c=com: point_motion(at(tt)[b], c)[1], t),
                 point_motion(s[b], com)[2]),
            ]
            worst = max(worst, *(rel_error(a, e) for a, e in checks))
        th = model_angles(s)
        worst = max(worst, rel_error(derivative(lambda tt: model_angles(at(tt))[0], t), th[1]),
                    rel_error(derivative(lambda tt: model_angles(at(tt))[1], t), th[2]))
    assert worst < 1e-9, worst


# --- the package against the reference ---------------------------------------------------------

def test_package_follows_the_closed_form_motion(package):
    """Same configuration and velocities (same assembly branch) at every frame."""
    res, idr, layout = package
    assert res.converged.all()
    x = np.array([layout.expand(q) for q in res.q])
    xd = np.array([layout.expand_rate(q, qd) for q, qd in zip(res.q, res.qd, strict=True)])
    assert rel_error(x, REF["x"]) < 1e-9
    assert rel_error(xd, REF["xd"]) < 1e-9
    assert np.abs(idr.residual).max() < 1e-8


def test_joint_moments_match_newton_euler(package, tau_rne):
    """The done-when: |τ_pkg − τ_RNE| ≤ 1e-6 · max(1, max|τ_RNE|) over 20 frames, 7 angles."""
    _, idr, _ = package
    tau_pkg = idr.joint_moments[BASE]
    assert idr.angle_names == tuple(a["name"] for a in SPEC["angles"])
    assert np.abs(tau_rne).max() > 1.0          # a non-trivial load case
    assert rel_error(tau_pkg, tau_rne) <= TOL_TAU, np.abs(tau_pkg - tau_rne).max(axis=0)


def test_kinetic_and_potential_energy(package):
    """T = Σ ½ m v_G² + ½ ωᵀ I_G ω and V = −Σ m g·r_G from the closed-form motion."""
    _, idr, _ = package
    assert rel_error(idr.kinetic, REF["kinetic"]) < TOL_ENERGY
    assert rel_error(idr.potential, REF["potential"]) < TOL_ENERGY


def test_power_balance(package):
    """Σ τ_k θ̇_k + P_ext = d(T + V)/dt, with the package's T + V differentiated by the 9-point
    stencil around each comparison frame and the package's own τ and external power."""
    _, idr, _ = package
    energy = (idr.kinetic + idr.potential).reshape(len(BASE_TIMES), len(STENCIL))
    de_dt = energy @ D1_WEIGHTS / H_STEP
    assert rel_error(idr.external_power, REF["ext_power"]) < TOL_ENERGY
    supplied = (np.sum(idr.joint_moments * REF["theta_d"], axis=1) + idr.external_power)[BASE]
    assert rel_error(supplied, de_dt) < TOL_POWER


@pytest.mark.parametrize("mistake", [{"mass_scale": {"B2": 1.01}}, {"moment_scale": 0.0}],
                         ids=["b2_mass_plus_1pct", "no_free_moment"])
def test_a_wrong_reference_is_detected(package, mistake):
    """Guard: the comparison can fail. 1 % more mass on B2, or the external free moment left
    out, in the RNE only, must miss the package by far more than the tolerance."""
    _, idr, _ = package
    wrong = rne_moments(TIME[BASE], **mistake)
    assert rel_error(idr.joint_moments[BASE], wrong) > 1e-4

"""Φ_q, ν and γ of every constraint type checked against finite differences.

docs/formulation.md §2: Φ_q q̇ = ν and Φ_q q̈ = γ. For ANY smooth q(t) (consistent with the
constraints or not) and smooth drive data θ*(t), y(t), the function Φ(t) = Φ(q(t), t) satisfies

    dΦ/dt   = Φ_q q̇ − ν
    d²Φ/dt² = Φ_q q̈ − γ(q, q̇)

so Φ_q is checked against central differences of Φ in q, and ν, γ against central differences of
Φ(t) in time along closed-form sinusoidal motions. Every constraint type (rigid body, the six joint
types between two moving bodies and with the ground on either side, AR drivers, MCR coordinates,
TC and TOC tracking) is exercised in fully-defined, reduced and mixed-form models; the models with
cylindrical, prismatic and parallel joints carry distance coordinates too ((r_Q − r_P)·s = d, the
slides no angle can drive), as drivers and as mixed coordinates. The second-order term of Newton's
method, Σ c_i ∇²Φ_i, is checked against central differences of Φ_qᵀc. A consistent motion (the
pendulum's synthesized AD analysis) closes the loop, and mutated outputs prove that the
comparisons can fail.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from fccgrb_cli.model import load_model, parse_model
from fccgrb_cli.pipeline.synth import synthesize
from fccgrb_cli.system import Drive, compile_system

CONFIGS = Path(__file__).resolve().parents[1] / "configs" / "models"

JOINT_TYPES = ("spherical", "revolute", "universal", "cylindrical", "prismatic", "parallel",
               "line")
# Scalar equations per joint (docs/formulation.md §2; cylindrical = 2 axis + 2 offset, prismatic +
# lock, parallel = the 2 axis equations, line = the 2 offset equations).
EXPECTED_ROWS = {"spherical": 3, "revolute": 5, "universal": 4, "cylindrical": 4,
                 "prismatic": 5, "parallel": 2, "line": 2}
WITH_POINTS = {"spherical", "revolute", "universal", "cylindrical", "prismatic", "line"}
WITH_AXES = {"revolute", "universal", "cylindrical", "prismatic", "parallel"}
# Joints that leave a slide: their models add distance coordinates (body–body, ground–body with
# the ground's point and axis, body–ground with the ground's point second).
WITH_DISTANCES = {"cylindrical", "prismatic", "parallel", "line"}
DISTANCES = """\
distances:
  - {name: d12, points: [B1.P, B2.Q], axis: B1.s}
  - {name: d01, points: [ground.O, B1.Q], axis: ground.g}
  - {name: d20, points: [B2.P, ground.O], axis: B2.k}
"""
FORMS = {"full": ("full", "full"), "reduced": ("reduced", "reduced"), "mixed": ("full", "reduced")}
MODES = ("driver", "coordinate")

H_Q = 1e-6       # step of the central differences in q
H_T1 = 1e-6      # step of the first time derivative
H_T2 = 1e-3      # step of the second time derivative (5-point stencil, O(h⁴))
TOL_JAC = 1e-7   # relative tolerances, each error scaled by max(1, |analytic|)
TOL_NU = 1e-7
TOL_GAMMA = 1e-6
TOL_HESSIAN = 1e-7
TOL_CONSISTENT = 1e-8

# Joints: name, bodies, points, axes, lock. Ground appears first (JG1) and second (JG2) so that
# ground features stand on both sides of every equation (body i and body j of the table).
JOINTS = (
    ("J12", ("B1", "B2"), ("P", "P"), ("s", "t"), ("k", "k")),
    ("JG1", ("ground", "B1"), ("O", "P"), ("g", "s"), ("h", "t")),
    ("JG2", ("B2", "ground"), ("Q", "O"), ("k", "g"), ("t", "h")),
)

MODEL_TEMPLATE = """\
name: test_{jtype}
units: {{angle: deg}}
ground:
  points: {{O: [0.1, -0.2, 0.3]}}
  vectors: {{g: [0.36, 0.48, 0.8], h: [0.8, -0.6, 0.0]}}
bodies:
  B1:
    form: {form1}
    points: {{P: [0.3, -0.2, 0.5], Q: [-0.4, 0.1, 0.7]}}
    vectors: {{s: [0.48, 0.6, 0.64], t: [0.0, 0.6, 0.8], k: [0.6, 0.0, -0.8]}}
  B2:
    form: {form2}
    points: {{P: [-0.25, 0.35, -0.6], Q: [0.2, 0.45, -0.3]}}
    vectors: {{s: [0.64, -0.48, 0.6], t: [0.8, 0.0, 0.6], k: [0.0, -0.8, 0.6]}}
joints:
{joints}
angles:
  - {{name: a12, vectors: [B1.s, B2.t]}}
  - {{name: a01, vectors: [ground.g, B1.k]}}
  - {{name: a20, vectors: [B2.k, ground.h]}}
{distances}tracking:
  points:
    - {{marker: M1, point: B1.Q}}
    - {{marker: M2, point: B2.Q}}
  vectors:
    - {{vector: B1.t, from: M1, to: M2}}
    - {{vector: B2.s, from: M2, to: M1}}
"""


def model_text(jtype: str, form: str) -> str:
    """A (not necessarily assemblable) two-body model whose three joints are all of one type."""
    lines = []
    for name, bodies, points, axes, lock in JOINTS:
        parts = [f"name: {name}", f"type: {jtype}", f"bodies: [{', '.join(bodies)}]"]
        if jtype in WITH_POINTS:
            parts.append(f"points: [{', '.join(points)}]")
        if jtype in WITH_AXES:
            parts.append(f"axes: [{', '.join(axes)}]")
        if jtype == "prismatic":
            parts.append(f"lock: [{', '.join(lock)}]")
        if jtype == "line":
            parts.append(f"axis: {axes[0]}")
        lines.append("  - {" + ", ".join(parts) + "}")
    form1, form2 = FORMS[form]
    return MODEL_TEMPLATE.format(jtype=jtype, form1=form1, form2=form2, joints="\n".join(lines),
                                 distances=DISTANCES if jtype in WITH_DISTANCES else "")


def build(jtype: str, form: str, mode: str, track: bool = True):
    return compile_system(parse_model(model_text(jtype, form), "test.yaml"), angles=mode,
                          track=track)


# --- closed-form motions -------------------------------------------------------------------------
Signal = Callable[[float, int], np.ndarray]


def sinusoid(rng: np.random.Generator, shape: tuple[int, ...]) -> Signal:
    """x(t) = a + b sin(ω t + φ) per entry; returns f(t, order) with order 0, 1 or 2."""
    a = rng.uniform(-1.0, 1.0, shape)
    b = rng.uniform(0.2, 1.0, shape)
    w = rng.uniform(0.5, 2.0, shape)
    p = rng.uniform(0.0, 2.0 * np.pi, shape)

    def f(t: float, order: int = 0) -> np.ndarray:
        arg = w * t + p
        if order == 0:
            return a + b * np.sin(arg)
        if order == 1:
            return b * w * np.cos(arg)
        return -b * w**2 * np.sin(arg)

    return f


@dataclass
class Motion:
    """q(t), θ*(t) and y(t) as closed-form sinusoids."""

    q: Signal
    theta: Signal
    ref: Signal

    def drive(self, t: float) -> Drive:
        return Drive(theta=self.theta(t, 0), theta_d=self.theta(t, 1), theta_dd=self.theta(t, 2),
                     ref=self.ref(t, 0), ref_d=self.ref(t, 1), ref_dd=self.ref(t, 2))


def random_motion(system, seed: int) -> Motion:
    rng = np.random.default_rng(seed)
    # θ* stays well inside (0, π) (distances: 1.5 ± 0.5 m); MCR coordinates are plain entries
    # of q(t).
    theta = sinusoid(rng, (len(system.model.angles),))
    return Motion(q=sinusoid(rng, (system.nq,)),
                  theta=lambda t, k=0: (1.5 if k == 0 else 0.0) + 0.5 * theta(t, k),
                  ref=sinusoid(rng, (system.n_targets, 3)))


# --- comparisons ---------------------------------------------------------------------------------
def rel_error(analytic: np.ndarray, numeric: np.ndarray) -> np.ndarray:
    """Entry-wise |analytic − numeric| / max(1, |analytic|)."""
    return np.abs(analytic - numeric) / np.maximum(1.0, np.abs(analytic))


def worst(analytic: np.ndarray, numeric: np.ndarray, labels: tuple[str, ...]) -> tuple[float, str]:
    """The largest relative error and the label of its row."""
    err = rel_error(analytic, numeric)
    if err.size == 0:
        return 0.0, ""
    row = np.unravel_index(int(np.argmax(err)), err.shape)[0]
    return float(err.max()), labels[row]


def fd_jacobian(system, q: np.ndarray, drive: Drive, h: float = H_Q) -> np.ndarray:
    cols = []
    for k in range(len(q)):
        e = np.zeros_like(q)
        e[k] = h
        cols.append((system.residual(q + e, drive) - system.residual(q - e, drive)) / (2 * h))
    return np.column_stack(cols)


def jacobian_error(system, q: np.ndarray, drive: Drive) -> tuple[float, str]:
    return worst(system.jacobian(q), fd_jacobian(system, q, drive), system.labels)


def phi_t(system, motion: Motion, t: float) -> np.ndarray:
    return system.residual(motion.q(t, 0), motion.drive(t))


def rate_errors(system, motion: Motion, t: float) -> tuple[tuple[float, str], tuple[float, str]]:
    """Errors of dΦ/dt = Φ_q q̇ − ν and d²Φ/dt² = Φ_q q̈ − γ against central differences in t."""
    q, qd, qdd, drive = motion.q(t, 0), motion.q(t, 1), motion.q(t, 2), motion.drive(t)
    J = system.jacobian(q)
    first = J @ qd - system.nu(q, drive)
    second = J @ qdd - system.gamma(q, qd, drive)
    d1 = (phi_t(system, motion, t + H_T1) - phi_t(system, motion, t - H_T1)) / (2 * H_T1)
    # 5-point stencil: with the 3-point one, rounding (~eps |Φ| / h²) and truncation (~h² Φ⁗)
    # cannot both stay below 1e-7; this one reaches ~1e-8 at h = 1e-3.
    p2, p1, p0, m1, m2 = (phi_t(system, motion, t + k * H_T2) for k in (2, 1, 0, -1, -2))
    d2 = (-p2 + 16 * p1 - 30 * p0 + 16 * m1 - m2) / (12 * H_T2**2)
    return worst(first, d1, system.labels), worst(second, d2, system.labels)


CASES = [(j, f, m) for j in JOINT_TYPES for f in FORMS for m in MODES]
CASE_IDS = [f"{j}-{f}-{m}" for j, f, m in CASES]
TIMES = (0.0, 0.7, 2.3)


# --- 3. every constraint type is present ---------------------------------------------------------
@pytest.mark.parametrize(("jtype", "form", "mode"), CASES, ids=CASE_IDS)
def test_every_constraint_type_has_rows(jtype: str, form: str, mode: str) -> None:
    system = build(jtype, form, mode)
    labels = system.labels
    for name, _, _, _, _ in JOINTS:
        rows = [lab for lab in labels if lab.startswith(f"joint {name} ({jtype})")]
        assert len(rows) == EXPECTED_ROWS[jtype], (name, rows)
    form1, form2 = FORMS[form]
    for body, bform in (("B1", form1), ("B2", form2)):
        rows = [lab for lab in labels if lab.startswith(f"rigid body {body}:")]
        assert len(rows) == (6 if bform == "full" else 3), rows
    tag = "AR" if mode == "driver" else "MCR"
    for angle in ("a12", "a01", "a20"):
        assert labels.count(f"angle {angle} ({tag})") == 1
    n_distances = 3 if jtype in WITH_DISTANCES else 0
    assert [lab for lab in labels if lab.startswith("distance ")] == [
        f"distance {d} ({tag})" for d in ("d12", "d01", "d20")][:n_distances]
    assert system.distance_rows.tolist() == [False] * 3 + [True] * n_distances
    for target in ("M1", "M2", "M1->M2", "M2->M1"):
        assert [lab for lab in labels if lab.startswith(f"track {target}:")] == [
            f"track {target}: {ax}" for ax in "xyz"]
    assert system.n_targets == 4
    n_body = sum(12 if f == "full" else 9 for f in (form1, form2))
    assert system.layout.n_body_q == n_body
    assert system.nq == n_body + (3 + n_distances if mode == "coordinate" else 0)
    assert system.jacobian(np.zeros(system.nq)).shape == (len(labels), system.nq)
    # Without tracking only the TC/TOC rows disappear.
    plain = build(jtype, form, mode, track=False)
    assert plain.labels == tuple(lab for lab in labels if not lab.startswith("track "))


# --- 1. Φ_q against central differences ----------------------------------------------------------
@pytest.mark.parametrize(("jtype", "form", "mode"), CASES, ids=CASE_IDS)
def test_jacobian_matches_finite_differences(jtype: str, form: str, mode: str) -> None:
    system = build(jtype, form, mode)
    rng = np.random.default_rng(CASES.index((jtype, form, mode)))
    motion = random_motion(system, seed=1000 + CASES.index((jtype, form, mode)))
    for _ in range(2):
        q = rng.uniform(-1.5, 1.5, system.nq)
        drive = motion.drive(float(rng.uniform(0, 3)))
        J = system.jacobian(q)
        # Every row depends on q here, so no row is checked vacuously.
        assert np.all(np.abs(J).max(axis=1) > 1e-3), "a row of Φ_q vanishes at a random q"
        err, label = jacobian_error(system, q, drive)
        assert err < TOL_JAC, f"Φ_q wrong in row {label!r}: relative error {err:.2e}"
        phi, J2 = system.evaluate(q, drive)
        np.testing.assert_array_equal(phi, system.residual(q, drive))
        np.testing.assert_array_equal(J2, J)


# --- 2. ν and γ against derivatives in time ------------------------------------------------------
@pytest.mark.parametrize(("jtype", "form", "mode"), CASES, ids=CASE_IDS)
def test_nu_gamma_match_time_derivatives(jtype: str, form: str, mode: str) -> None:
    system = build(jtype, form, mode)
    motion = random_motion(system, seed=CASES.index((jtype, form, mode)))
    for t in TIMES:
        (e1, l1), (e2, l2) = rate_errors(system, motion, t)
        assert e1 < TOL_NU, f"ν wrong in row {l1!r} at t={t}: relative error {e1:.2e}"
        assert e2 < TOL_GAMMA, f"γ wrong in row {l2!r} at t={t}: relative error {e2:.2e}"


# --- 2a. the Hessian term of Newton's method on ½ΦᵀWΦ ---------------------------------------------
def fd_hessian(system, q: np.ndarray, c: np.ndarray, h: float = H_Q) -> np.ndarray:
    """Σ c_i ∇²Φ_i by central differences of Φ_q(q)ᵀ c."""
    cols = []
    for k in range(len(q)):
        e = np.zeros_like(q)
        e[k] = h
        cols.append((system.jacobian(q + e).T @ c - system.jacobian(q - e).T @ c) / (2 * h))
    return np.column_stack(cols)


@pytest.mark.parametrize(("jtype", "form", "mode"), CASES, ids=CASE_IDS)
def test_residual_hessian_matches_finite_differences(jtype: str, form: str, mode: str) -> None:
    system = build(jtype, form, mode)
    rng = np.random.default_rng(500 + CASES.index((jtype, form, mode)))
    q = rng.uniform(-1.5, 1.5, system.nq)
    c = rng.uniform(-1.0, 1.0, system.n_rows)
    H = system.residual_hessian(q, c)
    numeric = fd_hessian(system, q, c)
    err = rel_error(H, numeric)
    assert err.max() < TOL_HESSIAN, f"Hessian wrong at {np.unravel_index(err.argmax(), H.shape)}"
    # Coordinate rows alone: an angle's c cos θ curvature on the diagonal (none for a distance)
    # and its mixed derivatives with the body coordinates.
    only = np.zeros(system.n_rows)
    only[system.n_linear_rows + system.angle_rows] = c[system.n_linear_rows + system.angle_rows]
    assert rel_error(system.residual_hessian(q, only), fd_hessian(system, q, only)).max() \
        < TOL_HESSIAN


# --- 2b. a consistent motion: the pendulum's synthesized AD analysis -----------------------------
def frame_rates(q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, block: slice,
                point: tuple[float, ...]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Position, velocity, acceleration of a body point from r, u, v and their rates (w = u × v
    differentiated by hand, independently of the package's expansion)."""
    (r, u, v), (rd, ud, vd), (rdd, udd, vdd) = (x[block][:9].reshape(3, 3) for x in (q, qd, qdd))
    w = np.cross(u, v)
    wd = np.cross(ud, v) + np.cross(u, vd)
    wdd = np.cross(udd, v) + 2 * np.cross(ud, vd) + np.cross(u, vdd)
    a, b, c = point
    return (r + a * u + b * v + c * w, rd + a * ud + b * vd + c * wd,
            rdd + a * udd + b * vdd + c * wdd)


@pytest.fixture(scope="module", params=["full", "reduced"])
def pendulum(request):
    model = load_model(CONFIGS / "pendulum.yaml").with_form(request.param)
    return model, synthesize(model, duration=0.5, rate=400.0)


def test_consistent_motion_ad(pendulum) -> None:
    _, synth = pendulum
    system, res = synth.system, synth.result
    for f in range(0, res.n_frames, 7):
        drive = Drive(res.theta[f], res.theta_d[f], res.theta_dd[f])
        q, qd, qdd = res.q[f], res.qd[f], res.qdd[f]
        J = system.jacobian(q)
        assert np.abs(system.residual(q, drive)).max() < TOL_CONSISTENT
        assert rel_error(J @ qd, system.nu(q, drive)).max() < TOL_CONSISTENT
        assert rel_error(J @ qdd, system.gamma(q, qd, drive)).max() < TOL_CONSISTENT
    # The solved rates really are the time derivatives of the solved positions (5-point stencil):
    # this ties the sign conventions of ν and γ to the motion, not only to the linear solves.
    dt = res.time[1] - res.time[0]

    def stencil(x: np.ndarray) -> np.ndarray:
        return (x[:-4] - 8 * x[1:-3] + 8 * x[3:-1] - x[4:]) / (12 * dt)

    assert rel_error(res.qd[2:-2], stencil(res.q)).max() < 1e-5
    assert rel_error(res.qdd[2:-2], stencil(res.qd)).max() < 1e-5
    np.testing.assert_allclose(system.angles_at(res.q[0]), res.theta[0], atol=1e-8)


def test_consistent_motion_mcr_and_tracking(pendulum) -> None:
    """The same motion seen by the MC system: θ as coordinates, markers as TC targets."""
    model, synth = pendulum
    res = synth.result
    system = compile_system(model, angles="coordinate", track=True)
    assert any("(MCR)" in lab for lab in system.labels)
    assert any(lab.startswith("track ") for lab in system.labels)
    layout = synth.system.layout
    for f in range(0, res.n_frames, 11):
        refs = [frame_rates(res.q[f], res.qd[f], res.qdd[f], layout.q_slice(tp.body),
                            model.body(tp.body).points[tp.point].local)
                for tp in model.tracked_points]
        ref, ref_d, ref_dd = (np.array([r[k] for r in refs]) for k in range(3))
        drive = Drive(ref=ref, ref_d=ref_d, ref_dd=ref_dd)
        q = np.concatenate([res.q[f], res.theta[f]])
        qd = np.concatenate([res.qd[f], res.theta_d[f]])
        qdd = np.concatenate([res.qdd[f], res.theta_dd[f]])
        J = system.jacobian(q)
        assert np.abs(system.residual(q, drive)).max() < TOL_CONSISTENT
        assert rel_error(J @ qd, system.nu(q, drive)).max() < TOL_CONSISTENT
        assert rel_error(J @ qdd, system.gamma(q, qd, drive)).max() < TOL_CONSISTENT


# --- 4. the comparisons can fail -----------------------------------------------------------------
class Mutant:
    """A compiled system with one output tampered with."""

    def __init__(self, system, **overrides: Callable):
        self._system = system
        self._overrides = overrides

    def __getattr__(self, name: str):
        if name in self._overrides:
            return self._overrides[name]
        return getattr(self._system, name)


@pytest.mark.parametrize("form", ["full", "reduced"])
def test_comparisons_flag_wrong_derivatives(form: str) -> None:
    system = build("revolute", form, "driver")
    motion = random_motion(system, seed=7)
    t = 0.7
    q, drive = motion.q(t, 0), motion.drive(t)
    labels = system.labels
    assert jacobian_error(system, q, drive)[0] < TOL_JAC
    (e1, _), (e2, _) = rate_errors(system, motion, t)
    assert e1 < TOL_NU and e2 < TOL_GAMMA

    # One Jacobian entry off by 1e-4.
    row, col = labels.index("joint J12 (revolute): axis ⟂ a"), system.layout.n_body_q - 1

    def bad_jacobian(qq: np.ndarray) -> np.ndarray:
        J = system.jacobian(qq).copy()
        J[row, col] += 1e-4
        return J

    err, label = jacobian_error(Mutant(system, jacobian=bad_jacobian), q, drive)
    assert err > 1e-5 and label == labels[row]

    # The AR driver's ν with the wrong sign.
    ar = labels.index("angle a12 (AR)")

    def bad_nu(qq: np.ndarray, dd: Drive) -> np.ndarray:
        nu = system.nu(qq, dd).copy()
        nu[ar] = -nu[ar]
        return nu

    (e1, l1), _ = rate_errors(Mutant(system, nu=bad_nu), motion, t)
    assert e1 > 1e-3 and l1 == labels[ar]

    # γ missing the θ̈* sin θ* term of the AR driver, then missing 2 ṡ1·ṡ2 of a rigid-body row.
    def bad_gamma_ar(qq: np.ndarray, qd: np.ndarray, dd: Drive) -> np.ndarray:
        gamma = system.gamma(qq, qd, dd).copy()
        gamma[ar] += dd.theta_dd[0] * np.sin(dd.theta[0])
        return gamma

    _, (e2, l2) = rate_errors(Mutant(system, gamma=bad_gamma_ar), motion, t)
    assert e2 > 1e-3 and l2 == labels[ar]

    uv = labels.index("rigid body B2: u·v")

    def bad_gamma_rb(qq: np.ndarray, qd: np.ndarray, dd: Drive) -> np.ndarray:
        gamma = system.gamma(qq, qd, dd).copy()
        block = qd[system.layout.q_slice("B2")]
        gamma[uv] += 2 * block[3:6] @ block[6:9]
        return gamma

    _, (e2, l2) = rate_errors(Mutant(system, gamma=bad_gamma_rb), motion, t)
    assert e2 > 1e-3 and l2 == labels[uv]


@pytest.mark.parametrize("form", ["full", "reduced"])
def test_comparisons_flag_wrong_distance_terms(form: str) -> None:
    """The distance rows' own terms: ν = ḋ* (AR), γ's d̈* (AR), Φ_d = −1 (MCR)."""
    system = build("prismatic", form, "driver")
    motion = random_motion(system, seed=11)
    t = 0.7
    labels = system.labels
    (e1, _), (e2, _) = rate_errors(system, motion, t)
    assert e1 < TOL_NU and e2 < TOL_GAMMA
    row = labels.index("distance d01 (AR)")
    k = list(system.angle_rows).index(row - system.n_linear_rows)

    def bad_nu(qq: np.ndarray, dd: Drive) -> np.ndarray:
        nu = system.nu(qq, dd).copy()
        nu[row] = -nu[row]
        return nu

    (e1, l1), _ = rate_errors(Mutant(system, nu=bad_nu), motion, t)
    assert e1 > 1e-3 and l1 == labels[row]

    def bad_gamma(qq: np.ndarray, qd: np.ndarray, dd: Drive) -> np.ndarray:
        gamma = system.gamma(qq, qd, dd).copy()
        gamma[row] -= dd.theta_dd[k]
        return gamma

    _, (e2, l2) = rate_errors(Mutant(system, gamma=bad_gamma), motion, t)
    assert e2 > 1e-3 and l2 == labels[row]

    mixed = build("prismatic", form, "coordinate")
    q = random_motion(mixed, seed=12).q(t, 0)
    drive = random_motion(mixed, seed=12).drive(t)
    assert jacobian_error(mixed, q, drive)[0] < TOL_JAC
    mrow = mixed.labels.index("distance d20 (MCR)")
    column = mixed.layout.n_body_q + 5  # a12 a01 a20 d12 d01 d20
    assert mixed.jacobian(q)[mrow, column] == -1.0

    def bad_jacobian(qq: np.ndarray) -> np.ndarray:
        J = mixed.jacobian(qq).copy()
        J[mrow, column] = 1.0
        return J

    err, label = jacobian_error(Mutant(mixed, jacobian=bad_jacobian), q, drive)
    assert err > 1.0 and label == mixed.labels[mrow]

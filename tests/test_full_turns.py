"""Signed, full-rotation joint angles (docs/signed_angles.md): the sine rows' derivatives against
central differences, three sample mechanisms through three crank turns by every method, the
input torque by power balance (energies from the test's own rigid-body formulas) and, for the
planar crank-rocker, against the test's own closed-form position analysis."""

from __future__ import annotations

from functools import cache
from pathlib import Path

import numpy as np
import pytest

import fccgrb_cli as fc
from fccgrb_cli.dynamics.convert import classical_dynamics
from fccgrb_cli.dynamics.loads import ExternalLoad
from fccgrb_cli.model import load_model
from fccgrb_cli.pipeline.synth import synthesize
from fccgrb_cli.system import Drive, compile_system
from fccgrb_cli.trial.record import Trial

ROOT = Path(__file__).resolve().parents[1]
MECHANISMS = ("crank_rocker", "slider_crank", "rssr")
METHODS = ("ad", "nrm-ls", "nrm-wls", "cno-sqp", "cno-ip", "mo-tc", "mo-ed")


@cache
def model(name: str):
    return load_model(ROOT / "configs" / "models" / f"{name}.yaml")


@cache
def truth(name: str):
    return synthesize(model(name), duration=3.0, rate=100.0, tol=1e-12)


def exact_trial(name: str) -> Trial:
    """The synthesized markers in double precision (a C3D would round them to 32 bits)."""
    s = truth(name)
    return Trial(f"<{name}>", s.labels, s.markers, 100.0)


# --- the relation's derivatives ----------------------------------------------------------

@pytest.mark.parametrize("form", ["full", "reduced"])
@pytest.mark.parametrize("name", ["crank_rocker", "rssr"])
@pytest.mark.parametrize("mode", ["coordinate", "driver"])
def test_sine_rows_derivatives_match_central_differences(name: str, form: str, mode: str):
    """Φ_q, ν, γ and the Hessian term at a configuration off the constraints, angles in every
    quadrant (the axis is a ground vector in these models: the sine row's second vector is a
    derived body vector t = n × s1)."""
    system = compile_system(model(name).with_form(form), angles=mode, track=mode == "coordinate")
    rng = np.random.default_rng(3)
    nb = system.layout.n_body_q
    q0 = system.layout.pose_q(system.model) + 0.05 * rng.standard_normal(system.nq)
    rows = system.n_linear_rows + system.sine_rows
    assert len(rows) == 1
    for theta in np.radians([10.0, 100.0, 190.0, 280.0, 725.0]):
        q = q0.copy()
        if mode == "coordinate":
            q[nb:] = theta
        qd, qdd = rng.standard_normal(system.nq), rng.standard_normal(system.nq)
        th = np.array([theta, 1.7, -2.3])  # θ*, θ̇*, θ̈*

        def phi(t: float, q=q, qd=qd, qdd=qdd, th=th) -> np.ndarray:
            qt = q + t * qd + 0.5 * t * t * qdd
            drive = Drive(np.array([th[0] + th[1] * t + 0.5 * th[2] * t * t]),
                          ref=np.zeros((system.n_targets, 3)))
            return system.residual(qt, drive)

        drive = Drive(np.array([th[0]]), np.array([th[1]]), np.array([th[2]]),
                      ref=np.zeros((system.n_targets, 3)), ref_d=np.zeros((system.n_targets, 3)),
                      ref_dd=np.zeros((system.n_targets, 3)))
        h = 1e-5
        J = system.jacobian(q)
        Jn = np.column_stack([(system.residual(q + h * e, drive)
                               - system.residual(q - h * e, drive)) / (2 * h)
                              for e in np.eye(system.nq)])
        np.testing.assert_allclose(J[rows], Jn[rows], atol=1e-8)
        first = (phi(h) - phi(-h)) / (2 * h)
        second = (phi(h) - 2 * phi(0.0) + phi(-h)) / h**2
        nu, gamma = system.nu(q, drive), system.gamma(q, qd, drive)
        # Φ̇ = Φ_q q̇ − ν and Φ̈ = Φ_q q̈ − γ along the path (ν = −Φ_t)
        np.testing.assert_allclose((J @ qd - nu)[rows], first[rows], atol=1e-7)
        np.testing.assert_allclose((J @ qdd - gamma)[rows], second[rows], atol=2e-4)
        c = np.zeros(system.n_rows)
        c[rows] = 1.3
        H = system.residual_hessian(q, c) if mode == "coordinate" else None
        if H is not None:
            Hn = np.column_stack([(system.jacobian(q + h * e).T @ c - system.jacobian(q - h * e).T
                                   @ c) / (2 * h) for e in np.eye(system.nq)])
            np.testing.assert_allclose(H, Hn, atol=1e-7)


def test_the_angle_is_signed_by_its_axis_and_keeps_counting():
    """atan2 of the pair at a configuration built in the test: the crank turned by −120° about
    ground z reads −120°, not +120° as arccos(s1·s2) would; synth's θ passes 1000°."""
    system = compile_system(model("crank_rocker"), angles="coordinate", track=True)
    q = system.layout.pose_q(system.model)
    sl = system.layout.q_slice("crank")
    c, s = np.cos(np.radians(-120)), np.sin(np.radians(-120))
    q[sl][3:6], q[sl][6:9] = [c, s, 0], [-s, c, 0]
    assert np.degrees(system.angles_at(q)[0]) == pytest.approx(-120.0)
    assert np.degrees(truth("crank_rocker").result.theta[-1, 0]) > 1000.0


# --- every method through three turns ------------------------------------------------------

@pytest.mark.parametrize("name", MECHANISMS)
def test_frames_land_on_the_quadrants_of_every_turn(name: str):
    theta = np.degrees(truth(name).result.theta[:, 0])
    for target in (0.0, 90.0, 180.0, 270.0, 360.0, 450.0, 540.0, 630.0, 720.0, 990.0):
        assert np.min(np.abs(theta - target)) < 1e-9, target
    assert theta[-1] - theta[0] > 3 * 360.0 - 10.0


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("name", MECHANISMS)
def test_every_method_recovers_the_crank_through_three_turns(name: str, method: str):
    """At P0 (the markers exact): the crank angle to 1e-6° on every frame, none failed or
    flagged, and the solved system's Jacobian keeps its smallest singular value away from zero
    at 0°, 90°, 180° and 270° alike. The optimizers run at ``--tol 1e-14``: they stop on the
    objective's change, which at the default 1e-10 leaves a few 1e-6° (the paper's tolerance,
    not the formulation's limit); Newton's methods at 1e-12 on the step."""
    extra = {"ad_drivers": "markers"} if method == "ad" else {}
    tol = 1e-12 if method in ("ad", "nrm-ls", "nrm-wls") else 1e-14
    run = fc.solve(model(name), exact_trial(name), method=method, dynamics=False,
                   events="none", tol=tol, **extra)
    error = np.degrees(np.abs(run.result.theta[:, 0] - truth(name).result.theta[:, 0]))
    assert error.max() <= 1e-6, (name, method, error.max())
    assert run.trusted.all()
    if method != "ad":
        system = compile_system(model(name), angles="coordinate", track=True)
        smallest = min(np.linalg.svd(system.jacobian(q), compute_uv=False)[-1]
                       for q in run.result.q[::5])
        assert smallest > 1e-2, smallest


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("name", MECHANISMS)
def test_at_p10_no_frame_fails_or_changes_branch(name: str, method: str):
    """10 mm of soft-tissue artefact: no failed frame, and every model point stays within
    30 mm of its true position (a frame on the other assembly branch of a four-bar or an RSSR
    puts the coupler and rocker tens of centimetres away)."""
    extra = {"ad_drivers": "markers"} if method == "ad" else {}
    run = fc.solve(model(name), exact_trial(name), method=method, perturb_mm=10,
                   dynamics=False, events="none", **extra)
    assert run.result.converged.all()
    off = np.linalg.norm(run.model_points - truth(name).markers, axis=2)
    assert off.max() < 0.03, off.max()


# --- inverse dynamics through the turn ------------------------------------------------------

def _rigid_energy_rate(model_, result) -> tuple[np.ndarray, np.ndarray]:
    """dT/dt and dV/dt of every frame from the test's own rigid-body formulas: each body's
    frame R = [u v w], ω̃ = Ṙ Rᵀ, α from Ṙ and R̈, the centre of mass's velocity and
    acceleration; dT/dt = Σ m v_G·a_G + ω·I_g α (I_g = R I Rᵀ, ω·(ω × I_g ω) = 0),
    dV/dt = −Σ m g·v_G."""
    system = compile_system(model_, angles="driver")
    layout = system.layout
    g = np.array(model_.gravity, dtype=float)
    dT, dV = np.zeros(len(result.q)), np.zeros(len(result.q))
    for f, (q, qd, qdd) in enumerate(zip(result.q, result.qd, result.qdd, strict=True)):
        x = layout.expand(q)
        xd = layout.expand_rate(q, qd)
        xq = layout.expand_jacobian(q)
        xdd = (qdd if xq is None else xq @ qdd) + layout.expand_bias(qd)
        for body in model_.bodies:
            k = layout.x_offset(body.name)
            R = x[k + 3:k + 12].reshape(3, 3).T
            rd, Rd = xd[k:k + 3], xd[k + 3:k + 12].reshape(3, 3).T
            rdd, Rdd = xdd[k:k + 3], xdd[k + 3:k + 12].reshape(3, 3).T
            com = np.asarray(body.inertia.com, dtype=float)
            vG, aG = rd + Rd @ com, rdd + Rdd @ com
            W = Rd @ R.T
            omega = np.array([W[2, 1], W[0, 2], W[1, 0]])
            A = Rdd @ R.T + Rd @ Rd.T  # d/dt (Ṙ Rᵀ)
            alpha = np.array([A[2, 1], A[0, 2], A[1, 0]])
            inertia = R @ np.asarray(body.inertia.tensor, dtype=float) @ R.T
            mass = body.inertia.mass
            dT[f] += mass * vG @ aG + omega @ inertia @ alpha
            dV[f] += -mass * g @ vG
    return dT, dV


def _slider_load(result, name: str) -> list[ExternalLoad]:
    """A known load: 40 N against the slider's travel (slider-crank only), at its pin."""
    if name != "slider_crank":
        return []
    system = compile_system(model(name), angles="driver")
    pin = np.array([system.point_positions(q, [("slider", "P")])[0] for q in result.q])
    n = len(result.q)
    return [ExternalLoad("push", "slider", np.tile([-40.0, 0.0, 0.0], (n, 1)), pin,
                         np.zeros((n, 3)))]


@pytest.mark.parametrize("name", MECHANISMS)
def test_input_torque_balances_power_at_every_frame(name: str):
    """τ θ̇ + P_load = dT/dt + dV/dt to 1e-6 of the largest term, every frame, 0° and 180°
    included, on the motion the inverse dynamics drives (θ from the synthesized crank, θ̇ and θ̈
    by central differences, q̇ and q̈ consistent with them)."""
    loads = _slider_load(truth(name).result, name)
    dynamics = classical_dynamics(model(name), truth(name).result, loads=loads, tol=1e-12)
    result = dynamics.kinematics  # the motion the moments are built on (θ̇, θ̈ differenced)
    tau = dynamics.inverse.joint_moments[:, 0]
    dT, dV = _rigid_energy_rate(model(name), result)
    input_power = tau * result.theta_d[:, 0] + dynamics.inverse.external_power
    scale = np.abs(dT + dV).max()
    np.testing.assert_allclose(input_power, dT + dV, atol=1e-6 * scale)
    if loads:  # the load's power computed here: F·v of the pin, the slider's origin
        system = compile_system(model(name), angles="driver")
        velocity = result.qd[:, system.layout.q_slice("slider")][:, :3]
        np.testing.assert_allclose(dynamics.inverse.external_power,
                                   (loads[0].force * velocity).sum(axis=1), atol=1e-9)
        assert np.abs(dynamics.inverse.external_power).max() > 10.0


def _four_bar(theta: complex) -> dict[str, tuple]:
    """The crank-rocker's joints in the plane by the test's closed-form position analysis
    (complex θ allowed, for complex-step derivatives): A on the crank circle, B the upper
    intersection of the coupler's circle about A and the rocker's about D (the pose's branch)."""
    a, b, c, d = 0.10, 0.35, 0.30, 0.40
    Ax, Ay = a * np.cos(theta), a * np.sin(theta)
    ex, ey = d - Ax, -Ay
    L = np.sqrt(ex * ex + ey * ey)
    along = (b * b - c * c + L * L) / (2 * L)
    up = np.sqrt(b * b - along * along)
    Bx, By = Ax + along * ex / L - up * ey / L, Ay + along * ey / L + up * ex / L
    zero = 0.0 * theta
    return {"crank": ((zero, zero), (Ax, Ay), 0.05 / a),
            "coupler": ((Ax, Ay), (Bx, By), 0.175 / b),
            "rocker": ((d + zero, zero), (Bx, By), 0.15 / c)}


def _planar_torque(theta: float, theta_d: float, theta_dd: float) -> float:
    """τ from virtual power, τ θ̇ = Σ m v_G·(a_G − g) + I ω α, with the closed-form positions:
    first derivatives in θ by complex step, second by central differences of those; each
    link's ω and α from its end points (d = e₁ − e₀ of fixed length: ω = d × ḋ / |d|²,
    α = d × d̈ / |d|²). Masses, centres of mass and I_zz as in crank_rocker.yaml."""
    links = {"crank": (0.8, 0.0009), "coupler": (1.6, 0.0168), "rocker": (1.2, 0.0093)}

    def points(th: complex) -> dict[str, np.ndarray]:
        out = {}
        for body, ((x0, y0), (x1, y1), f) in _four_bar(th).items():
            out[body] = np.array([x0, y0, x1, y1, x0 + f * (x1 - x0), y0 + f * (y1 - y0)])
        return out

    def slope(th: float) -> dict[str, np.ndarray]:
        h = 1e-20
        return {k: v.imag / h for k, v in points(th + 1j * h).items()}

    here = {k: v.real for k, v in points(theta).items()}
    first = slope(theta)
    step = 1e-5
    up, down = slope(theta + step), slope(theta - step)
    power = 0.0
    for body, (mass, inertia) in links.items():
        p1, p2 = first[body], (up[body] - down[body]) / (2 * step)
        rate = p1 * theta_d
        accel = p2 * theta_d**2 + p1 * theta_dd
        d = here[body][2:4] - here[body][0:2]
        dd, ddd = rate[2:4] - rate[0:2], accel[2:4] - accel[0:2]
        omega = (d[0] * dd[1] - d[1] * dd[0]) / (d @ d)
        alpha = (d[0] * ddd[1] - d[1] * ddd[0]) / (d @ d)
        vG, aG = rate[4:6], accel[4:6]
        power += mass * vG @ (aG + np.array([0.0, 9.81])) + inertia * omega * alpha
    return power / theta_d


def test_crank_rocker_torque_equals_a_closed_form_analysis():
    dynamics = classical_dynamics(model("crank_rocker"), truth("crank_rocker").result, tol=1e-12)
    result, tau = dynamics.kinematics, dynamics.inverse.joint_moments[:, 0]
    expected = np.array([_planar_torque(th, thd, thdd) for th, thd, thdd in
                         zip(result.theta[:, 0], result.theta_d[:, 0], result.theta_dd[:, 0],
                             strict=True)])
    np.testing.assert_allclose(tau, expected, atol=1e-6 * np.abs(expected).max())
    assert np.abs(expected).max() > 1.0  # a torque worth checking

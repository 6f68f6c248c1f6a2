"""Floating bases: the five-bar with its ground joint removed, so that B1 floats (6 degrees of
freedom determined by its markers in MC, by base drivers in the classical model), and B1 given a
prescribed motion (``bodies.B1.motion``): it translates and rotates with non-zero acceleration.

Independent checks, every rate differenced from positions alone (5-point stencils at 1 kHz), so
that a wrong acceleration anywhere in the package cannot cancel out:
* the base motion's exact derivatives (r*, u*, v*, w* and their rates) against central
  differences, and the synthesized q̇, q̈ against the synthesized q;
* the base drivers' residual force against Newton's second law for the whole system,
  Σ m_i (a_Gi − g);
* their moment, reported about the moving base origin B, moved to the fixed ground origin O
  (M_O = M_B + r_B × F) against dH_O/dt − Σ r_Gi × m_i g, H_O = Σ (r_Gi × m_i v_Gi + I_i ω_i);
* the mixed-coordinate q̇, q̈ (where the topology leaves the base's rates to the markers)
  against the synthesized motion.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from fccgrb_cli.cli.main import main
from fccgrb_cli.dynamics.convert import classical_dynamics
from fccgrb_cli.model import BaseMotion, Motion, parse_model
from fccgrb_cli.pipeline.synth import synthesize
from fccgrb_cli.solvers.nrm.solve import NrmSettings, solve_nrm
from fccgrb_cli.system import compile_system
from fccgrb_cli.system.constraints import floating_bases
from fccgrb_cli.system.structure import analyse

ROOT = Path(__file__).resolve().parents[1]
FIVE_BAR = (ROOT / "configs" / "models" / "five_bar.yaml").read_text()


def floating_text() -> str:
    text = FIVE_BAR.replace(
        "  - {name: J1, type: revolute, bodies: [ground, B1], points: [O, P1], axes: [z, w]}\n",
        "")
    text = text.replace("""  - {name: J1_z, vectors: [ground.x, B1.v],
     motion: {mean: 90, terms: [{amplitude: 30, frequency: 0.4}]}}
""", "")
    text = text.replace("points: {P1: [-0.15, 0, 0], P2: [0.15, 0, 0]}",
                        "points: {P1: [-0.15, 0, 0], P2: [0.15, 0, 0], P0: [0, 0.08, 0]}")
    text = text.replace("    - {marker: P1, point: B1.P1}\n",
                        "    - {marker: P1, point: B1.P1}\n    - {marker: P0, point: B1.P0}\n")
    assert "J1" not in text.split("joints:")[1].split("angles:")[0]
    return text


# B1 translates along all three axes and turns about all three (deg), x first.
BASE_MOTION = """\
    motion:
      translation: [{mean: 0, terms: [{amplitude: 0.3, frequency: 0.5}]},
                    {mean: 0.1, terms: [{amplitude: 0.1, frequency: 0.8, phase: 60}]},
                    {mean: 0, terms: [{amplitude: 0.15, frequency: 0.7, phase: 20}]}]
      rotation: [{mean: 10, terms: [{amplitude: 25, frequency: 0.6}]},
                 {mean: -5, terms: [{amplitude: 15, frequency: 0.9, phase: 45}]},
                 {mean: 20, terms: [{amplitude: 30, frequency: 0.4, phase: 100}]}]
"""


def moving_text() -> str:
    """The floating five-bar with B1 moving (its pose line followed by the motion)."""
    pose = "    pose: {r: [0.15, 0, 0], u: [1, 0, 0], v: [0, 1, 0], w: [0, 0, 1]}\n"
    text = floating_text()
    assert text.count(pose) == 1
    return text.replace(pose, pose + BASE_MOTION)


def test_floating_bases_are_found_and_counted() -> None:
    model = parse_model(floating_text(), "floating.yaml")
    assert floating_bases(model) == ("B1",)
    report = analyse(model)
    assert report.dof == 8 + 6 and report.floating == ("B1",)
    assert report.ad_rank == report.nq


def test_too_few_angles_for_a_floating_model_says_so(tmp_path: Path) -> None:
    text = floating_text().replace("""  - {name: J2_w, vectors: [B1.u, B2.v],
     motion: {mean: 95, terms: [{amplitude: 25, frequency: 0.5, phase: 45}]}}
""", "")
    path = tmp_path / "floating.yaml"
    path.write_text(text)
    result = CliRunner().invoke(main, ["check", str(path)])
    assert result.exit_code == 2
    assert "expected 8 angular coordinates" in result.stderr
    assert "floating base (B1)" in result.stderr


def test_base_motion_derivatives_match_central_differences() -> None:
    """r, u, v, w of BaseMotion.frames and their first and second derivatives (product rule on
    Rz Ry Rx) against 5-point central differences; the frame stays orthonormal."""
    rng = np.random.default_rng(3)

    def random_motion() -> Motion:
        return Motion(float(rng.uniform(-1, 1)), tuple(
            (float(rng.uniform(0.2, 0.8)), float(rng.uniform(0.3, 1.5)),
             float(rng.uniform(0, 6))) for _ in range(2)))

    motion = BaseMotion(tuple(random_motion() for _ in range(3)),
                        tuple(random_motion() for _ in range(3)))
    c, s = np.cos(0.7), np.sin(0.7)
    pose = np.array([[0.1, -0.2, 0.3], [c, s, 0], [-s, c, 0], [0, 0, 1]])
    t = np.linspace(0.0, 3.0, 7)
    h = 1e-3
    x, xd, xdd = motion.frames(t, pose)
    shifted = [motion.frames(t + k * h, pose)[0] for k in (-2, -1, 1, 2)]
    d1 = (shifted[0] - 8 * shifted[1] + 8 * shifted[2] - shifted[3]) / (12 * h)
    shifted_d = [motion.frames(t + k * h, pose)[1] for k in (-2, -1, 1, 2)]
    d2 = (shifted_d[0] - 8 * shifted_d[1] + 8 * shifted_d[2] - shifted_d[3]) / (12 * h)
    assert np.abs(xd - d1).max() < 1e-8 * np.abs(xd).max()
    assert np.abs(xdd - d2).max() < 1e-8 * np.abs(xdd).max()
    assert np.abs(xdd[:, 1:]).max() > 0.5  # a real rotational acceleration
    R = x[:, 1:].transpose(0, 2, 1)
    assert np.abs(R.transpose(0, 2, 1) @ R - np.eye(3)).max() < 1e-12
    assert np.allclose(np.linalg.det(R), 1.0)
    # The convention: angles about the ground's fixed x, y, z, x first (R = Rz Ry Rx).
    only_x = BaseMotion(rotation=(Motion(0.3), Motion(0.0), Motion(0.0)))
    only_z_then_x = BaseMotion(rotation=(Motion(0.3), Motion(0.0), Motion(0.5)))
    frame = only_x.frames(np.zeros(1), np.vstack([np.zeros(3), np.eye(3)]))[0][0]
    np.testing.assert_allclose(frame[2], [0, np.cos(0.3), np.sin(0.3)], atol=1e-15)  # v
    frame = only_z_then_x.frames(np.zeros(1), np.vstack([np.zeros(3), np.eye(3)]))[0][0]
    v_x = np.array([0, np.cos(0.3), np.sin(0.3)])
    rz = np.array([[np.cos(0.5), -np.sin(0.5), 0], [np.sin(0.5), np.cos(0.5), 0], [0, 0, 1]])
    np.testing.assert_allclose(frame[2], rz @ v_x, atol=1e-15)


@pytest.fixture(scope="module", params=["full", "reduced"])
def solved(request):
    model = parse_model(moving_text(), "floating.yaml").with_form(request.param)
    s = synthesize(model, duration=1.0, rate=1000.0)
    system = compile_system(model, angles="coordinate", track=True)
    result = solve_nrm(system, s.result.time, s.markers, NrmSettings(tol=1e-12))
    return model, s, result, classical_dynamics(model, result, tol=1e-12)


def test_markers_determine_the_floating_base(solved) -> None:
    _, s, result, _ = solved
    assert result.converged.all()
    assert np.abs(result.theta - s.result.theta).max() < 1e-8
    assert np.abs(result.q[:, :9] - s.result.q[:, :9]).max() < 1e-8  # B1, moving


def stencil(x: np.ndarray, dt: float) -> np.ndarray:
    """5-point central first derivative along axis 0 (loses two samples at each end)."""
    return (x[:-4] - 8 * x[1:-3] + 8 * x[3:-1] - x[4:]) / (12 * dt)


def test_synthesized_base_moves_as_prescribed(solved) -> None:
    """The base follows r*(t), u*(t), … and the solved q̇, q̈ are the motion's rates."""
    model, s, _, _ = solved
    r = s.result
    dt = r.time[1] - r.time[0]
    body = model.body("B1")
    x, _, xdd = body.motion.frames(r.time, body.pose.as_array())
    n = 12 if body.form == "full" else 9
    assert np.abs(r.q[:, :n] - x.reshape(len(x), 12)[:, :n]).max() < 1e-9
    assert np.abs(xdd[:, 0]).max() > 1.0 and np.abs(xdd[:, 1:]).max() > 1.0  # m/s², 1/s²
    inner = slice(2, -2)
    assert np.abs(r.qd[inner] - stencil(r.q, dt)).max() < 1e-6 * np.abs(r.qd).max()
    assert np.abs(r.qdd[inner] - stencil(r.qd, dt)).max() < 1e-6 * np.abs(r.qdd).max()


def _bodies(model, dynamics):
    """Per body: mass, and per frame (two samples lost at each end) the CoM position, velocity
    and acceleration, ω and the inertia tensor (global), all from the classical model's
    positions alone, differenced in time (5-point stencils at 1 kHz)."""
    system = compile_system(model, angles="driver")
    layout = system.layout
    kin = dynamics.kinematics
    dt = kin.time[1] - kin.time[0]
    x = np.array([layout.expand(q) for q in kin.q])
    inner = slice(2, -2)
    out = []
    for k, body in enumerate(model.bodies):
        c = np.array([1.0, *body.inertia.com])
        block = x[:, 12 * k:12 * k + 12].reshape(-1, 4, 3)
        rG = np.einsum("a,fai->fi", c, block)
        vG = stencil(rG, dt)
        aG = stencil(stencil(rG, dt), dt)
        R = block[:, 1:].transpose(0, 2, 1)          # columns u, v, w
        W = stencil(R, dt) @ R[inner].transpose(0, 2, 1)
        omega = np.stack([W[:, 2, 1], W[:, 0, 2], W[:, 1, 0]], axis=1)
        inertia = R[inner] @ np.array(body.inertia.tensor) @ R[inner].transpose(0, 2, 1)
        out.append((body.inertia.mass, rG[inner], vG, aG, omega, inertia))
    return out


def test_residual_force_is_newtons_second_law(solved) -> None:
    model, _, _, dynamics = solved
    g = np.array(model.gravity)
    bodies = _bodies(model, dynamics)
    total = sum(m * (aG - g) for m, _, _, aG, _, _ in bodies)  # frames 4 … n − 5
    force = dynamics.inverse.residual_force[4:-4, 0]
    assert np.abs(force - total).max() <= 1e-5 * np.abs(total).max()
    assert np.abs(total).max() > 10.0  # gravity and motion: a real load


def test_residual_moment_is_the_rate_of_angular_momentum(solved) -> None:
    """About the fixed ground origin: the drivers' moment about the moving base origin B plus
    r_B × F equals dH_O/dt − Σ r_G × m g."""
    model, _, _, dynamics = solved
    g = np.array(model.gravity)
    dt = dynamics.kinematics.time[1] - dynamics.kinematics.time[0]
    bodies = _bodies(model, dynamics)
    H = sum(np.cross(rG, m * vG) + np.einsum("fij,fj->fi", inertia, omega)
            for m, rG, vG, _, omega, inertia in bodies)
    gravity_moment = sum(np.cross(rG, m * g) for m, rG, _, _, _, _ in bodies)
    expected = stencil(H, dt) - gravity_moment[2:-2]
    base = dynamics.kinematics.q[4:-4, :3]  # B1's origin
    inv = dynamics.inverse
    moment = inv.residual_moment[4:-4, 0] + np.cross(base, inv.residual_force[4:-4, 0])
    scale = np.abs(expected).max()
    assert np.abs(moment - expected).max() <= 1e-5 * scale
    assert scale > 1.0


def test_mixed_rates_of_every_body_follow_the_motion(solved) -> None:
    """The topology alone leaves a floating base's rates free (6 per base): the solution's q̇
    and q̈ must still be the motion's, here the synthesized exact ones (base moving)."""
    _, s, result, _ = solved
    inner = slice(2, -2)  # one-sided stencils at the ends are less accurate
    scale_d = np.abs(s.result.qd).max()
    scale_dd = np.abs(s.result.qdd).max()
    n = s.result.qd.shape[1]  # the body coordinates (the mixed q adds the angles)
    assert np.abs(result.qd[:, :n] - s.result.qd)[inner].max() < 1e-4 * scale_d
    assert np.abs(result.qdd[:, :n] - s.result.qdd)[inner].max() < 1e-3 * scale_dd


def test_a_base_turned_far_at_t0_carries_its_chain_rigidly() -> None:
    """Frame 0 of a base translated by (0.4, −0.2, 0.3) m and turned by (70, −40, 150) deg is
    the still base's frame 0 moved rigidly with it: the joints' configuration, set by the same
    angles, must not land on another assembly branch on the way from the stated pose."""
    pose = "    pose: {r: [0.15, 0, 0], u: [1, 0, 0], v: [0, 1, 0], w: [0, 0, 1]}\n"
    motion = ("    motion:\n      translation: [{mean: 0.4}, {mean: -0.2}, {mean: 0.3}]\n"
              "      rotation: [{mean: 70}, {mean: -40}, {mean: 150}]\n")
    still = synthesize(parse_model(floating_text(), "still.yaml"), duration=0.02, rate=100)
    model = parse_model(floating_text().replace(pose, pose + motion), "moved.yaml")
    moved = synthesize(model, duration=0.02, rate=100)
    c, s = np.cos, np.sin
    ax, ay, az = np.radians([70.0, -40.0, 150.0])
    Rx = np.array([[1, 0, 0], [0, c(ax), -s(ax)], [0, s(ax), c(ax)]])
    Ry = np.array([[c(ay), 0, s(ay)], [0, 1, 0], [-s(ay), 0, c(ay)]])
    Rz = np.array([[c(az), -s(az), 0], [s(az), c(az), 0], [0, 0, 1]])
    R = Rz @ Ry @ Rx
    origin = np.array([0.15, 0.0, 0.0])
    before = still.result.q[0].reshape(-1, 4, 3)
    expected = before @ R.T
    expected[:, 0] = origin + np.array([0.4, -0.2, 0.3]) + (before[:, 0] - origin) @ R.T
    assert np.abs(moved.result.q[0].reshape(-1, 4, 3) - expected).max() < 1e-9

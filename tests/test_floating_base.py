"""Floating bases: the five-bar with its ground joint removed, so that B1 floats (6 degrees of
freedom determined by its markers in MC, by base drivers in the classical model).

Independent checks of the base drivers' residual wrench: the force against Newton's second law
for the whole system, Σ m_i (a_Gi − g); the moment about the (still) base origin O against the
rate of the system's angular momentum, dH_O/dt − Σ (r_Gi − O) × m_i g, with H_O from the
bodies' velocities and inertia tensors and d/dt by central differences at 1 kHz.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from fccgrb_cli.cli import main
from fccgrb_cli.dynamics.convert import classical_dynamics
from fccgrb_cli.model import parse_model
from fccgrb_cli.solvers.nrm import NrmSettings, solve_nrm
from fccgrb_cli.synth import synthesize
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


@pytest.fixture(scope="module", params=["full", "reduced"])
def solved(request):
    model = parse_model(floating_text(), "floating.yaml").with_form(request.param)
    s = synthesize(model, duration=1.0, rate=1000.0)
    system = compile_system(model, angles="coordinate", track=True)
    result = solve_nrm(system, s.result.time, s.markers, NrmSettings(tol=1e-12))
    return model, s, result, classical_dynamics(model, result, tol=1e-12)


def test_markers_determine_the_floating_base(solved) -> None:
    _, s, result, _ = solved
    assert result.converged.all()
    assert np.abs(result.theta - s.result.theta).max() < 1e-8
    assert np.abs(result.q[:, :9] - s.result.q[:, :9]).max() < 1e-8  # B1 (held still by synth)


def _bodies(model, dynamics):
    """Per body and frame: mass, CoM position, velocity, acceleration, ω and I (global)."""
    system = compile_system(model, angles="driver")
    layout = system.layout
    kin = dynamics.kinematics
    out = []
    for k, body in enumerate(model.bodies):
        c = np.array([1.0, *body.inertia.com])
        I_local = np.array(body.inertia.tensor)
        rows = []
        for f in range(len(kin.q)):
            x = layout.expand(kin.q[f])[12 * k:12 * k + 12].reshape(4, 3)
            xd = layout.expand_rate(kin.q[f], kin.qd[f])[12 * k:12 * k + 12].reshape(4, 3)
            xq = layout.expand_jacobian(kin.q[f])
            xdd = (kin.qdd[f] if xq is None else xq @ kin.qdd[f]) + layout.expand_bias(kin.qd[f])
            xdd = xdd[12 * k:12 * k + 12].reshape(4, 3)
            R, Rd = x[1:].T, xd[1:].T
            W = Rd @ R.T
            omega = np.array([W[2, 1], W[0, 2], W[1, 0]])
            rows.append((c @ x, c @ xd, c @ xdd, omega, R @ I_local @ R.T))
        out.append((body.inertia.mass, rows))
    return out


def test_residual_force_is_newtons_second_law(solved) -> None:
    model, _, _, dynamics = solved
    g = np.array(model.gravity)
    total = sum(m * np.array([a - g for _, _, a, _, _ in rows])
                for m, rows in _bodies(model, dynamics))
    force = dynamics.inverse.residual_force[:, 0]
    assert np.abs(force - total).max() <= 1e-9 * np.abs(total).max()
    assert np.abs(total).max() > 10.0  # gravity and motion: a real load


def test_residual_moment_is_the_rate_of_angular_momentum(solved) -> None:
    model, _, result, dynamics = solved
    g = np.array(model.gravity)
    origin = result.q[0, :3]  # B1's origin, held still
    bodies = _bodies(model, dynamics)
    n = len(result.time)
    H = np.zeros((n, 3))
    gravity_moment = np.zeros((n, 3))
    for m, rows in bodies:
        for f, (rG, vG, _, omega, inertia) in enumerate(rows):
            H[f] += np.cross(rG - origin, m * vG) + inertia @ omega
            gravity_moment[f] += np.cross(rG - origin, m * g)
    dH = np.gradient(H, result.time, axis=0)
    expected = dH - gravity_moment
    moment = dynamics.inverse.residual_moment[:, 0]
    inner = slice(5, -5)
    scale = np.abs(expected[inner]).max()
    assert np.abs(moment[inner] - expected[inner]).max() <= 1e-4 * scale
    assert scale > 1.0


def test_mixed_rates_of_every_body_follow_the_motion(solved) -> None:
    """The topology alone leaves a floating base's rates free (6 per base): the solution's q̇
    and q̈ must still be the motion's, here the synthesized exact ones (base held still)."""
    _, s, result, _ = solved
    inner = slice(2, -2)  # one-sided stencils at the ends are less accurate
    scale_d = np.abs(s.result.qd).max()
    scale_dd = np.abs(s.result.qdd).max()
    n = s.result.qd.shape[1]  # the body coordinates (the mixed q adds the angles)
    assert np.abs(result.qd[:, :n] - s.result.qd)[inner].max() < 1e-4 * scale_d
    assert np.abs(result.qdd[:, :n] - s.result.qdd)[inner].max() < 1e-3 * scale_dd

"""The batched dynamics stage against the frame-by-frame one, and the stacked
evaluation against derivatives taken by central differences.

* ``classical_dynamics`` batched (every frame at once from the run's own body coordinates; the
  default where Φ_q is square, forced here for the taller ones too) and sequential (frame by
  frame, warm-started) give the same q, q̇, q̈, θ, multipliers, joint moments, residuals and
  energies to 1e-9, on the five-bar sample solved by NRM-WLS at P30
  (drivers met only to the WLS topology's 1e-5, then 6 Hz filtered), and on synthesized
  motions of the bundled crank-rocker (a signed full-turn angle: a sine row, so Φ_q is taller
  than wide and the stacked solves go through QR), slider (a distance coordinate), RSSR, and
  the floating-base five-bar in both body forms (base drivers; reduced bodies: X_q ≠ I).
* frames the batch leaves to the frame-by-frame path (a one-iteration batch, a frame without a
  guess) still give the same answers.
* the stacked Φ_q, ν and γ of a drawn configuration and rates against central differences of
  the stacked Φ (an independent check of every row kind's signs: linear, base, dot, driver,
  sine and distance rows, reduced bodies).
* the stacked solves (square, taller, singular, rank-deficient, wider) against
  ``linear_solve`` frame by frame.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from test_floating_base import moving_text

from fccgrb_cli.dynamics import ExternalLoad
from fccgrb_cli.dynamics.convert import Dynamics, classical_dynamics
from fccgrb_cli.model import load_model, parse_model
from fccgrb_cli.pipeline.options import SolveOptions
from fccgrb_cli.pipeline.solve import solve_trial
from fccgrb_cli.pipeline.synth import synthesize
from fccgrb_cli.solvers.ad import solve as ad
from fccgrb_cli.solvers.batched import Drives, Stacked, factor
from fccgrb_cli.solvers.newton import linear_solve
from fccgrb_cli.system import compile_system
from fccgrb_cli.trial.record import read_trial

ROOT = Path(__file__).resolve().parents[1]
MODELS = ROOT / "configs" / "models"


def assert_same(a: Dynamics, b: Dynamics, tol: float = 1e-9) -> None:
    """Every number of the two dynamics runs within ``tol`` (SI: m, rad, N·m, N, J)."""
    for name in ("q", "qd", "qdd", "theta", "theta_d", "theta_dd"):
        np.testing.assert_allclose(getattr(a.kinematics, name), getattr(b.kinematics, name),
                                   rtol=0, atol=tol, err_msg=name)
    assert a.kinematics.converged.all() and b.kinematics.converged.all()
    for name in ("lam", "joint_moments", "residual", "kinetic", "potential", "external_power"):
        np.testing.assert_allclose(getattr(a.inverse, name), getattr(b.inverse, name),
                                   rtol=0, atol=tol, err_msg=name)
    if b.inverse.residual_force is not None:
        np.testing.assert_allclose(a.inverse.residual_force, b.inverse.residual_force,
                                   rtol=0, atol=tol)
        np.testing.assert_allclose(a.inverse.residual_moment, b.inverse.residual_moment,
                                   rtol=0, atol=tol)


@pytest.fixture(scope="module")
def five_bar_run():
    model = load_model(MODELS / "five_bar.yaml")
    trial = read_trial(ROOT / "sample_data" / "five_bar.c3d")
    # each frame's own solution (the smoother's satisfies the topology exactly, and the
    # guesses would not be off)
    run = solve_trial(model, trial, SolveOptions(method="nrm-wls", perturb_mm=30.0,
                                                 dynamics=False, smooth="none"))
    return model, run.result


@pytest.mark.parametrize("cutoff", [None, 6.0])
def test_five_bar_sample_batched_equals_sequential(five_bar_run, cutoff) -> None:
    model, result = five_bar_run
    rng = np.random.default_rng(5)
    n = result.n_frames
    push = ExternalLoad("push", "B3", rng.normal(0, 20, (n, 3)),
                        rng.normal(0, 0.3, (n, 3)), rng.normal(0, 2, (n, 3)))
    batched = classical_dynamics(model, result, cutoff=cutoff, loads=[push], batched=True)
    sequential = classical_dynamics(model, result, cutoff=cutoff, loads=[push], batched=False)
    assert_same(batched, sequential)
    # not a trivial equality: the guesses were off (WLS topology, filtered drivers)
    assert np.abs(batched.kinematics.q - result.q[:, :60]).max() > 1e-7
    assert np.abs(batched.inverse.joint_moments).max() > 10.0
    assert np.abs(batched.inverse.external_power).max() > 1.0


def synthesized(name: str, form: str = "model") -> tuple[Dynamics, Dynamics]:
    """The model's own prescribed motion (1 s at 100 Hz), then its dynamics both ways with the
    drivers low-passed at 6 Hz (so that the guesses are not already solutions)."""
    if name == "floating":
        model = parse_model(moving_text(), "floating.yaml")
    else:
        model = load_model(MODELS / f"{name}.yaml")
    if form != "model":
        model = model.with_form(form)
    truth = synthesize(model, duration=1.0).result
    return (classical_dynamics(model, truth, cutoff=6.0, batched=True),
            classical_dynamics(model, truth, cutoff=6.0, batched=False))


@pytest.mark.parametrize(("name", "form"), [("crank_rocker", "model"), ("slider", "model"),
                                            ("rssr", "model"), ("floating", "full"),
                                            ("floating", "reduced")])
def test_bundled_models_batched_equals_sequential(name: str, form: str) -> None:
    batched, sequential = synthesized(name, form)
    assert_same(batched, sequential)
    if name == "crank_rocker":  # the crank turns through full turns: signed angle kept
        theta = batched.kinematics.theta[:, 0]
        assert np.ptp(theta) > np.pi
    if name == "floating":
        assert np.abs(batched.inverse.residual_force).max() > 1.0


def test_frames_left_by_the_batch_take_the_frame_by_frame_path(five_bar_run, monkeypatch
                                                               ) -> None:
    """One batch iteration: the frames not converged by then (most, the drivers being
    filtered) and a frame without a guess go through solve_ad's own path (from the previous
    frame, extrapolated)."""
    model, result = five_bar_run
    sequential = classical_dynamics(model, result, cutoff=6.0, batched=False)
    monkeypatch.setattr(ad, "BATCH_ITER", 1)
    holed = result.q.copy()
    holed[7] = np.nan
    batched = classical_dynamics(model, replace(result, q=holed), cutoff=6.0, batched=True)
    assert (batched.kinematics.iterations > 1).sum() > 100
    assert_same(batched, sequential)


MODELS_FOR_DERIVATIVES = [("crank_rocker", "model"), ("slider", "model"),
                          ("floating", "reduced"), ("five_bar", "reduced")]


@pytest.mark.parametrize(("name", "form"), MODELS_FOR_DERIVATIVES)
def test_stacked_derivatives_match_central_differences(name: str, form: str) -> None:
    """At drawn q, q̇, q̈ (not consistent: every row counts) and drivers moving as
    θ*(t) = θ + θ̇ t + θ̈ t²/2 (likewise the base features): Φ_q against ∂Φ/∂q, ν = −∂Φ/∂t,
    and γ = Φ_q q̈ − d²Φ/dt² along q(t) = q + q̇ t + q̈ t²/2."""
    model = parse_model(moving_text(), "floating.yaml") if name == "floating" else \
        load_model(MODELS / f"{name}.yaml")
    if form != "model":
        model = model.with_form(form)
    system = compile_system(model, angles="driver")
    stacked = Stacked(system)
    rng = np.random.default_rng(7)
    frames, nq, nd = 3, system.nq, len(system.angle_rows)
    q, qd, qdd = (rng.normal(size=(frames, nq)) for _ in range(3))
    th, thd, thdd = rng.uniform(0.3, 2.5, (frames, nd)), *rng.normal(size=(2, frames, nd))
    ref, refd, refdd = rng.normal(size=(3, frames, system.n_base_slots, 3))

    def drives_at(t: float) -> Drives:
        return Drives(th + thd * t + 0.5 * thdd * t * t, thd + thdd * t, thdd,
                      ref + refd * t + 0.5 * refdd * t * t, refd + refdd * t, refdd)

    d0 = drives_at(0.0)
    phi, J = stacked.evaluate(q, d0)
    h = 1e-6
    numeric = np.stack([(stacked.residual(q + h * e, d0) - stacked.residual(q - h * e, d0))
                        / (2 * h) for e in np.eye(nq)], axis=2)
    np.testing.assert_allclose(J, numeric, rtol=0, atol=1e-7 * max(1.0, np.abs(J).max()))
    phi_t = (stacked.residual(q, drives_at(h)) - stacked.residual(q, drives_at(-h))) / (2 * h)
    np.testing.assert_allclose(stacked.nu(d0), -phi_t, rtol=0, atol=1e-6)
    k = 1e-4

    def along(t: float) -> np.ndarray:
        return stacked.residual(q + qd * t + 0.5 * qdd * t * t, drives_at(t))

    second = (along(k) - 2 * phi + along(-k)) / k**2
    gamma = stacked.gamma(q, qd, d0)
    expected = np.einsum("frq,fq->fr", J, qdd) - second
    np.testing.assert_allclose(gamma, expected, rtol=0, atol=1e-4 * max(1.0, np.abs(gamma).max()))
    # and the one-frame System agrees with its stack (same rows, same order)
    f = 1
    np.testing.assert_allclose(J[f], system.jacobian(q[f]), rtol=0, atol=1e-12)
    np.testing.assert_allclose(gamma[f], system.gamma(q[f], qd[f], d0.frame(f)), rtol=0,
                               atol=1e-9)


def test_stacked_solves_equal_linear_solve() -> None:
    """Square (regular and exactly singular), taller (full column rank and rank-deficient) and
    wider stacks: J x = b and Jᵀ y = c as linear_solve answers them frame by frame."""
    rng = np.random.default_rng(11)

    def stack(m: int, n: int, broken: int | None = None) -> np.ndarray:
        J = rng.normal(size=(5, m, n))
        if broken is not None:  # a column repeated: singular / rank-deficient
            J[broken, :, 1] = J[broken, :, 0]
        return J

    for J in (stack(6, 6), stack(6, 6, broken=2), stack(8, 6), stack(8, 6, broken=3),
              stack(5, 7)):
        b = rng.normal(size=J.shape[:2])
        c = rng.normal(size=(len(J), J.shape[2]))
        prepared = factor(J)
        x, y = prepared.solve(b), prepared.solve_transposed(c)
        for f in range(len(J)):
            np.testing.assert_allclose(x[f], linear_solve(J[f], b[f]), rtol=0, atol=1e-9)
            np.testing.assert_allclose(y[f], linear_solve(J[f].T, c[f]), rtol=0, atol=1e-9)
        if J.shape[1] == J.shape[2] and not np.isclose(np.linalg.det(J), 0).any():
            np.testing.assert_allclose(np.einsum("fij,fj->fi", J, x), b, atol=1e-10)


def test_blocks_of_frames_give_the_same_answers(five_bar_run, monkeypatch) -> None:
    """Long trials are stacked block by block (memory); a block size that splits the 300 frames
    unevenly changes nothing (frames are independent)."""
    from fccgrb_cli.solvers import batched

    model, result = five_bar_run
    whole = classical_dynamics(model, result, cutoff=6.0, batched=True)
    monkeypatch.setattr(batched, "BLOCK", 37)
    assert len(batched.blocks(result.n_frames)) == 9
    pieces = classical_dynamics(model, result, cutoff=6.0, batched=True)
    assert_same(whole, pieces, tol=1e-12)

"""The stabilized SQP (solvers/cno/sqp.py) against the paper's reference optimizer and against the
optimality conditions themselves.

* SLSQP (scipy, tightened to ftol 1e-14) reaches the same optimum on the five-bar at P0–P30, on
  a crank-rocker whose signed angle makes the topological rows dependent, and with gaps;
* at every solution the KKT conditions hold, checked with numpy's SVD independently of either
  optimizer: Φ_top = 0, and ∇F has no component in the null space of Φ_top,q (so no feasible
  direction lowers F to first order); F rises along feasible curves out of the solution
  (second order);
* the compiled kernels give the numpy path's answers; a frame the SQP cannot solve goes to
  SLSQP, and says so.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from fccgrb_cli.model import load_model
from fccgrb_cli.pipeline.synth import synthesize
from fccgrb_cli.signals.artefact import perturb
from fccgrb_cli.solvers.newton import Iterate
from fccgrb_cli.solvers.optimize import frame
from fccgrb_cli.solvers.optimize.problem import FrameProblem
from fccgrb_cli.solvers.optimize.solve import Settings, solve_optimization
from fccgrb_cli.system import compile_system

MODELS = Path(__file__).resolve().parents[1] / "configs" / "models"
FRAMES = 25


def case(name: str, level: float, frames: int = FRAMES):
    model = load_model(MODELS / f"{name}.yaml")
    truth = synthesize(model)
    system = compile_system(model, angles="coordinate", track=True)
    markers = perturb(truth.markers, truth.labels, truth.rate, level, seed=4)[:frames]
    return system, truth.result.time[:frames], markers


def run(system, time, markers, **settings):
    return solve_optimization(system, time, markers, Settings("cno-sqp", "tc", **settings))


def kkt_residuals(system, q: np.ndarray, markers: np.ndarray) -> tuple[float, float]:
    """max |Φ_top| and the largest component of ∇F (m²) in the null space of Φ_top,q (from the
    problem's own objective and Jacobian; the null space by SVD). At 7.5 mm noise |∇F| is
    ~1e-2."""
    problem = FrameProblem(system, markers)
    phi, J = system.evaluate(q, problem.drive)
    top = problem.top
    _, gradient = problem.tc(q)
    _, sv, vt = np.linalg.svd(J[top])
    rank = int((sv > sv[0] * 1e-10).sum())
    null = vt[rank:]
    return float(np.abs(phi[top]).max()), float(np.abs(null @ gradient).max())


def rises_along_feasible_curves(system, q: np.ndarray, markers: np.ndarray) -> bool:
    """F at the solution is below F at points reached by moving 1e-4 along random null-space
    directions and projecting back onto Φ_top = 0 (Gauss–Newton on the constraints only)."""
    problem = FrameProblem(system, markers)
    top = problem.top
    f0 = problem.tc(q)[0]
    rng = np.random.default_rng(0)
    for _ in range(6):
        J = system.evaluate(q, problem.drive)[1][top]
        _, sv, vt = np.linalg.svd(J)
        null = vt[int((sv > sv[0] * 1e-10).sum()):]
        p = q + 1e-4 * (rng.standard_normal(len(null)) @ null)
        for _ in range(20):
            phi, Jp = system.evaluate(p, problem.drive)
            p = p - np.linalg.lstsq(Jp[top], phi[top], rcond=None)[0]
        if not problem.tc(p)[0] > f0:
            return False
    return True


@pytest.mark.parametrize("level", [0.0, 7.5e-3, 30e-3])
def test_same_optimum_as_slsqp_on_the_five_bar(level: float) -> None:
    system, time, markers = case("five_bar", level)
    ours = run(system, time, markers, engine="numpy")
    reference = run(system, time, markers, optimizer="scipy", tol=1e-14)
    assert ours.converged.all() and reference.converged.all()
    assert all(m == "stabilized SQP: converged successfully" for m in ours.status)
    assert np.abs(ours.theta - reference.theta).max() < np.radians(1e-5)
    assert np.abs(ours.q - reference.q).max() < 1e-8
    assert ours.phi_top_max.max() <= 1e-11
    # it takes far fewer iterations than SLSQP (13–15 a frame)
    assert ours.iterations[1:].mean() <= 5
    for f in range(0, FRAMES, 6):
        violation, stationarity = kkt_residuals(system, ours.q[f], markers[f])
        assert violation <= 1e-11 and stationarity < 1e-10, (f, violation, stationarity)
    assert rises_along_feasible_curves(system, ours.q[FRAMES // 2], markers[FRAMES // 2])


def test_dependent_rows_and_gaps() -> None:
    system, time, markers = case("crank_rocker", 10e-3)
    assert system.redundant_topology
    markers = markers.copy()
    markers[5:9, 1] = np.nan
    ours = run(system, time, markers, engine="numpy")
    reference = run(system, time, markers, optimizer="scipy", tol=1e-14)
    assert ours.converged.all()
    assert np.abs(ours.q - reference.q).max() < 1e-8
    for f in (0, 6, 20):
        violation, stationarity = kkt_residuals(system, ours.q[f], markers[f])
        assert violation <= 1e-11 and stationarity < 1e-10


@pytest.mark.parametrize("name", ["five_bar", "crank_rocker", "slider", "rssr"])
def test_compiled_equals_numpy(name: str) -> None:
    system, time, markers = case(name, 15e-3, 60)
    markers = markers.copy()
    markers[20:23, 0] = np.nan
    numpy = run(system, time, markers, engine="numpy")
    compiled = run(system, time, markers, engine="compiled")
    assert (numpy.converged == compiled.converged).all()
    # the warm start's Hessian switch may count a frame's iterations apart (test_interior's
    # note): one frame, a few iterations, never the point
    differ = numpy.iterations != compiled.iterations
    assert differ.sum() <= 1 and (np.abs(numpy.iterations - compiled.iterations) <= 5).all()
    assert np.abs(numpy.q - compiled.q).max() < 1e-12
    assert np.abs(numpy.phi_norm - compiled.phi_norm).max() < 1e-12
    assert numpy.status == compiled.status


def test_a_frame_the_sqp_cannot_solve_goes_to_slsqp(monkeypatch) -> None:
    system, time, markers = case("five_bar", 7.5e-3, 8)
    real = frame.stabilized_sqp

    def capped(system, q0, drive, weights, tol, max_iter=1, bounds=None):
        out = real(system, q0, drive, weights, tol, 1, bounds)
        return Iterate(out.q, out.iterations, out.converged)

    monkeypatch.setattr(frame, "stabilized_sqp", capped)
    result = run(system, time, markers, engine="numpy")
    reference = run(system, time, markers, optimizer="scipy")
    assert result.converged.all()
    assert all(re.match(r"stabilized SQP: no convergence in \d+ iterations; SLSQP: ", m)
               for m in result.status), result.status
    assert np.abs(result.q - reference.q).max() < 1e-12


def test_frames_the_compiled_sqp_cannot_solve_take_the_same_way_out() -> None:
    """An iteration cap of 2: the kernels' SQP fails on most frames, which go back to Python
    (SLSQP, then the retry from NRM-WLS) exactly as the numpy path's do; the history carried
    on between frames is the same."""
    system, time, markers = case("five_bar", 30e-3, 12)
    numpy = run(system, time, markers, engine="numpy", max_iter=2)
    compiled = run(system, time, markers, engine="compiled", max_iter=2)
    assert sum("SLSQP" in m for m in compiled.status) >= 6
    assert numpy.status == compiled.status
    assert (numpy.converged == compiled.converged).all()
    assert (numpy.iterations == compiled.iterations).all()
    assert np.abs(numpy.q - compiled.q).max() < 1e-9

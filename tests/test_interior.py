"""The structured CNO-IP (sqp.Barrier: the stabilized SQP with a primal-dual barrier on the
bounds) against the SQP, against the paper's reference implementations (scipy's trust-constr and
SLSQP) and against the optimality conditions with an active bound:

* where no bound is active (every bundled trial), it reaches the SQP's optimum to ~1e-10 and
  trust-constr's to the latter's own accuracy;
* with a bound cut through the unbounded optimum, it lands on the bound, at trust-constr's
  optimum (SLSQP gives up on some of these frames),
  and the KKT conditions hold with the bound's multiplier of the right sign (checked by SVD and
  least squares, independently of any optimizer);
* the compiled kernel gives the numpy path's answers, bounds active or not.
"""

from __future__ import annotations

import numpy as np
import pytest

from fccgrb_cli.solvers.optimize.problem import ANGLE_MARGIN, FrameProblem
from fccgrb_cli.solvers.optimize.solve import Settings, solve_optimization
from tests.test_sqp import case, kkt_residuals


def run(system, time, markers, method="cno-ip", **settings):
    return solve_optimization(system, time, markers, Settings(method, "tc", **settings))


@pytest.mark.parametrize("level", [0.0, 30e-3])
def test_same_optimum_as_the_sqp_and_trust_constr(level: float) -> None:
    system, time, markers = case("five_bar", level, 12)
    ours = run(system, time, markers, engine="numpy")
    sqp = run(system, time, markers, "cno-sqp", engine="numpy")
    assert ours.converged.all()
    assert all(m == "interior point: converged successfully" for m in ours.status)
    assert np.abs(ours.q - sqp.q).max() < 1e-9
    assert ours.phi_top_max.max() <= 1e-11
    assert ours.iterations[1:].mean() <= 7
    reference = run(system, time[:4], markers[:4], optimizer="scipy")
    assert reference.converged.all()
    assert np.abs(ours.theta[:4] - reference.theta).max() < np.radians(1e-4)
    for f in (0, 5, 11):
        violation, stationarity = kkt_residuals(system, ours.q[f], markers[f])
        assert violation <= 1e-11 and stationarity < 1e-10


def first_bounded_angle(system) -> int:
    lower, _ = FrameProblem(system, np.zeros((len(system.trk_weight), 3))).bound_arrays()
    return int(np.flatnonzero(lower == ANGLE_MARGIN)[0])


@pytest.fixture
def cut(monkeypatch):
    """Bounds with one angle's upper bound 0.05 rad below its lowest unbounded optimum over the
    frames: that bound is active at every frame's optimum."""

    def install(system, q_free: np.ndarray) -> tuple[int, float]:
        i = first_bounded_angle(system)
        cap = float(q_free[:, i].min()) - 0.05
        original = FrameProblem.bounds

        def bounds(self):
            out = original(self)
            out[i] = (out[i][0], cap)
            return out

        monkeypatch.setattr(FrameProblem, "bounds", bounds)
        return i, cap

    return install


def bound_kkt(system, q: np.ndarray, markers: np.ndarray, i: int) -> tuple[float, float]:
    """At q with q_i on its upper bound: the largest component of ∇F in the null space of
    [Φ_top,q; e_i] (by SVD), and the bound's multiplier z from ∇F + Φ_top,qᵀλ + z e_i = 0
    (least squares), which must be ≥ 0: moving q_i up, out of the box, would lower F."""
    problem = FrameProblem(system, markers)
    J = system.evaluate(q, problem.drive)[1][problem.top]
    e = np.zeros(len(q))
    e[i] = 1.0
    A = np.vstack([J, e])
    gradient = problem.tc(q)[1]
    _, sv, vt = np.linalg.svd(A)
    null = vt[int((sv > sv[0] * 1e-10).sum()):]
    multipliers = np.linalg.lstsq(A.T, -gradient, rcond=None)[0]
    return float(np.abs(null @ gradient).max()), float(multipliers[-1])


def test_an_active_bound(cut) -> None:
    system, time, markers = case("five_bar", 7.5e-3, 6)
    free = run(system, time, markers, engine="numpy")
    i, cap = cut(system, free.q)
    ours = run(system, time, markers, engine="numpy")
    reference = run(system, time, markers, optimizer="scipy")  # trust-constr
    assert ours.converged.all() and reference.converged.all()
    assert all(m == "interior point: converged successfully" for m in ours.status)
    assert (ours.q[:, i] < cap).all() and np.abs(ours.q[:, i] - cap).max() < 1e-9
    assert np.abs(ours.q - reference.q).max() < 1e-8
    for f in range(len(time)):
        problem = FrameProblem(system, markers[f])
        assert problem.tc(ours.q[f])[0] <= problem.tc(reference.q[f])[0] + 1e-12
        stationarity, z = bound_kkt(system, ours.q[f], markers[f], i)
        assert stationarity < 1e-8 and z > 1e-6, (f, stationarity, z)


@pytest.mark.parametrize("name", ["five_bar", "crank_rocker"])
def test_compiled_equals_numpy(name: str) -> None:
    system, time, markers = case(name, 15e-3, 40)
    markers = markers.copy()
    markers[20:23, 0] = np.nan
    numpy = run(system, time, markers, engine="numpy")
    compiled = run(system, time, markers, engine="compiled")
    assert numpy.converged.all()
    # the warm start's Gauss-Newton turns to the exact Hessian after a slow full step
    # (solvers/newton.py): whether a line search kept the full step can differ by rounding
    # between the engines on a frame, and with it that frame's count (crank_rocker, a frame
    # among the missing markers: 12 against 15), never the point
    differ = numpy.iterations != compiled.iterations
    assert differ.sum() <= 1 and (np.abs(numpy.iterations - compiled.iterations) <= 3).all()
    assert np.abs(numpy.q - compiled.q).max() < 1e-12
    assert numpy.status == compiled.status


def test_compiled_equals_numpy_with_an_active_bound(cut) -> None:
    system, time, markers = case("five_bar", 7.5e-3, 8)
    i, cap = cut(system, run(system, time, markers, engine="numpy").q)
    numpy = run(system, time, markers, engine="numpy")
    compiled = run(system, time, markers, engine="compiled")
    assert numpy.converged.all() and np.abs(numpy.q[:, i] - cap).max() < 1e-9
    # counts may differ by the warm start's Hessian switch (see test_compiled_equals_numpy)
    assert (np.abs(numpy.iterations - compiled.iterations) <= 3).all()
    assert np.abs(numpy.q - compiled.q).max() < 1e-12

"""Multi-objective goal attainment (Gembicki; docs/formulation.md §3): over (q, γ), min γ subject to
F_i(q) − w_i γ ≤ F_i* and Φ_top(q) = 0, solved by SQP (scipy's SLSQP, as MATLAB's fgoalattain).

Objectives: 'tc', each tracking component |r_P − r*| (3 per point, written as ±(r_P − r*) − wγ ≤ 0
so that it stays smooth), or 'ed', each point's Euclidean distance. Goals F* = 0, weights 1
unless a tracked point has its own weight.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from fccgrb_cli.solvers.optimize.problem import FrameProblem


@dataclass(frozen=True)
class FrameOutcome:
    """What an optimizer returns for one frame."""

    q: np.ndarray
    iterations: int
    converged: bool
    message: str


FEASIBLE = 1e-9
KKT_TOL = 1e-6


def kkt_satisfied(grad: np.ndarray, eq_jac: np.ndarray, eq: np.ndarray,
                  ineq_jac: np.ndarray | None = None, ineq: np.ndarray | None = None) -> bool:
    """First-order optimality at a point an optimizer stopped at without claiming success:
    feasible (|c_eq| ≤ 1e-9, c_ineq ≥ −1e-9) and ∇f = Σ μ ∇c_eq + Σ λ ∇c_active for some
    λ ≥ 0, to 1e-6 relative. SLSQP stops with 'positive directional derivative' at degenerate
    optima (zero-residual goal attainment, where every goal is active at once, or a tolerance
    at the precision limit); this tells such a stop from a failure. The multipliers are found
    by least squares with λ ≥ 0 as a bound (bounded-variable least squares): at a degenerate
    optimum they are not unique, and the minimum-norm ones may have a slightly negative λ
    although non-negative ones fit exactly (the five-bar's exact markers with --tol 1e-14)."""
    from scipy.optimize import lsq_linear

    if np.abs(eq).max(initial=0.0) > FEASIBLE:
        return False
    blocks = [eq_jac]
    n_eq = len(eq_jac)
    if ineq is not None and ineq_jac is not None:
        if ineq.min(initial=0.0) < -FEASIBLE:
            return False
        blocks.append(ineq_jac[ineq <= 1e-7 * max(1.0, np.abs(ineq).max(initial=0.0))])
    A = np.vstack(blocks)
    lower = np.concatenate([np.full(n_eq, -np.inf), np.zeros(len(A) - n_eq)])
    fit = lsq_linear(A.T, grad, bounds=(lower, np.inf), method="bvls", tol=1e-14)
    residual = np.linalg.norm(A.T @ fit.x - grad)
    return bool(residual <= KKT_TOL * max(1.0, float(np.linalg.norm(grad))))


def judged(res, nq: int, grad: Callable, eq: Callable, eq_jac: Callable,
           ineq: Callable | None = None, ineq_jac: Callable | None = None,
           keep: slice | None = None) -> FrameOutcome:
    """A SciPy result as a FrameOutcome, its stop checked against the KKT conditions."""
    x = res.x
    ok = bool(res.success)
    message = str(res.message)
    if not ok:
        ok = kkt_satisfied(grad(x), eq_jac(x), eq(x),
                           None if ineq_jac is None else ineq_jac(x),
                           None if ineq is None else ineq(x))
        if ok:
            message += " (first-order optimality verified)"
    return FrameOutcome(x[: nq] if keep is None else x[keep], int(res.nit), ok, message)


def solve_goal_frame(problem: FrameProblem, q0: np.ndarray, *, objective: str, tol: float,
                     max_iter: int) -> FrameOutcome:
    """One frame of goal attainment."""
    from scipy.optimize import minimize  # 0.1–0.2 s to load: only when a frame comes here

    nq = len(q0)
    w = np.where(problem.point_weights > 0, problem.point_weights, 1.0)
    active = problem.point_weights > 0

    def split(z: np.ndarray) -> tuple[np.ndarray, float]:
        return z[:nq], float(z[nq])

    if objective == "tc":
        rows = np.repeat(active, 3)
        w_rows = np.repeat(w, 3)[rows]

        def ineq(z: np.ndarray) -> np.ndarray:
            q, gamma = split(z)
            d = problem.residuals(q)[0].ravel()[rows]
            return np.concatenate([w_rows * gamma - d, w_rows * gamma + d])

        def ineq_jac(z: np.ndarray) -> np.ndarray:
            q, _ = split(z)
            Jd = problem.residuals(q)[1].reshape(-1, nq)[rows]
            return np.block([[-Jd, w_rows[:, None]], [Jd, w_rows[:, None]]])

        start = np.abs(problem.residuals(q0)[0].ravel()[rows] / w_rows).max(initial=0.0)
    else:
        w_pts = w[active]

        def ineq(z: np.ndarray) -> np.ndarray:
            q, gamma = split(z)
            return w_pts * gamma - problem.distances(q)[0][active]

        def ineq_jac(z: np.ndarray) -> np.ndarray:
            q, _ = split(z)
            return np.hstack([-problem.distances(q)[1][active], w_pts[:, None]])

        start = (problem.distances(q0)[0][active] / w_pts).max(initial=0.0)

    def eq(z: np.ndarray) -> np.ndarray:
        return problem.constraints(z[:nq])

    def eq_jac(z: np.ndarray) -> np.ndarray:
        J = problem.constraints_jacobian(z[:nq])
        return np.hstack([J, np.zeros((len(J), 1))])

    gradient = np.zeros(nq + 1)
    gradient[nq] = 1.0

    res = minimize(lambda z: (z[nq], gradient), np.append(q0, start), jac=True,
                   method="SLSQP", bounds=[*problem.bounds(), (None, None)],
                   constraints=[{"type": "eq", "fun": eq, "jac": eq_jac},
                                {"type": "ineq", "fun": ineq, "jac": ineq_jac}],
                   options={"maxiter": max_iter, "ftol": tol})
    return judged(res, nq, lambda z: gradient, eq, eq_jac, ineq, ineq_jac)

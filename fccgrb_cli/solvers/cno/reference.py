"""Constrained nonlinear optimization (CNO, docs/formulation.md §3): min F(q) subject to the
topological equations Φ_top(q) = 0 and bounds, so the model never stretches to follow noise.

F is the weighted sum of squared tracking residuals ('tc') or of Euclidean distances ('ed').
SQP is scipy's SLSQP; the interior-point-like method is scipy's trust-constr (a trust-region
barrier method for inequalities, equality-constrained SQP otherwise) with exact Hessians of the
objective and the constraints from the engine. IPOPT (cyipopt) is not used: it does not install
from PyPI without a compiled IPOPT on the machine.
"""

from __future__ import annotations

import warnings

import numpy as np

from fccgrb_cli.solvers.goal.reference import FEASIBLE, FrameOutcome, judged
from fccgrb_cli.solvers.optimize.problem import FrameProblem


def solve_cno_frame(problem: FrameProblem, q0: np.ndarray, *, algorithm: str, objective: str,
                    tol: float, max_iter: int) -> FrameOutcome:
    """One frame by SQP ('sqp') or trust-constr ('ip'). trust-constr stops on the optimality
    (gtol = 100·tol) or step (xtol = tol) test, its barrier at 100·tol, starting from a barrier
    parameter of 1e-3: at the paper's 1e-10 for everything it took 10 s a frame."""
    # imported here: scipy.optimize takes 0.1–0.2 s to load, which a run whose frames all stay
    # in the engine's own optimizer never needs
    from scipy.optimize import Bounds, NonlinearConstraint, minimize

    fun = problem.tc if objective == "tc" else problem.ed
    scale = 1e6 if objective == "tc" else 1e3  # m² → mm², m → mm: ftol acts on sensible units

    def scaled(q: np.ndarray) -> tuple[float, np.ndarray]:
        value, grad = fun(q)
        return scale * value, scale * grad

    if algorithm == "sqp":
        res = minimize(scaled, q0, jac=True, method="SLSQP", bounds=problem.bounds(),
                       constraints=[{"type": "eq", "fun": problem.constraints,
                                     "jac": problem.constraints_jacobian}],
                       options={"maxiter": max_iter, "ftol": tol})
        return judged(res, len(q0), lambda q: scaled(q)[1], problem.constraints,
                      problem.constraints_jacobian)
    else:
        lower, upper = problem.bound_arrays()
        hess = (lambda q: scale * problem.tc_hessian(q)) if objective == "tc" else None
        eq = NonlinearConstraint(problem.constraints, 0.0, 0.0,
                                 jac=problem.constraints_jacobian,
                                 hess=problem.constraints_hessian)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # trust-constr warns about delta_grad == 0
            res = minimize(scaled, q0, jac=True, hess=hess, method="trust-constr",
                           bounds=Bounds(lower, upper, keep_feasible=False), constraints=[eq],
                           options={"maxiter": max_iter, "gtol": 100 * tol, "xtol": tol,
                                    "barrier_tol": 100 * tol,
                                    "initial_barrier_parameter": 1e-3})
        ok = bool(res.status in (1, 2)) and res.constr_violation <= FEASIBLE
    return FrameOutcome(res.x, int(res.nit), ok, str(res.message))

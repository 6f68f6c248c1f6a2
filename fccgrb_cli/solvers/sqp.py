"""CNO-SQP with the engine's own linear algebra: a stabilized SQP on the equality-constrained
least squares min F(q) = Σ w_n ‖C_P q − r*‖² subject to Φ_top(q) = 0 (FORMULATION §3, CNO with
the TC objective).

Newton on the KKT conditions ∇F + Φ_topᵀλ = 0, Φ_top = 0 with the exact Lagrangian Hessian
H = 2Φ_trkᵀWΦ_trk + Σ λ_i ∇²Φ_i (the tracking rows are linear: no second-order term of their
own), each step from the regularized KKT system

    [ H        Φ_topᵀ ] [ Δq ]     [ −∇F − Φ_topᵀλ ]
    [ Φ_top    −δ I   ] [ Δλ ]  =  [ −Φ_top        ]

(stabilized SQP: the multiplier block's −δI centred at the current λ; δ = 1e-6). Eliminating
Δλ leaves a positive definite matrix of the NRM shape, Φ_qᵀWΦ_q + Σ s_i ∇²Φ_i with W = 1 on the
topological rows and 2δ w_n on the tracking rows, and the multipliers enter as a shift s = δλ
of the topological residuals: the iteration is NRM's Gauss–Newton machinery (and its compiled
kernels) with the shift updated after each step, s ← s + Φ_top + Φ_top,q Δq. It converges to
the exact optimum (Φ_top = 0 to rounding, whatever δ; δ sets only the rate): from the previous
frames' extrapolation, 3–4 iterations per frame on the five-bar from P0 to P30, against SLSQP's
13–15. Dependent topological rows (a closed planar loop, a signed angle's pair) need no special
treatment: −δI keeps the system regular.

No bounds: the result is checked against FrameProblem's bounds, and a frame whose optimum lies
outside them, or that does not converge, is handed to SLSQP (cno.py).
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import lapack

from fccgrb_cli.solvers.newton import Iterate
from fccgrb_cli.system import Drive, System

DELTA = 1e-6
FEASIBLE_TOP = 1e-11  # max |Φ_top| at a converged frame (m and dimensionless)
MAX_ITER = 50
FAR = 1e-3  # max |Φ_top| of a guess that goes through NRM-WLS before the SQP (optimize.py)


def sqp_weights(system: System, point_weights: np.ndarray) -> np.ndarray:
    """W of the eliminated system: 1 on the topological rows, 2δ w_n on each tracked element's
    three rows (0 where its marker is missing)."""
    w = np.where(system.kinds == 0, 1.0, 0.0)
    start = 3 * len(system.lin_a)
    w[start:start + 3 * len(point_weights)] = 2.0 * DELTA * np.repeat(point_weights, 3)
    return w


def stabilized_sqp(system: System, q0: np.ndarray, drive: Drive, weights: np.ndarray,
                   tol: float, max_iter: int = MAX_ITER) -> Iterate:
    """One frame (``weights`` from :func:`sqp_weights`): steps until ‖Δq‖∞ < tol with
    max |Φ_top| ≤ FEASIBLE_TOP at the result."""
    top = system.kinds == 0
    q = q0.copy()
    shift = np.zeros(system.n_rows)
    size = np.inf
    for k in range(max_iter + 1):
        phi, J = system.evaluate(q, drive)
        violation = np.abs(phi[top]).max(initial=0.0)
        if size < tol and violation <= FEASIBLE_TOP:
            return Iterate(q, k, True)
        if k == max_iter:
            break
        r = weights * (phi + shift)
        normal = J.T @ (weights[:, None] * J)
        _, step, info = lapack.dposv(normal + system.residual_hessian(q, shift), -(J.T @ r))
        if info != 0:
            _, step, info = lapack.dposv(normal, -(J.T @ r))
        if info != 0:
            return Iterate(q, k + 1, False)
        size = np.abs(step).max()
        if not np.isfinite(size):
            return Iterate(q, k + 1, False)
        shift = np.where(top, shift + phi + J @ step, 0.0)
        q = q + step
    return Iterate(q, max_iter, False)

"""Newton–Raphson on square (or redundant) systems and Gauss–Newton on weighted over-determined
ones: the shared iteration of the AD and NRM methods (docs/formulation.md §3)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fccgrb_cli.core.blas import lapack
from fccgrb_cli.system import Drive, System


@dataclass(frozen=True)
class Iterate:
    """The outcome of one frame's iteration."""

    q: np.ndarray
    iterations: int
    converged: bool


def linear_solve(J: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """J x = rhs: LU for a square J, least squares with minimum norm for a redundant (or, at a
    singular configuration, rank-deficient) one."""
    if J.shape[0] == J.shape[1]:
        try:
            return np.linalg.solve(J, rhs)
        except np.linalg.LinAlgError:
            pass
    return minimum_norm_solve(J, rhs)


def minimum_norm_solve(J: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """The minimum-norm least-squares solution of J x = rhs (rhs: a vector or columns), rank
    decided at max(J.shape)·ε relative: LAPACK's gelsy (complete orthogonal factorization),
    the same solution as numpy's SVD-based lstsq, about 4× faster at these sizes (78 × 84:
    0.20 vs 0.84 ms). Called through scipy's compiled LAPACK module (``core.blas.lapack``), as
    ``scipy.linalg.lstsq(..., lapack_driver='gelsy')`` calls it, without that package's ~0.1 s
    import."""
    m, n = J.shape
    columns = rhs.reshape(m, -1)
    b = np.zeros((max(m, n), columns.shape[1]))
    b[:m] = columns
    cond = np.finfo(float).eps * max(m, n)
    work, info = lapack.dgelsy_lwork(m, n, columns.shape[1], cond)
    if info:
        raise np.linalg.LinAlgError(f"gelsy's workspace query failed ({info})")
    pivots = np.zeros(n, dtype=np.int32)
    x, info = lapack.dgelsy(np.array(J, dtype=float), b, pivots, cond, int(work.real))[1::3]
    if info:
        raise np.linalg.LinAlgError(f"gelsy: illegal argument {-info}")
    return x[:n].reshape((n, *rhs.shape[1:]))


def newton_raphson(system: System, q0: np.ndarray, drive: Drive, tol: float,
                   max_iter: int) -> Iterate:
    """Φ_q Δq = −Φ until ‖Δq‖∞ < tol (kinematic analysis with angular drivers)."""
    q = q0.copy()
    for k in range(1, max_iter + 1):
        phi, J = system.evaluate(q, drive)
        try:
            step = linear_solve(J, -phi)
        except np.linalg.LinAlgError:
            return Iterate(q, k, False)
        q += step
        size = np.abs(step).max()
        if not np.isfinite(size):
            return Iterate(q0, k, False)
        if size < tol:
            return Iterate(q, k, True)
    return Iterate(q, max_iter, False)


HESSIANS = ("auto", "gauss-newton", "exact")
# Relative size of the rounding in ΦᵀWΦ: near a solution a full step's decrease falls below it,
# and an Armijo test that ignored it would shrink converging steps a thousandfold.
ROUNDING = 1e-12
# 'auto' turns to the exact matrix once a step is below NEAR (m and rad: near the optimum) or
# shrinks by less than 1/SLOW after a full step (Gauss–Newton's linear rate on a
# large-residual problem).
NEAR = 1e-3
SLOW = 0.25
# ... near the optimum only where the residuals are large enough for Σ wΦ∇²Φ to matter: on
# markers the model fits exactly Gauss–Newton converges quadratically by itself
LARGE = 1e-8


def gauss_newton(system: System, q0: np.ndarray, drive: Drive, weights: np.ndarray, tol: float,
                 max_iter: int, hessian: str = "gauss-newton") -> Iterate:
    """(Φ_qᵀ W Φ_q) Δq = −Φ_qᵀ W Φ until ‖Δq‖∞ < tol (NRM with LS or WLS).

    The full step is taken whenever it lowers ½ΦᵀWΦ enough (Armijo); otherwise it is halved.
    Near a solution that is always the case, so the iteration is the plain one of the paper;
    far from it (large marker noise) the line search keeps Gauss–Newton from oscillating.
    ``hessian``: 'gauss-newton' (the paper's NRM), 'exact' (the matrix gains Σ wᵢΦᵢ ∇²Φᵢ:
    Newton's method on the weighted least-squares objective, quadratic instead of linear
    convergence when noisy markers leave large residuals), or 'auto': Gauss–Newton until a
    step is below ``NEAR`` (1 mm / 1 mrad) with some weighted residual above ``LARGE`` (noisy
    markers), or shrinks by less than 4× after a full step (the linear rate of a large residual:
    markers a model cannot follow; after a step the line search shortened, the next is as long
    as the part not taken, which says nothing of the rate), exact from then on. The exact matrix
    pays only near the optimum: from a warm start on the five-bar at P30 a first exact step often
    overshoots (its residual term is built from the guess's residuals), while Gauss–Newton
    then Newton meets 1e-10 in 4.1 iterations per frame instead of Gauss–Newton's 12.8 (P7.5:
    3.1 instead of 6.3; P0: 2.2 either way). Where the exact matrix is not positive definite the
    Gauss–Newton step is used.
    """
    q = q0.copy()
    unit = bool(np.all(weights == 1.0))
    phi, J = system.evaluate(q, drive)
    cost = float(phi @ (weights * phi))
    size = previous = np.inf
    full = True
    exact = hessian == "exact"
    trial_J: np.ndarray | None  # None after a shortened step: evaluated where it lands
    for k in range(1, max_iter + 1):
        near = size < NEAR and np.abs(weights * phi).max() > LARGE
        exact = exact or (hessian == "auto" and (near or size > SLOW * previous))
        JW = J if unit else J * weights[:, None]
        gradient = JW.T @ phi
        normal = JW.T @ J
        info = 1
        if exact:
            _, step, info = lapack.dposv(normal + system.residual_hessian(q, weights * phi),
                                         -gradient)
        if info != 0:
            _, step, info = lapack.dposv(normal, -gradient)
        if info != 0:
            return Iterate(q, k, False)
        previous, size = size if full else np.inf, np.abs(step).max()
        if not np.isfinite(size):
            return Iterate(q, k, False)
        if size < tol:
            return Iterate(q + step, k, True)
        slope = float(gradient @ step)
        alpha = 1.0
        trial = q + step
        trial_phi, trial_J = system.evaluate(trial, drive)
        trial_cost = float(trial_phi @ (weights * trial_phi))
        while trial_cost > cost + 2e-4 * alpha * slope + ROUNDING * cost and alpha >= 1e-3:
            alpha *= 0.5
            trial = q + alpha * step
            trial_phi = system.residual(trial, drive)
            trial_cost = float(trial_phi @ (weights * trial_phi))
            trial_J = None
        full = alpha == 1.0
        q, phi, cost = trial, trial_phi, trial_cost
        J = system.jacobian(q) if trial_J is None else trial_J
    return Iterate(q, max_iter, False)

"""Newton–Raphson on square (or redundant) systems and Gauss–Newton on weighted over-determined
ones: the shared iteration of the AD and NRM methods (FORMULATION §3)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fccgrb_cli.system import Drive, System


@dataclass(frozen=True)
class Iterate:
    """The outcome of one frame's iteration."""

    q: np.ndarray
    iterations: int
    converged: bool


def linear_solve(J: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """J x = rhs: LU for a square J, least squares with minimum norm for a redundant one."""
    if J.shape[0] == J.shape[1]:
        return np.linalg.solve(J, rhs)
    return np.linalg.lstsq(J, rhs, rcond=None)[0]


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
        if not np.all(np.isfinite(q)):
            return Iterate(q0, k, False)
        if np.abs(step).max() < tol:
            return Iterate(q, k, True)
    return Iterate(q, max_iter, False)


def gauss_newton(system: System, q0: np.ndarray, drive: Drive, weights: np.ndarray, tol: float,
                 max_iter: int) -> Iterate:
    """(Φ_qᵀ W Φ_q) Δq = −Φ_qᵀ W Φ until ‖Δq‖∞ < tol (NRM with LS or WLS)."""
    q = q0.copy()
    for k in range(1, max_iter + 1):
        phi, J = system.evaluate(q, drive)
        JW = J.T * weights
        try:
            step = np.linalg.solve(JW @ J, -(JW @ phi))
        except np.linalg.LinAlgError:
            return Iterate(q, k, False)
        q += step
        if not np.all(np.isfinite(q)):
            return Iterate(q0, k, False)
        if np.abs(step).max() < tol:
            return Iterate(q, k, True)
    return Iterate(q, max_iter, False)

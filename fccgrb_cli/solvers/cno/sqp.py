"""CNO-SQP with the engine's own linear algebra: a stabilized SQP on the equality-constrained
least squares min F(q) = Σ w_n ‖C_P q − r*‖² subject to Φ_top(q) = 0 (docs/formulation.md §3, CNO
with the TC objective).

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

The SQP takes no bounds: its result is checked against FrameProblem's bounds, and a frame whose
optimum lies outside them, or that does not converge, is handed to SLSQP (cno/reference.py).

CNO-IP is the same iteration with a primal-dual logarithmic barrier on the bounds l ≤ q ≤ u
(the interior point of docs/formulation.md §3, as MATLAB's fmincon 'interior-point', on this linear
algebra): bound multipliers z_l, z_u with z·s = μ on the slacks s_l = q − l, s_u = u − q; the
Newton step adds Σ = Z_l S_l⁻¹ + Z_u S_u⁻¹ to the Hessian's diagonal and μ S_l⁻¹ − μ S_u⁻¹ to
the right-hand side (scaled by δ in the eliminated system), takes the largest step that goes
at most 99.5 % of the way to a bound, for the slacks and the bound multipliers alike (fraction
to the boundary, τ = 0.995), and lowers μ after every iteration by IPOPT's superlinear update
μ ← max(μ_end, min(κμ, μ^θ)), κ = 0.2, θ = 1.5, from μ₀ = 1e-6 to μ_end = 1e-3·tol (IPOPT
waits for each barrier problem to be solved first; here the iteration simply goes on at μ_end
until the step is below tol, which is where the answer is judged). The iterate stays strictly
inside the bounds; the barrier moves
an optimum whose bounds are inactive by about μ_end / (slack · curvature), below tol.
"""

from __future__ import annotations

import numpy as np

from fccgrb_cli.core.blas import lapack
from fccgrb_cli.solvers.newton import Iterate
from fccgrb_cli.system import Drive, System

DELTA = 1e-6
FEASIBLE_TOP = 1e-11  # max |Φ_top| at a converged frame (m and dimensionless)
MAX_ITER = 50
FAR = 1e-3  # max |Φ_top| of a guess that goes through NRM-WLS before the SQP (optimize/frame.py)


def sqp_weights(system: System, point_weights: np.ndarray) -> np.ndarray:
    """W of the eliminated system: 1 on the topological rows, 2δ w_n on each tracked element's
    three rows (0 where its marker is missing)."""
    w = np.where(system.kinds == 0, 1.0, 0.0)
    start = 3 * len(system.lin_a)
    w[start:start + 3 * len(point_weights)] = 2.0 * DELTA * np.repeat(point_weights, 3)
    return w


def stabilized_sqp(system: System, q0: np.ndarray, drive: Drive, weights: np.ndarray,
                   tol: float, max_iter: int = MAX_ITER, bounds: Bounds | None = None) -> Iterate:
    """One frame (``weights`` from :func:`sqp_weights`): steps until ‖Δq‖∞ < tol with
    max |Φ_top| ≤ FEASIBLE_TOP at the result; with ``bounds`` (lower, upper), the interior
    point, which also waits for μ to reach μ_end."""
    top = system.kinds == 0
    q = q0.copy()
    shift = np.zeros(system.n_rows)
    barrier = None if bounds is None else Barrier.start(q, *bounds, tol)
    size = np.inf
    for k in range(max_iter + 1):
        phi, J = system.evaluate(q, drive)
        violation = np.abs(phi[top]).max(initial=0.0)
        if size < tol and violation <= FEASIBLE_TOP and (barrier is None or barrier.done):
            return Iterate(q, k, True)
        if k == max_iter:
            break
        r = weights * (phi + shift)
        normal = J.T @ (weights[:, None] * J)
        rhs = -(J.T @ r)
        if barrier is not None:
            barrier.add_terms(q, normal, rhs)
        _, step, info = lapack.dposv(normal + system.residual_hessian(q, shift), rhs)
        if info != 0:
            _, step, info = lapack.dposv(normal, rhs)
        if info != 0:
            return Iterate(q, k + 1, False)
        size = np.abs(step).max()
        if not np.isfinite(size):
            return Iterate(q, k + 1, False)
        alpha = 1.0 if barrier is None else barrier.advance(q, step)
        shift = np.where(top, shift + alpha * (phi + J @ step), 0.0)
        q = q + alpha * step
    return Iterate(q, max_iter, False)


Bounds = tuple[np.ndarray, np.ndarray]
MU_START = 1e-6
MU_END = 1e-3  # × tol
KAPPA, THETA = 0.2, 1.5
TAU = 0.995


class Barrier:
    """The interior point's state beside the SQP's: μ, the bounded coordinates' indices and
    bounds, and their multipliers z_l, z_u (module doc)."""

    def __init__(self, lower: np.ndarray, upper: np.ndarray, tol: float, q: np.ndarray):
        self.lo, self.hi = np.flatnonzero(np.isfinite(lower)), np.flatnonzero(np.isfinite(upper))
        self.lower, self.upper = lower[self.lo], upper[self.hi]
        self.mu, self.mu_end = MU_START, MU_END * tol
        self.zl = self.mu / (q[self.lo] - self.lower)
        self.zu = self.mu / (self.upper - q[self.hi])

    @classmethod
    def start(cls, q: np.ndarray, lower: np.ndarray, upper: np.ndarray, tol: float) -> Barrier:
        """The barrier at q, which is first moved inside the bounds (in place) by 1e-6 of
        each bounded range, or of 1 where only one side is bounded."""
        span = np.where(np.isfinite(upper - lower), upper - lower, 1.0)
        np.clip(q, lower + 1e-6 * span, upper - 1e-6 * span, out=q)
        return cls(lower, upper, tol, q)

    @property
    def done(self) -> bool:
        return self.mu <= self.mu_end

    def slacks(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return q[self.lo] - self.lower, self.upper - q[self.hi]

    def add_terms(self, q: np.ndarray, normal: np.ndarray, rhs: np.ndarray) -> None:
        """δΣ on the normal matrix's diagonal and δ(μ/s_l − μ/s_u) on the right-hand side."""
        sl, su = self.slacks(q)
        normal[self.lo, self.lo] += DELTA * self.zl / sl
        normal[self.hi, self.hi] += DELTA * self.zu / su
        rhs[self.lo] += DELTA * self.mu / sl
        rhs[self.hi] -= DELTA * self.mu / su

    def advance(self, q: np.ndarray, step: np.ndarray) -> float:
        """Update the bound multipliers (their own fraction to the boundary) and μ; returns
        the primal step length α (fraction to the boundary of the slacks)."""
        sl, su = self.slacks(q)
        dl, du = step[self.lo], -step[self.hi]
        dzl = (self.mu - self.zl * sl - self.zl * dl) / sl
        dzu = (self.mu - self.zu * su - self.zu * du) / su
        alpha = _to_boundary(np.concatenate([sl, su]), np.concatenate([dl, du]))
        alpha_z = _to_boundary(np.concatenate([self.zl, self.zu]), np.concatenate([dzl, dzu]))
        self.zl, self.zu = self.zl + alpha_z * dzl, self.zu + alpha_z * dzu
        self.mu = max(self.mu_end, min(KAPPA * self.mu, self.mu**THETA))
        return alpha


def _to_boundary(x: np.ndarray, dx: np.ndarray) -> float:
    """The largest α ≤ 1 with x + α dx ≥ (1 − τ) x (x > 0)."""
    shrinking = dx < 0
    if not shrinking.any():
        return 1.0
    return float(min(1.0, (-TAU * x[shrinking] / dx[shrinking]).min()))

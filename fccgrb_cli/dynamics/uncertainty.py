"""How uncertain each joint moment is: the smoother's covariance of the driver coordinates and
their rates, carried through the inverse dynamics linearized at each frame (FORMULATION §4).

The moments τ(d, ḋ, d̈) of a frame are those of the classical model driven by d, ḋ, d̈:
q̇ solves Φ_q q̇ = ν, q̈ solves Φ_q q̈ = γ, λ solves Φ_qᵀλ = Q − M q̈ and τ_k = −g′(θ_k) λ_k
(dynamics/inverse.py). Their Jacobian T = ∂τ/∂(d, ḋ, d̈) (angles × 3n) is taken column by
column:

* d̈: τ is linear in d̈ (q̈ is, and λ is in q̈), so τ(d̈ + e_k) − τ(d̈) is exact;
* ḋ: τ is quadratic in ḋ (q̇ = S ḋ, γ is quadratic in q̇ and in the drivers' rates), so the
  central difference with a unit step is exact;
* d: forward differentiation along the motion q' = S_k (S = ∂q/∂d), d' = e_k, on the same
  factor: q̇' = Φ_q⁻¹ (ν' − Φ_q' q̇), q̈' = Φ_q⁻¹ (γ' − Φ_q' q̈), λ' = Φ_q⁻ᵀ (b' − Φ_q'ᵀ λ)
  with b = Q − M q̈, the explicit functions' derivatives (Φ_q, ν, γ, b: no solve inside) by
  central differences of step h = ``STEP`` (exact for Φ_q, linear in q; O(h²) for the rest).
  Where Φ_q is taller (a floating base's drivers), λ' is the minimum-norm solution: it may
  differ from the minimum-norm λ's derivative by a multiplier of the redundant base rows,
  which no joint's moment reads.

Every column shares the frame's factor of Φ_q (its inverse, or the QR of a taller one). The
moments' covariance per frame is T Σ Tᵀ, Σ the smoother's (frames × 3n × 3n).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from fccgrb_cli.dynamics.loads import ExternalLoad
from fccgrb_cli.dynamics.mass import gravity_forces, mass_matrix
from fccgrb_cli.solvers.batched import Drives, Stacked
from fccgrb_cli.solvers.smooth.coordinates import Coordinates

STEP = 1e-5  # rad or m: the central differences in d


@dataclass(frozen=True)
class MomentUncertainty:
    """T = ∂τ/∂(d, ḋ, d̈) per frame (frames × angles × 3n, derivative-major columns) and the
    moments' covariance (frames × angles × angles; N·m, N for a distance's joint force)."""

    jacobian: np.ndarray
    covariance: np.ndarray

    @property
    def sd(self) -> np.ndarray:
        """Standard deviations (frames × angles)."""
        return np.sqrt(np.maximum(np.diagonal(self.covariance, axis1=1, axis2=2), 0.0))


class _Frames:
    """The classical system at positions q of every frame, factored once: solves with Φ_q
    (least squares where taller) and Φ_qᵀ (minimum norm), several right-hand sides at once."""

    def __init__(self, coordinates: Coordinates, q: np.ndarray,
                 loads: Sequence[ExternalLoad]) -> None:
        system = coordinates.system
        self.coordinates, self.q, self.loads = coordinates, q, loads
        self.stacked = Stacked(system)
        self.J = self.stacked.jacobian(q)
        self.square = self.J.shape[1] == self.J.shape[2]
        if self.square:  # one factorization for every right-hand side to come
            self.inverse = np.linalg.inv(self.J)
        else:
            self.Q, self.R = np.linalg.qr(self.J)
        model = system.model
        self.M = mass_matrix(model)
        self.g = gravity_forces(model)

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """Φ_q X = rhs (frames × rows × k → frames × nq × k)."""
        if self.square:
            return np.matmul(self.inverse, rhs)
        return np.linalg.solve(self.R, np.matmul(self.Q.transpose(0, 2, 1), rhs))

    def solve_transposed(self, rhs: np.ndarray) -> np.ndarray:
        """Φ_qᵀ Y = rhs (frames × nq × k → frames × rows × k), minimum norm."""
        if self.square:
            return np.matmul(self.inverse.transpose(0, 2, 1), rhs)
        return np.matmul(self.Q, np.linalg.solve(self.R.transpose(0, 2, 1), rhs))

    def balance(self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> np.ndarray:
        """Q − M q̈ on q (X_qᵀ (Q_x − M_x ẍ), ẍ = X_q q̈ + V̇ q̇): the right-hand side of
        Φ_qᵀ λ (frames × nq)."""
        system, stacked = self.coordinates.system, self.stacked
        x = stacked.expand(q)
        xq = stacked.expand_jacobian(q)
        forces = np.tile(self.g, (len(q), 1))
        frames = np.arange(len(q))
        for load in self.loads:
            s = system.layout.x_offset(load.body)
            forces[:, s:s + 12] += load.generalized(x[:, s:s + 12], frames)
        xdd = qdd if xq is None else np.einsum("fxq,fq->fx", xq, qdd)
        rhs = forces - (xdd + stacked.expand_bias(qd)) @ self.M.T
        return rhs if xq is None else np.einsum("fxq,fx->fq", xq, rhs)

    def motion(self, drives: list[Drives]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """q̇, q̈ and λ (frames × · × k) for each of the drives, at these positions."""
        stacked, q = self.stacked, self.q
        qd = self.solve(np.stack([stacked.nu(dr) for dr in drives], axis=2))
        gamma = np.stack([stacked.gamma(q, qd[:, :, k], dr) for k, dr in enumerate(drives)],
                         axis=2)
        qdd = self.solve(gamma)
        rhs = np.stack([self.balance(q, qd[:, :, k], qdd[:, :, k])
                        for k in range(len(drives))], axis=2)
        return qd, qdd, self.solve_transposed(rhs)


def _joint_moments(system, lam: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """τ_k = −g′(θ_k) λ_k, and a signed angle's sine row (inverse.inverse_dynamics)."""
    moments = -system.g_terms(theta)[1] * lam[:, system.n_linear_rows + system.angle_rows]
    if len(system.sine_rows):
        k = system.sine_of
        moments[:, k] -= np.cos(theta[:, k]) * lam[:, system.n_linear_rows + system.sine_rows]
    return moments


def moments_at(coordinates: Coordinates, q: np.ndarray, d: np.ndarray, d_d: np.ndarray,
               d_dd: np.ndarray, loads: Sequence[ExternalLoad] = ()) -> np.ndarray:
    """τ (frames × angles) of the classical model at positions q driven by d, ḋ, d̈."""
    drives = coordinates.drives(d, d_d, d_dd)
    lam = _Frames(coordinates, q, loads).motion([drives])[2][:, :, 0]
    return _joint_moments(coordinates.system, lam, drives.theta)


def _position_column(frames: _Frames, S_k: np.ndarray, d: np.ndarray, d_d: np.ndarray,
                     d_dd: np.ndarray, k: int, base: tuple[np.ndarray, ...]) -> np.ndarray:
    """∂τ/∂d_k by forward differentiation along q' = S_k, d' = e_k, on the frame's own
    factor: q̇' = Φ_q⁻¹ (ν' − Φ_q' q̇), q̈' = Φ_q⁻¹ (γ' − Φ_q' q̈), λ' = Φ_q⁻ᵀ (b' − Φ_q'ᵀ λ),
    the explicit functions' derivatives (Φ_q, ν, γ, b = Q − M q̈) by central differences."""
    co, stacked, q = frames.coordinates, frames.stacked, frames.q
    system = co.system
    qd, qdd, lam = base
    h = STEP
    step = np.zeros_like(d)
    step[:, k] = h
    plus, minus = co.drives(d + step, d_d, d_dd), co.drives(d - step, d_d, d_dd)
    Jd = (stacked.jacobian(q + h * S_k) - stacked.jacobian(q - h * S_k)) / (2 * h)
    nu_d = (stacked.nu(plus) - stacked.nu(minus)) / (2 * h)
    qd_d = frames.solve((nu_d - np.einsum("frq,fq->fr", Jd, qd))[:, :, None])[:, :, 0]
    gamma_d = (stacked.gamma(q + h * S_k, qd + h * qd_d, plus)
               - stacked.gamma(q - h * S_k, qd - h * qd_d, minus)) / (2 * h)
    qdd_d = frames.solve((gamma_d - np.einsum("frq,fq->fr", Jd, qdd))[:, :, None])[:, :, 0]
    b_d = (frames.balance(q + h * S_k, qd + h * qd_d, qdd + h * qdd_d)
           - frames.balance(q - h * S_k, qd - h * qd_d, qdd - h * qdd_d)) / (2 * h)
    lam_d = frames.solve_transposed((b_d - np.einsum("frq,fr->fq", Jd, lam))[:, :, None])
    lam_d = lam_d[:, :, 0]
    return (_joint_moments(system, lam + h * lam_d, plus.theta)
            - _joint_moments(system, lam - h * lam_d, minus.theta)) / (2 * h)


def moment_jacobian(coordinates: Coordinates, q: np.ndarray, S: np.ndarray, d: np.ndarray,
                    d_d: np.ndarray, d_dd: np.ndarray,
                    loads: Sequence[ExternalLoad] = ()) -> np.ndarray:
    """T (frames × angles × 3n; see the module's docstring). ``S``: ∂q/∂d at q."""
    n = coordinates.n
    system = coordinates.system
    frames = _Frames(coordinates, q, loads)
    drives = [coordinates.drives(d, d_d, d_dd)]
    for k in range(n):
        unit = np.zeros_like(d)
        unit[:, k] = 1.0
        drives += [coordinates.drives(d, d_d + unit, d_dd), coordinates.drives(d, d_d - unit, d_dd),
                   coordinates.drives(d, d_d, d_dd + unit)]
    qd, qdd, lam = frames.motion(drives)
    tau = np.stack([_joint_moments(system, lam[:, :, k], dr.theta)
                    for k, dr in enumerate(drives)], axis=2)
    base = tau[:, :, 0]
    T = np.empty((*base.shape, 3 * n))
    for k in range(n):
        T[:, :, n + k] = (tau[:, :, 1 + 3 * k] - tau[:, :, 2 + 3 * k]) / 2.0
        T[:, :, 2 * n + k] = tau[:, :, 3 + 3 * k] - base
        T[:, :, k] = _position_column(frames, S[:, :, k], d, d_d, d_dd, k,
                                      (qd[:, :, 0], qdd[:, :, 0], lam[:, :, 0]))
    return T


def moment_uncertainty(coordinates: Coordinates, q: np.ndarray, S: np.ndarray, d: np.ndarray,
                       d_d: np.ndarray, d_dd: np.ndarray, covariance: np.ndarray,
                       loads: Sequence[ExternalLoad] = ()) -> MomentUncertainty:
    """The moments' covariance T Σ Tᵀ of every frame."""
    T = moment_jacobian(coordinates, q, S, d, d_d, d_dd, loads)
    return MomentUncertainty(T, np.einsum("fai,fij,fbj->fab", T, covariance, T))

"""How uncertain each joint moment is: the smoother's covariance of the driver coordinates and
their rates, carried through the inverse dynamics linearized at each frame
(docs/formulation.md §13).

The moments τ(d, ḋ, d̈) of a frame are those of the classical model driven by d, ḋ, d̈:
q̇ solves Φ_q q̇ = ν, q̈ solves Φ_q q̈ = γ, λ solves Φ_qᵀλ = Q − M q̈ and τ_k = −g′(θ_k) λ_k
(dynamics/inverse.py). Their Jacobian T = ∂τ/∂(d, ḋ, d̈) (angles × 3n) is taken column by
column:

* d̈: τ is linear in d̈ (q̈ is, and λ is in q̈), so τ(d̈ + e_k) − τ(d̈) is exact;
* ḋ: τ is quadratic in ḋ (q̇ = S ḋ, γ is quadratic in q̇ and in the drivers' rates), so the
  central difference with a unit step is exact;
* d: forward differentiation along the motion q' = S_k (S = ∂q/∂d), d' = e_k, on the same
  factor: q̇' = Φ_q⁻¹ (ν' − Φ_q' q̇), q̈' = Φ_q⁻¹ (γ' − Φ_q' q̈), λ' = Φ_q⁻ᵀ (b' − Φ_q'ᵀ λ)
  with b = Q − M q̈, the explicit functions' derivatives (ν, γ, b: no solve inside) by
  central differences of step h = ``STEP`` (O(h²)); Φ_q', linear in q' for fully-defined
  bodies, in closed form from the features of S_k (:class:`_Along`; reduced bodies: central
  differences too).
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
BLOCK = 64  # frames


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


def _variants(values: np.ndarray, k: int) -> np.ndarray:
    """frames·k × … (variant-major) → frames × … × k."""
    return np.moveaxis(values.reshape(k, -1, *values.shape[1:]), 0, -1)


class _Frames:
    """The classical system at positions q of a block of frames, factored once: solves with Φ_q
    (least squares where taller) and Φ_qᵀ (minimum norm), several right-hand sides at once;
    Φ_q, ν, γ and the right-hand side of Φ_qᵀλ evaluated for several variants of the frames at
    once (the variants stacked along the frames)."""

    def __init__(self, coordinates: Coordinates, q: np.ndarray,
                 loads: Sequence[ExternalLoad], frames: np.ndarray) -> None:
        system = coordinates.system
        self.coordinates, self.q, self.loads, self.frames = coordinates, q, loads, frames
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
        Φ_qᵀ λ, for stacked variants of the block's frames (variants·frames × nq)."""
        system, stacked = self.coordinates.system, self.stacked
        x = stacked.expand(q)
        xq = stacked.expand_jacobian(q)
        forces = np.tile(self.g, (len(q), 1))
        frames = np.tile(self.frames, len(q) // len(self.frames))
        for load in self.loads:
            s = system.layout.x_offset(load.body)
            forces[:, s:s + 12] += load.generalized(x[:, s:s + 12], frames)
        xdd = qdd if xq is None else np.einsum("fxq,fq->fx", xq, qdd)
        rhs = forces - (xdd + stacked.expand_bias(qd)) @ self.M.T
        return rhs if xq is None else np.einsum("fxq,fx->fq", xq, rhs)

    def motion(self, both: Drives, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """q̇, q̈ and λ (frames × · × k) for k variants of the frames' drives (stacked,
        variant-major), at these positions."""
        stacked = self.stacked
        q = np.tile(self.q, (k, 1))
        qd = self.solve(_variants(stacked.nu(both), k))
        qd_flat = np.moveaxis(qd, -1, 0).reshape(len(q), -1)
        qdd = self.solve(_variants(stacked.gamma(q, qd_flat, both), k))
        qdd_flat = np.moveaxis(qdd, -1, 0).reshape(len(q), -1)
        lam = self.solve_transposed(_variants(self.balance(q, qd_flat, qdd_flat), k))
        return qd, qdd, lam


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
    frames = _Frames(coordinates, q, loads, np.arange(len(q)))
    return _joint_moments(coordinates.system, frames.motion(drives, 1)[2][:, :, 0],
                          drives.theta)


def _block_jacobian(frames: _Frames, S: np.ndarray, d: np.ndarray, d_d: np.ndarray,
                    d_dd: np.ndarray) -> np.ndarray:
    """T of one block of frames (see moment_jacobian)."""
    co = frames.coordinates
    system = co.system
    n = co.n
    B = len(d)
    # the variants: as they are, then per coordinate ḋ + e_k, ḋ − e_k, d̈ + e_k
    k = 1 + 3 * n
    rate, accel = np.zeros((k, n)), np.zeros((k, n))
    rate[1::3][np.arange(n), np.arange(n)] = 1.0
    rate[2::3][np.arange(n), np.arange(n)] = -1.0
    accel[3::3][np.arange(n), np.arange(n)] = 1.0
    drives = co.drives(np.tile(d, (k, 1)), (d_d[None] + rate[:, None]).reshape(k * B, n),
                       (d_dd[None] + accel[:, None]).reshape(k * B, n))
    qd, qdd, lam = frames.motion(drives, k)
    theta = drives.theta.reshape(k, B, -1)
    tau = np.stack([_joint_moments(system, lam[:, :, j], theta[j]) for j in range(k)], axis=2)
    T = np.empty((*tau.shape[:2], 3 * n))
    T[:, :, n:2 * n] = (tau[:, :, 1::3] - tau[:, :, 2::3]) / 2.0
    T[:, :, 2 * n:] = tau[:, :, 3::3] - tau[:, :, :1]
    T[:, :, :n] = _position_columns(frames, S, (d, d_d, d_dd),
                                    (qd[:, :, 0], qdd[:, :, 0], lam[:, :, 0]))
    return T


def _position_columns(frames: _Frames, S: np.ndarray, state: tuple[np.ndarray, ...],
                      base: tuple[np.ndarray, ...]) -> np.ndarray:
    """∂τ/∂d_k for every k by forward differentiation along q' = S_k, d' = e_k on the block's
    own factor: q̇' = Φ_q⁻¹ (ν' − Φ_q' q̇), q̈' = Φ_q⁻¹ (γ' − Φ_q' q̈), λ' = Φ_q⁻ᵀ (b' − Φ_q'ᵀ λ),
    the explicit functions' derivatives (Φ_q, ν, γ, b = Q − M q̈) by central differences, the
    2n moved variants of the block evaluated at once."""
    co, stacked, q = frames.coordinates, frames.stacked, frames.q
    system = co.system
    d, d_d, d_dd = state
    qd, qdd, lam = base
    n, h = co.n, STEP
    B = len(q)
    moved = np.concatenate([q[None] + sign * h * np.moveaxis(S, 2, 0)
                            for sign in (1.0, -1.0)]).reshape(2 * n * B, -1)
    steps = np.concatenate([sign * h * np.eye(n) for sign in (1.0, -1.0)])
    drives = co.drives((d[None] + steps[:, None]).reshape(2 * n * B, n),
                       np.tile(d_d, (2 * n, 1)), np.tile(d_dd, (2 * n, 1)))
    along = _Along(frames, S, moved)
    nu = stacked.nu(drives).reshape(2, n, B, -1)
    nu_d = (nu[0] - nu[1]) / (2 * h)
    rhs = nu_d - along.times(qd)
    qd_d = np.moveaxis(frames.solve(np.moveaxis(rhs, 0, -1)), -1, 0)  # n × B × nq
    qd_moved = np.concatenate([qd[None] + sign * h * qd_d for sign in (1.0, -1.0)])
    gamma = stacked.gamma(moved, qd_moved.reshape(2 * n * B, -1), drives).reshape(2, n, B, -1)
    rhs = (gamma[0] - gamma[1]) / (2 * h) - along.times(qdd)
    qdd_d = np.moveaxis(frames.solve(np.moveaxis(rhs, 0, -1)), -1, 0)
    qdd_moved = np.concatenate([qdd[None] + sign * h * qdd_d for sign in (1.0, -1.0)])
    b = frames.balance(moved, qd_moved.reshape(2 * n * B, -1),
                       qdd_moved.reshape(2 * n * B, -1)).reshape(2, n, B, -1)
    rhs = (b[0] - b[1]) / (2 * h) - along.transposed_times(lam)
    lam_d = np.moveaxis(frames.solve_transposed(np.moveaxis(rhs, 0, -1)), -1, 0)
    out = np.empty((B, len(system.angle_rows), n))
    theta = drives.theta.reshape(2, n, B, -1)
    for k in range(n):
        out[:, :, k] = (_joint_moments(system, lam + h * lam_d[k], theta[0, k])
                        - _joint_moments(system, lam - h * lam_d[k], theta[1, k])) / (2 * h)
    return out


class _Along:
    """Φ_q' = ∂Φ_q/∂d_k along q' = S_k for every k (n × frames × rows × nq), as products.
    Fully-defined bodies: Φ_q = Φ_x is affine in x = q, the linear rows constant and a dot
    row's F_bᵀA_a + F_aᵀA_b (Eq. 2–3), so Φ_q' is exactly the dot rows' G_bᵀA_a + G_aᵀA_b with
    G = A S_k, and its products with a vector v or with λ follow from the features of v without
    forming the matrices (a block's 2n moved Jacobians took two thirds of the uncertainty's
    time on the gait trial). Reduced bodies (X_q depends on q): the central difference of the
    moved Jacobians (step ``STEP``)."""

    def __init__(self, frames: _Frames, S: np.ndarray, moved: np.ndarray) -> None:
        stacked = frames.stacked
        system = stacked.system
        self.system, self.n_lin = system, system.n_linear_rows
        self.exact = stacked.expand_jacobian(frames.q[:1]) is None and \
            system.nq == system.layout.nx
        n, B = S.shape[2], len(frames.q)
        if self.exact:  # G = A S_k: frames' features of each direction, without f0
            self.G = (np.moveaxis(S, 2, 0) @ system.A_flat.T).reshape(n, B, -1, 3)
            self.blocks = stacked._dot_blocks.reshape(len(system.dot_a) * 6, -1)
        else:
            J = stacked.jacobian(moved).reshape(2, n, B, *frames.J.shape[1:])
            self.Jd = (J[0] - J[1]) / (2 * STEP)

    def times(self, v: np.ndarray) -> np.ndarray:
        """Φ_q' v (n × frames × rows) for v (frames × nq)."""
        if not self.exact:
            return np.einsum("kfrq,fq->kfr", self.Jd, v)
        s = self.system
        Fv = (v @ s.A_flat.T).reshape(len(v), -1, 3)
        out = np.zeros((*self.G.shape[:2], s.n_rows))
        out[:, :, self.n_lin:] = (np.einsum("kfdj,fdj->kfd", self.G[:, :, s.dot_b], Fv[:, s.dot_a])
                                  + np.einsum("kfdj,fdj->kfd", self.G[:, :, s.dot_a],
                                              Fv[:, s.dot_b]))
        return out

    def transposed_times(self, lam: np.ndarray) -> np.ndarray:
        """Φ_q'ᵀ λ (n × frames × nq) for λ (frames × rows)."""
        if not self.exact:
            return np.einsum("kfrq,fr->kfq", self.Jd, lam)
        s = self.system
        partners = np.concatenate([self.G[:, :, s.dot_b], self.G[:, :, s.dot_a]], axis=3)
        weighted = partners * lam[None, :, self.n_lin:, None]
        n, B = weighted.shape[:2]
        return (weighted.reshape(n * B, -1) @ self.blocks).reshape(n, B, -1)


def moment_jacobian(coordinates: Coordinates, q: np.ndarray, S: np.ndarray, d: np.ndarray,
                    d_d: np.ndarray, d_dd: np.ndarray,
                    loads: Sequence[ExternalLoad] = ()) -> np.ndarray:
    """T (frames × angles × 3n; see the module's docstring), ``BLOCK`` frames at a time (the
    moved variants of a block hold 2n Jacobians a frame). ``S``: ∂q/∂d at q."""
    n = coordinates.n
    T = np.empty((len(q), len(coordinates.system.angle_rows), 3 * n))
    for start in range(0, len(q), BLOCK):
        part = slice(start, min(len(q), start + BLOCK))
        frames = _Frames(coordinates, q[part], loads, np.arange(len(q))[part])
        T[part] = _block_jacobian(frames, S[part], d[part], d_d[part], d_dd[part])
    return T


def moment_uncertainty(coordinates: Coordinates, q: np.ndarray, S: np.ndarray, d: np.ndarray,
                       d_d: np.ndarray, d_dd: np.ndarray, covariance: np.ndarray,
                       loads: Sequence[ExternalLoad] = ()) -> MomentUncertainty:
    """The moments' covariance T Σ Tᵀ of every frame (two stacked matrix products: einsum's
    three-operand loop took 0.17 s on the gait trial)."""
    T = moment_jacobian(coordinates, q, S, d, d_d, d_dd, loads)
    return MomentUncertainty(T, T @ covariance @ T.transpose(0, 2, 1))

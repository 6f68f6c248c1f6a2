"""A small rigid motion of the whole body, frame by frame, that lowers the residual for the least
added marker misfit (the kinematic half of the residual reduction).

Moving every body of a floating group by the same rigid motion keeps every joint angle and
every joint equation: it is a correction of the floating base's trajectory alone. At frame t
the correction is a translation δr_t and a small rotation θ_t about the group's centre of mass
c_t (6 numbers, δ_t); its rates come by the same central differences as the motion's
(``rates.central_derivatives``). To first order the residual r_t = [F_t; M_t] and the markers'
misfit e_t change as

    r_t + J⁰_t δ_t + J¹_t δ̇_t + J²_t δ̈_t,     e_k,t + δr_t + θ_t × (p_k,t − c_t),

J⁰, J¹, J² from the residual of the rigidly moved motion (``residuals.whole_body_residual``;
polynomial in δ, so central differences give its derivatives exactly). δ minimizes

    Σ_{t measured} ‖r_t + J_t δ‖²_W + Σ_{t not measured} ‖J_t δ‖²_W
        + Σ_t ‖J_{t+1} δ − 2 J_t δ + J_{t−1} δ‖²_W + Σ_t (1/σ²) mean_k ‖e_k,t + Δp_k,t‖²,

W = diag(1/σ_F², 1/σ_M²): the residual where every contact is measured; no change of it where a
contact is not (the correction adds no acceleration there); the bend, frame to frame, of the
change the correction makes to the residual (without it the correction would switch on and off
at the edges of the measured stretches within a frame: a step in the accelerations, and so in
the joint moments; a second difference leaves a smooth change, however fast, nearly free); and
the mean squared marker misfit (the quantity whose RMS is reported).
σ_F = 0.5 % of body weight, σ_M = 0.5 % of body weight × 1 m and σ = 2 mm: a residual that
size costs as much as a marker misfit of 2 mm, the growth of marker RMS a lab accepts (on the
Qualisys walking trial the reduction then adds 0.3 mm to the markers' RMS over the trial). A
sparse symmetric system (6 unknowns per frame, banded by the difference stencils).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from fccgrb_cli.dynamics.loads import ExternalLoad
from fccgrb_cli.dynamics.residuals import BodyMotion, whole_body_residual
from fccgrb_cli.model import Model
from fccgrb_cli.system import System
from fccgrb_cli.system.layout import skew

FORCE_SCALE = 0.005  # σ_F: 0.5 % of body weight (N)
MOMENT_SCALE = 0.005  # σ_M: 0.5 % of body weight × 1 m (N·m)
MARKER_SCALE = 0.002  # σ: 2 mm of marker misfit (m)


@dataclass(frozen=True)
class RigidCorrection:
    """Per frame: a translation (frames × 3, m) and a rotation vector (frames × 3, rad) about
    ``centre`` (frames × 3, m)."""

    translation: np.ndarray
    rotation: np.ndarray
    centre: np.ndarray

    def rotations(self) -> np.ndarray:
        """R_t = exp([θ_t]×) (frames × 3 × 3), by Rodrigues' formula."""
        angle = np.linalg.norm(self.rotation, axis=1)
        axis = np.divide(self.rotation, angle[:, None], out=np.zeros_like(self.rotation),
                         where=angle[:, None] > 0)
        k = skew(axis)
        s, c = np.sin(angle)[:, None, None], np.cos(angle)[:, None, None]
        return np.eye(3) + s * k + (1.0 - c) * (k @ k)

    def apply(self, system: System, q: np.ndarray) -> np.ndarray:
        """q (frames × nq) with every body moved: r → R (r − c) + c + δr, u, v (, w) → R u ..."""
        out = q.copy()
        R = self.rotations()
        layout = system.layout
        for name in layout.body_names:
            block = out[:, layout.q_slice(name)]
            parts = block.reshape(len(q), -1, 3)
            rotated = np.einsum("fij,fkj->fki", R, parts - np.concatenate(
                [self.centre[:, None], np.zeros_like(parts[:, 1:])], axis=1))
            rotated[:, 0] += self.centre + self.translation
            out[:, layout.q_slice(name)] = rotated.reshape(len(q), -1)
        return out


def _moved(motion: BodyMotion, centre: np.ndarray, rates: tuple[np.ndarray, np.ndarray],
           d: tuple[np.ndarray, np.ndarray, np.ndarray]) -> BodyMotion:
    """The motion rigidly moved by δ (value, rate, acceleration: frames × 6 each) to first
    order in the rotation: X' = X + δr e₁ᵀ + [θ]×(X − c e₁ᵀ), and its derivatives."""
    cd, cdd = rates
    d0, d1, d2 = d

    def arm(X: np.ndarray, c: np.ndarray) -> np.ndarray:
        out = X.copy()
        out[:, :, :, 0] -= c[:, None, :]
        return out

    def spin(theta: np.ndarray, X: np.ndarray) -> np.ndarray:
        return np.einsum("fij,fbjk->fbik", skew(theta[:, 3:]), X)

    def shift(v: np.ndarray) -> np.ndarray:
        out = np.zeros_like(motion.X)
        out[:, :, :, 0] = v[:, None, :3]
        return out

    X0, X1, X2 = arm(motion.X, centre), arm(motion.Xd, cd), arm(motion.Xdd, cdd)
    X = motion.X + shift(d0) + spin(d0, X0)
    Xd = motion.Xd + shift(d1) + spin(d1, X0) + spin(d0, X1)
    Xdd = motion.Xdd + shift(d2) + spin(d2, X0) + 2.0 * spin(d1, X1) + spin(d0, X2)
    return BodyMotion(motion.names, X, Xd, Xdd)


def _difference_operators(n: int, dt: float):
    """Sparse D1, D2 (n × n): central_derivatives' stencils as matrices."""
    from scipy.sparse import lil_matrix

    D1, D2 = lil_matrix((n, n)), lil_matrix((n, n))
    for t in range(1, n - 1):
        D1[t, t - 1], D1[t, t + 1] = -0.5 / dt, 0.5 / dt
        D2[t, t - 1], D2[t, t], D2[t, t + 1] = 1 / dt**2, -2 / dt**2, 1 / dt**2
    D1[0, :3] = np.array([-3.0, 4.0, -1.0]) / (2 * dt)
    D1[n - 1, n - 3:] = np.array([1.0, -4.0, 3.0]) / (2 * dt)
    D2[0, :4] = np.array([2.0, -5.0, 4.0, -1.0]) / dt**2
    D2[n - 1, n - 4:] = np.array([-1.0, 4.0, -5.0, 2.0]) / dt**2
    return D1.tocsr(), D2.tocsr()


def centre_of_mass(motion: BodyMotion, K: np.ndarray) -> tuple[np.ndarray, ...]:
    """The group's CoM and its rates (frames × 3 each): Σ X_i K_i e₁ / Σ m_i."""
    m = K[:, 0, 0].sum()
    return tuple(np.einsum("fbcj,bj->fc", X, K[:, 0, :]) / m
                 for X in (motion.X, motion.Xd, motion.Xdd))


@dataclass(frozen=True)
class CorrectionData:
    """What one correction step needs: the motion the dynamics used, its bodies' inertia
    coefficients K, the external loads, the measured frames (boolean), the tracked model
    points and their markers (frames × markers × 3; NaN where a marker is missing), the body
    weight (N) and the frame rate (Hz)."""

    motion: BodyMotion
    K: np.ndarray
    loads: Sequence[ExternalLoad]
    measured: np.ndarray
    points: np.ndarray
    markers: np.ndarray
    weight: float
    rate: float


def correction_step(model: Model, data: CorrectionData) -> RigidCorrection:
    """The rigid correction δ of every frame minimizing the module's objective (one
    Gauss–Newton step from the given motion)."""
    from scipy.sparse import block_diag, diags, kron
    from scipy.sparse import eye as speye
    from scipy.sparse.linalg import spsolve

    motion, n = data.motion, len(data.motion.X)
    centre, cd, cdd = centre_of_mass(motion, data.K)
    zero = np.zeros((n, 6))
    force, moment = whole_body_residual(model, motion, data.K, data.loads)
    r0 = np.concatenate([force[:, 0], moment[:, 0]], axis=1)
    step = 1e-6
    J = np.zeros((3, n, 6, 6))  # J[order][t] = ∂r_t/∂δ^(order)_t
    for order in range(3):
        for j in range(6):
            d = [zero.copy(), zero.copy(), zero.copy()]
            d[order][:, j] = step
            plus = whole_body_residual(model, _moved(motion, centre, (cd, cdd), tuple(d)),
                                       data.K, data.loads)
            d[order][:, j] = -step
            minus = whole_body_residual(model, _moved(motion, centre, (cd, cdd), tuple(d)),
                                        data.K, data.loads)
            J[order, :, :, j] = np.concatenate([plus[0][:, 0] - minus[0][:, 0],
                                                plus[1][:, 0] - minus[1][:, 0]], 1) / (2 * step)
    D1, D2 = _difference_operators(n, 1.0 / data.rate)
    I6 = speye(6)
    A = (block_diag(list(J[0])) + block_diag(list(J[1])) @ kron(D1, I6)
         + block_diag(list(J[2])) @ kron(D2, I6))
    w = np.repeat([1.0 / (FORCE_SCALE * data.weight), 1.0 / (MOMENT_SCALE * data.weight)], 3)
    W = diags(np.tile(w, n))
    target = np.where(data.measured[:, None], r0, 0.0).ravel()
    WA = W @ A
    bend = diags([np.ones(n - 2), -2 * np.ones(n - 2), np.ones(n - 2)], [0, 1, 2],
                 shape=(n - 2, n))  # the second difference from frame to frame
    step_change = diags(np.tile(w, n - 2)) @ kron(bend, I6) @ A
    lhs = WA.T @ WA + step_change.T @ step_change
    rhs = -(WA.T @ (W @ target))
    # markers: Δp = δr + θ × d = [I, −[d]×] δ per marker, mean over the markers seen
    d = data.points - centre[:, None]
    e = data.points - data.markers
    seen = np.isfinite(e).all(axis=2)
    blocks, grads = [], np.zeros((n, 6))
    for t in range(n):
        k = seen[t]
        if not k.any():
            blocks.append(np.zeros((6, 6)))
            continue
        G = np.concatenate([np.tile(np.eye(3), (k.sum(), 1, 1)), -skew(d[t, k])], axis=2)
        scale = 1.0 / (MARKER_SCALE**2 * k.sum())
        blocks.append(scale * np.einsum("kij,kil->jl", G, G))
        grads[t] = scale * np.einsum("kij,ki->j", G, e[t, k])
    lhs = lhs + block_diag(blocks)
    delta = spsolve(lhs.tocsc(), rhs - grads.ravel()).reshape(n, 6)
    return RigidCorrection(delta[:, :3], delta[:, 3:], centre)

"""Segment masses and centres of mass that make a floating base's residual smallest.

The residual wrench is linear in every body's inertia coefficients K_i (``dynamics.residuals``):
r_t = Σ_i A_i(t) vec(K_i) + b_t, A_i(t) from the motion alone, b_t from the external loads.
Each body's K_i is written in its mass m_i and centre of mass c_i with its radii of gyration kept
(the inertia tensor scales with the mass, I_i = m_i ρ_i):

    K_i = m_i [[1, c_iᵀ], [c_i, c_i c_iᵀ + ρ̃_i]],   ρ̃_i = ½ tr(ρ_i) 1 − ρ_i,

and the fit is the bounded nonlinear least squares (scipy.optimize.least_squares, trust-region
reflective with the analytic Jacobian) of the residuals over the measured frames, with a pull
towards the first model that keeps directions the motion does not excite where they were:

    min Σ_t ‖F_t/σ_F‖² + ‖M_t/σ_M‖² + Σ_i [(m_i − m⁰_i)/(π m⁰_i)]² + ‖(c_i − c⁰_i)/(κ L_i)‖²
    s.t. |m_i − m⁰_i| ≤ β m⁰_i,  |c_i − c⁰_i| ≤ γ L_i per axis,

β = MASS_BOUND, γ = COM_BOUND, π = MASS_PRIOR, κ = COM_PRIOR and L_i the body's size (the
largest distance between its named points, its origin and its CoM). The mass's pull is loose
(50 %): a segment the motion barely tells from its neighbour (the pelvis from the thorax) would
otherwise stay near a wrong first guess. The CoM's (3 % of the size, about the spread of de
Leva's CoM fractions between subjects) is tight: a CoM and a mass trade against each other (the
first moment m c is what much of the residual sees), and a loose CoM lets noise move the
masses.

σ_F and σ_M are the residual's own noise level, estimated from the data (empirical Bayes): 1 %
of body weight (N, and N·m over 1 m) to start, then the RMS residual component the last fit
left (floored at 0.1 %), inflated by √(n / n_eff) for a residual correlated in time
(:func:`independent`), ROUNDS fits in all. On data the segment inertia explains (a synthetic
trial with wrong masses and white noise) the residual falls to its noise and the data
outweigh the pull; on data whose residual comes mostly from elsewhere (soft-tissue motion,
filtering: smooth, so few independent samples) the pull keeps the masses from running to the
bounds to chase it.

Writing K_i in (m, m c) would make the problem linear (lsq_linear) but turn the box on c into
coupled constraints and drop the coupling of the inertia tensor to the mass; in (m, c) the
bounds are the stated boxes and the problem is mildly nonlinear (a few iterations from the
first model).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from fccgrb_cli.dynamics.loads import ExternalLoad
from fccgrb_cli.dynamics.residuals import (
    BodyMotion,
    generalized_loads,
    gravity_matrix,
    groups,
    rigid_wrench,
)
from fccgrb_cli.model import Model

MASS_BOUND = 0.25  # a segment's mass stays within ±25 % of the first model's
MASS_PRIOR = 0.5  # the pull's standard deviation for a mass: 50 % of the first model's
COM_BOUND = 0.10  # its CoM within ±10 % of its size along each body axis
COM_PRIOR = 0.03  # the pull's standard deviation for a CoM: 3 % of the body's size
ROUNDS = 3  # fits, each weighing the residual by the noise level the last one left
NOISE_FLOOR = 0.001  # the residual's noise level is at least 0.1 % of body weight


@dataclass(frozen=True)
class InertiaFit:
    """Masses (bodies, kg) and CoMs (bodies × 3, local, m) before and after the fit, the
    adjusted K (bodies × 4 × 4, the system's body order), each body's size L (m), and the
    optimizer's verdict."""

    names: tuple[str, ...]
    mass0: np.ndarray
    mass: np.ndarray
    com0: np.ndarray
    com: np.ndarray
    K: np.ndarray
    size: np.ndarray
    success: bool
    message: str

    def tensor(self, k: int, tensor0: np.ndarray) -> np.ndarray:
        """Body k's adjusted inertia tensor about its CoM: the first one scaled by the mass."""
        return tensor0 * self.mass[k] / self.mass0[k]


def body_size(model: Model, name: str) -> float:
    """The largest distance between a body's named points, its origin and its CoM (m)."""
    body = model.body(name)
    points = [np.zeros(3), *(np.asarray(p.local) for p in body.points.values())]
    if body.inertia is not None:
        points.append(np.asarray(body.inertia.com, float))
    pts = np.array(points)
    return float(np.max(np.linalg.norm(pts[:, None] - pts[None], axis=2)))


def regressors(model: Model, motion: BodyMotion, loads: Sequence[ExternalLoad],
               frames: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A (frames × 6 × bodies × 16) and b (frames × 6): the residual wrench [F; M] of the base
    at each frame is Σ_i A[:, :, i] vec(K_i) + b (one floating base)."""
    bases = groups(model)
    if len(bases) != 1:
        raise ValueError("the inertia fit takes one floating base")
    base, members = next(iter(bases.items()))
    n = len(motion.X)
    origin = motion.X[:, motion.index(base), :, 0]
    rows = [motion.index(b) for b in members]
    accel = (gravity_matrix(model, n) - motion.Xdd)[frames]  # (G − Ẍ), frames × bodies × 3 × 4
    X = motion.X[frames]
    A = np.zeros((len(frames), 6, len(motion.names), 16))
    for b in rows:
        for j in range(4):
            column = accel[:, b, :, j]  # Q's column k when K = E_jk
            for k in range(4):
                lever = X[:, b, :, 0] - origin[frames] if k == 0 else X[:, b, :, k]
                if k == 0:
                    A[:, :3, b, 4 * j + k] = -column
                A[:, 3:, b, 4 * j + k] = -np.cross(lever, column)
    Q = generalized_loads(motion, loads)[frames][:, rows]
    force, moment = rigid_wrench(Q, X[:, rows], origin[frames])
    return A, -np.concatenate([force, moment], axis=1)


def independent(residual: np.ndarray) -> float:
    """How many independent samples a residual series (frames × components) holds: n (1 − ρ)
    / (1 + ρ), ρ its lag-1 autocorrelation (an AR(1) series' effective sample size), at least
    1. Smooth residuals (filtered motion, soft tissue) carry far fewer independent errors than
    frames; white noise as many."""
    centred = residual - residual.mean(axis=0)
    power = np.sum(centred ** 2)
    if len(residual) < 3 or power == 0:
        return float(len(residual))
    rho = float(np.clip(np.sum(centred[1:] * centred[:-1]) / power, 0.0, 0.999))
    return max(1.0, len(residual) * (1.0 - rho) / (1.0 + rho))


def _coefficients(mass: np.ndarray, com: np.ndarray, rho: np.ndarray) -> np.ndarray:
    """K_i = m_i [[1, cᵀ], [c, c cᵀ + ρ̃_i]] (bodies × 4 × 4)."""
    K = np.empty((len(mass), 4, 4))
    K[:, 0, 0] = 1.0
    K[:, 0, 1:] = K[:, 1:, 0] = com
    K[:, 1:, 1:] = np.einsum("bi,bj->bij", com, com) + rho
    return K * mass[:, None, None]


def fit_inertia(model: Model, motion: BodyMotion, loads: Sequence[ExternalLoad],
                frames: np.ndarray, weight: float) -> InertiaFit:
    """The masses and CoMs that minimize the residual over ``frames`` (indices or a boolean
    mask), within the bounds (module docstring); ``weight``: the body weight (N) that scales the
    first noise level."""
    from scipy.optimize import least_squares

    frames = np.flatnonzero(frames) if np.asarray(frames).dtype == bool else np.asarray(frames)
    names = motion.names
    inertias = []
    for name in names:
        inertia = model.body(name).inertia
        assert inertia is not None  # the residual's mass matrices required it
        inertias.append(inertia)
    mass0 = np.array([i.mass for i in inertias])
    com0 = np.array([i.com for i in inertias], dtype=float)
    tensors = np.array([i.tensor for i in inertias], dtype=float)
    rho = np.array([0.5 * np.trace(t) * np.eye(3) - t for t in tensors]) / mass0[:, None, None]
    size = np.array([body_size(model, n) for n in names])
    A, b = regressors(model, motion, loads, frames)
    nb = len(names)
    A2 = A.reshape(len(frames) * 6, nb, 16)
    b2 = b.ravel()
    noise = np.full(6, 0.01 * weight)
    sigma = np.tile(noise, len(frames))
    scale_m, scale_c = MASS_PRIOR * mass0, np.maximum(COM_PRIOR * size, 1e-9)

    def unpack(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return p[:nb], p[nb:].reshape(nb, 3)

    def fun(p: np.ndarray) -> np.ndarray:
        mass, com = unpack(p)
        K = _coefficients(mass, com, rho).reshape(nb, 16)
        data = (np.einsum("rbk,bk->r", A2, K) + b2) / sigma
        prior = np.concatenate([(mass - mass0) / scale_m,
                                ((com - com0) / scale_c[:, None]).ravel()])
        return np.concatenate([data, prior])

    def jac(p: np.ndarray) -> np.ndarray:
        mass, com = unpack(p)
        dm = _coefficients(np.ones(nb), com, rho).reshape(nb, 16)
        J = np.zeros((len(b2) + 4 * nb, 4 * nb))
        J[: len(b2), :nb] = np.einsum("rbk,bk->rb", A2, dm) / sigma[:, None]
        for axis in range(3):
            e = np.zeros((nb, 4, 4))
            e[:, 0, 1 + axis] = e[:, 1 + axis, 0] = 1.0
            e[:, 1 + axis, 1:] += com
            e[:, 1:, 1 + axis] += com
            dc = (e * mass[:, None, None]).reshape(nb, 16)
            J[: len(b2), nb + np.arange(nb) * 3 + axis] = \
                np.einsum("rbk,bk->rb", A2, dc) / sigma[:, None]
        J[len(b2) + np.arange(nb), np.arange(nb)] = 1.0 / scale_m
        J[len(b2) + nb + np.arange(3 * nb), nb + np.arange(3 * nb)] = \
            np.repeat(1.0 / scale_c, 3)
        return J

    low = np.concatenate([(1.0 - MASS_BOUND) * mass0, (com0 - COM_BOUND * size[:, None]).ravel()])
    high = np.concatenate([(1.0 + MASS_BOUND) * mass0,
                           (com0 + COM_BOUND * size[:, None]).ravel()])
    fixed = high <= low  # a body of no size keeps its CoM
    high = np.where(fixed, low + 1e-12, high)
    p = np.concatenate([mass0, com0.ravel()])
    for _ in range(ROUNDS):
        solution = least_squares(fun, p, jac=jac, bounds=(low, high), method="trf",
                                 x_scale="jac", ftol=1e-12, xtol=1e-12, gtol=1e-12)
        p = solution.x
        left = (fun(p)[: len(b2)] * sigma).reshape(len(frames), 6)
        noise = np.maximum(np.sqrt(np.mean(left.reshape(-1, 2, 3) ** 2, axis=(0, 2))),
                           NOISE_FLOOR * weight)
        sigma = np.tile(np.repeat(noise, 3) * np.sqrt(len(frames) / independent(left)),
                        len(frames))
    mass, com = unpack(p)
    return InertiaFit(names, mass0, mass, com0, com, _coefficients(mass, com, rho), size,
                      bool(solution.success), str(solution.message))

"""The linear smoother of the whole trial, in numpy: the reference the compiled kernels
(``kernels.py``) equal to rounding.

Every driver coordinate k (n of them) carries the integrated-Wiener-process state of
``prior.py`` (p numbers, scaled by its own frequency); the trial's state stacks them, x_f ∈ R^(np),
coordinate-major (x[k p + j] = d_k^(j) / ω_k^j). The prior couples a frame to the next, one
coordinate at a time (block-diagonal F and Q); the markers couple the coordinates within a frame,
through the information they carry about d (frames × n × n matrices A_f and vectors b_f: a frame
says A_f d_f ≈ b_f; A_f = 0 where it says nothing — a gap, an untrusted frame). A may be
singular (markers that fix only some coordinates).

Three passes, each O(frames):

1. Kalman filter, forward (covariance form, the update in information form):
   B = E P⁻ Eᵀ, U = P⁻ Eᵀ, G = I + A B, ν = G⁻¹ (b − A E x⁻), M = G⁻¹ A (= (A⁻¹ + B)⁻¹),
   x⁺ = x⁻ + U ν, P⁺ = P⁻ − U M Uᵀ (computed in Joseph's form C P⁻ Cᵀ + U N Uᵀ, with C and N
   of step 3: the short form drifts off positive definite over hundreds of frames),
   x⁻ ← F x⁺, P⁻ ← F P⁺ Fᵀ + Q. E picks each coordinate's d.
2. Modified Bryson–Frazier smoother, backward (Bierman 1977): C = I − U M E,
   λ̃ = −Eᵀ ν + Cᵀ Fᵀ λ̃₊, Ω = Eᵀ M E + Cᵀ Fᵀ Ω₊ F C, the smoothed state x⁻ − P⁻ λ̃ and
   its posterior covariance P⁻ − P⁻ Ω P⁻.
3. The covariance of the smoothed outputs that the marker noise alone causes (the estimate's
   scatter over repeated trials, which is what a Monte-Carlo over noise measures; the posterior
   covariance of step 2 adds the prior's own spread, which overstates a motion smoother than the
   prior — 1.4× in d̈'s standard deviation on the five-bar, as 1/√(1 − 5/(2p)) says for a steady
   smoother). With the noise of b (covariance A) as the only random input, x⁻ (noise part)
   has covariance Π⁻: Π⁻ ← F (C Π⁻ Cᵀ + U N Uᵀ) Fᵀ, N = G⁻¹ A G⁻ᵀ; λ̃ = Ω x⁻ + ρ with ρ
   driven by the present and future noise only, Cov ρ = Γ = a N aᵀ + Cᵀ Fᵀ Γ₊ F C,
   a = Cᵀ Fᵀ Ω₊ F U − Eᵀ; so the smoothed state x⁻ − P⁻ λ̃ = (I − P⁻ Ω) x⁻ − P⁻ ρ has
   Ξ = (I − P⁻ Ω) Π⁻ (I − P⁻ Ω)ᵀ + P⁻ Γ P⁻.

Outputs: per frame d, ḋ and d̈ of every coordinate (scaled back) and the covariance Ξ of those
3n numbers; tests compare both with the dense solution of the same least squares.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fccgrb_cli.solvers.smooth.arrays import ChainArrays
from fccgrb_cli.solvers.smooth.prior import DERIVATIVES, noise_shape, transition


@dataclass(frozen=True)
class Chains:
    """The prior of every coordinate (n of them, order p): F and Q = q C per coordinate
    (n × p × p, scaled units), each one's scaling frequency ω (rad/s), and the first frame's
    prior: the mean (n × p) and covariance (n × p × p) of each coordinate's state, scaled units
    (see ``start.initial_state``)."""

    F: np.ndarray
    Q: np.ndarray
    scale: np.ndarray
    mean0: np.ndarray
    cov0: np.ndarray

    @classmethod
    def build(cls, order: int, dt: float, scale: np.ndarray, density: np.ndarray,
              mean0: np.ndarray, cov0: np.ndarray) -> Chains:
        """Chains of the given order for coordinates with scaling frequencies ``scale``
        (rad/s) and spectral densities ``density`` (q, in the coordinate's unit² / s^(2p−1))."""
        F = np.array([transition(order, dt, w) for w in scale])
        Q = np.array([q * noise_shape(order, dt, w) for q, w in zip(density, scale, strict=True)])
        return cls(F, Q, np.asarray(scale, float), np.asarray(mean0, float),
                   np.asarray(cov0, float))

    @property
    def n(self) -> int:
        return self.F.shape[0]

    @property
    def order(self) -> int:
        return self.F.shape[1]

    def arrays(self):
        """The kernels' ChainArrays (kernels.py)."""
        return ChainArrays(self.F, self.Q, np.ascontiguousarray(self.mean0.ravel()), self.cov0)

    def unscale(self) -> np.ndarray:
        """ω^j for every output (3n, derivative-major: d of all coordinates, then ḋ, then d̈)."""
        j = np.arange(DERIVATIVES)[:, None]
        return (self.scale[None, :] ** j).ravel()

    def outputs(self) -> np.ndarray:
        """The state indices of the outputs (3n, derivative-major)."""
        p = self.order
        return (np.arange(self.n)[None, :] * p + np.arange(DERIVATIVES)[:, None]).ravel()


@dataclass(frozen=True)
class Smoothed:
    """The smoother's answer: per frame the outputs (frames × 3 × n: d, ḋ, d̈ of every
    coordinate, in its units per s^j) and, when asked, the covariance their noise part has
    (frames × 3n × 3n, derivative-major) and the posterior covariance (the same shape)."""

    values: np.ndarray
    covariance: np.ndarray | None = None
    posterior: np.ndarray | None = None


def _blocks(blocks: np.ndarray) -> np.ndarray:
    """The block-diagonal matrix (np × np) of n blocks p × p."""
    n, p = blocks.shape[:2]
    out = np.zeros((n * p, n * p))
    for k in range(n):
        out[k * p:(k + 1) * p, k * p:(k + 1) * p] = blocks[k]
    return out


def _dense(chains: Chains) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """F, Q (np × np, block-diagonal) and E (n × np)."""
    n, p = chains.n, chains.order
    E = np.zeros((n, n * p))
    E[np.arange(n), np.arange(n) * p] = 1.0
    return _blocks(chains.F), _blocks(chains.Q), E


def smooth(chains: Chains, A: np.ndarray, b: np.ndarray, *, covariance: bool = True,
           posterior: bool = False) -> Smoothed:
    """The smoothed outputs of the trial whose frames carry information A_f d_f ≈ b_f (A:
    frames × n × n, b: frames × n, in the coordinates' units; A_f = 0 where a frame carries
    none); ``covariance``: the noise part's covariance of the outputs (step 3 of the module's
    docstring); ``posterior``: the Bayesian posterior covariance too (for the tests)."""
    n, p = chains.n, chains.order
    N = len(A)
    F, Q, E = _dense(chains)
    x = chains.mean0.ravel().copy()
    P = _blocks(chains.cov0)
    x_pred = np.empty((N, n * p))
    P_pred = np.empty((N, n * p, n * p))
    nu = np.zeros((N, n))
    M = np.zeros((N, n, n))
    Nn = np.zeros((N, n, n))
    eye = np.eye(n)
    for f in range(N):
        if f:
            x = F @ x
            P = F @ P @ F.T + Q
        x_pred[f], P_pred[f] = x, P
        if not A[f].any():
            continue
        U = P @ E.T
        G = eye + A[f] @ (E @ U)
        nu[f] = np.linalg.solve(G, b[f] - A[f] @ (E @ x))
        m = np.linalg.solve(G, A[f])
        M[f] = 0.5 * (m + m.T)
        Nn[f] = np.linalg.solve(G, np.linalg.solve(G, A[f]).T)
        Nn[f] = 0.5 * (Nn[f] + Nn[f].T)
        x = x + U @ nu[f]
        C = np.eye(n * p) - U @ M[f] @ E
        P = C @ P @ C.T + U @ Nn[f] @ U.T  # Joseph's form (P − U M Uᵀ drifts off, see tests)
    out = chains.outputs()
    values = np.empty((N, DERIVATIVES * n))
    shape = (N, DERIVATIVES * n, DERIVATIVES * n)
    cov = np.empty(shape) if covariance else None
    post = np.empty(shape) if posterior else None
    lam = np.zeros(n * p)  # λ̂ = Fᵀ λ̃₊ (0 after the last frame)
    Lam = np.zeros((n * p, n * p))  # Λ̂ = Fᵀ Ω₊ F
    Gam = np.zeros((n * p, n * p))  # Γ̂ = Fᵀ Γ₊ F
    kept = []  # per frame (rows of I − P⁻Ω at the outputs, P⁻ Γ P⁻ there) for step 3
    for f in range(N - 1, -1, -1):
        U = P_pred[f] @ E.T
        C = np.eye(n * p) - U @ M[f] @ E
        lam_t = -E.T @ nu[f] + C.T @ lam
        Om = E.T @ M[f] @ E + C.T @ Lam @ C
        values[f] = (x_pred[f] - P_pred[f] @ lam_t)[out]
        Prow = P_pred[f][out]
        if posterior:
            assert post is not None  # made when posterior
            post[f] = P_pred[f][np.ix_(out, out)] - Prow @ Om @ Prow.T
        if covariance:
            a = C.T @ Lam @ U - E.T
            Ga = a @ Nn[f] @ a.T + C.T @ Gam @ C
            kept.append((np.eye(n * p)[out] - Prow @ Om, Prow @ Ga @ Prow.T))
            Gam = F.T @ Ga @ F
        lam = F.T @ lam_t
        Lam = F.T @ Om @ F
    if covariance:
        kept.reverse()
        Pi = np.zeros((n * p, n * p))
        for f in range(N):
            if f:
                Pi = F @ Pi @ F.T
            T, tail = kept[f]
            assert cov is not None  # made when covariance
            cov[f] = T @ Pi @ T.T + tail
            U = P_pred[f] @ E.T
            C = np.eye(n * p) - U @ M[f] @ E
            Pi = C @ Pi @ C.T + U @ Nn[f] @ U.T
    unscale = chains.unscale()
    values = (values * unscale).reshape(N, DERIVATIVES, n)
    if cov is not None:
        cov = cov * unscale[:, None] * unscale[None, :]
    if post is not None:
        post = post * unscale[:, None] * unscale[None, :]
    return Smoothed(values, cov, post)


def log_likelihood(z: np.ndarray, variance: np.ndarray, F: np.ndarray, Q: np.ndarray,
                   mean0: np.ndarray, cov0: np.ndarray, skip: int) -> float:
    """log p(z) (up to a constant) of one coordinate's measurements z (frames; variance inf
    where none) under its chain (F, Q: p × p; first frame's prior mean0, cov0), by the Kalman
    filter's prediction errors;
    the first ``skip`` measured frames, which fix the vague start, are left out (the diffuse
    likelihood)."""
    p = len(F)
    x = mean0.astype(float).copy()
    P = np.array(cov0, dtype=float)
    total, seen = 0.0, 0
    for f in range(len(z)):
        if f:
            x = F @ x
            P = F @ P @ F.T + Q
        r = variance[f]
        if not np.isfinite(r):
            continue
        S = P[0, 0] + r
        v = z[f] - x[0]
        K = P[:, 0] / S
        if seen >= skip:
            total -= 0.5 * (np.log(S) + v * v / S)
        seen += 1
        x = x + K * v
        C = np.eye(p)
        C[:, 0] -= K
        P = C @ P @ C.T + r * np.outer(K, K)
    return total

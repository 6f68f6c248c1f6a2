"""Compiled passes of the whole-trial smoother (numba): the same three passes as
``filter.smooth`` (its docstring gives the equations) and the same scalar filter as
``filter.log_likelihood``, on plain arrays.

The prior's F and Q are block-diagonal with upper-triangular blocks (one p × p block per
coordinate), so F P Fᵀ costs ~n² p³ instead of 2 (np)³ (loops); C = I − U M E changes a
matrix by low-rank terms (n or 2n columns), which go to BLAS as thin matrix products. Kept
per frame between the passes: the output rows of P⁻ (3n × np; overwritten by the rows of
I − P⁻Ω once the backward pass has used them), U, M, N, ν and P⁻ Γ P⁻ at the outputs
(3n × 3n).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from fccgrb_cli.solvers.smooth.arrays import ChainArrays


@njit(cache=True)
def _predict(F: np.ndarray, P: np.ndarray, work: np.ndarray) -> None:
    """P ← F P Fᵀ, F block-diagonal with upper-triangular blocks (n × p × p)."""
    n, p = F.shape[0], F.shape[1]
    m = n * p
    for k in range(n):
        for i in range(p):
            row = work[k * p + i]
            row[:] = 0.0
            for j in range(i, p):
                a = F[k, i, j]
                src = P[k * p + j]
                for c in range(m):
                    row[c] += a * src[c]
    for r in range(m):
        src = work[r]
        dst = P[r]
        for k in range(n):
            for i in range(p):
                total = 0.0
                for j in range(i, p):
                    total += src[k * p + j] * F[k, i, j]
                dst[k * p + i] = total


@njit(cache=True)
def _predict_t(F: np.ndarray, P: np.ndarray, work: np.ndarray) -> None:
    """P ← Fᵀ P F for the same F."""
    n, p = F.shape[0], F.shape[1]
    m = n * p
    for k in range(n):
        for i in range(p):
            row = work[k * p + i]
            row[:] = 0.0
            for j in range(i + 1):
                a = F[k, j, i]
                src = P[k * p + j]
                for c in range(m):
                    row[c] += a * src[c]
    for r in range(m):
        src = work[r]
        dst = P[r]
        for k in range(n):
            for i in range(p):
                total = 0.0
                for j in range(i + 1):
                    total += src[k * p + j] * F[k, j, i]
                dst[k * p + i] = total


@njit(cache=True)
def _apply(F: np.ndarray, x: np.ndarray, out: np.ndarray, transpose: bool) -> None:
    """out = F x (Fᵀ x with ``transpose``)."""
    n, p = F.shape[0], F.shape[1]
    for k in range(n):
        for i in range(p):
            total = 0.0
            if transpose:
                for j in range(i + 1):
                    total += F[k, j, i] * x[k * p + j]
            else:
                for j in range(i, p):
                    total += F[k, i, j] * x[k * p + j]
            out[k * p + i] = total


@njit(cache=True)
def _c_x_ct(X: np.ndarray, U: np.ndarray, M: np.ndarray, N: np.ndarray, p: int) -> None:
    """X ← C X Cᵀ + U N Uᵀ for C = I − U M E (E picks each coordinate's first state):
    X + [U V] [[M (E X Eᵀ) M + N, −M], [−M, 0]] [U V]ᵀ with V = X Eᵀ, one rank-2n product."""
    m, n = U.shape
    W = np.empty((m, 2 * n))
    W[:, :n] = U
    for a in range(n):
        W[:, n + a] = X[:, a * p]
    XE = np.empty((n, n))
    for a in range(n):
        for c in range(n):
            XE[a, c] = X[a * p, c * p]
    K = np.zeros((2 * n, 2 * n))
    K[:n, :n] = M @ XE @ M + N
    K[:n, n:] = -M
    K[n:, :n] = -M
    X += (W @ K) @ W.T


@njit(cache=True)
def _ct_x_c(X: np.ndarray, U: np.ndarray, M: np.ndarray, p: int) -> np.ndarray:
    """X ← Cᵀ X C for the same C (only the n rows and columns of the coordinates' first states
    change: X − Eᵀ M Uᵀ X − X U M E + Eᵀ M (Uᵀ X U) M E); returns X U (before the change)."""
    n = U.shape[1]
    XU = X @ U
    XUM = XU @ M
    inner = M @ (U.T @ XU) @ M
    for a in range(n):
        X[:, a * p] -= XUM[:, a]
    for a in range(n):
        X[a * p, :] -= XUM[:, a]
    for a in range(n):
        for c in range(n):
            X[a * p, c * p] += inner[a, c]
    return XU


@njit(cache=True)
def _symmetrize(X: np.ndarray) -> None:
    """X ← (X + Xᵀ)/2: a rounding asymmetry left in the covariances grows from frame to frame
    unless removed (the tests saw 10⁻¹³ become 10¹³ over 400 frames without it)."""
    m = X.shape[0]
    for r in range(m):
        for c in range(r + 1, m):
            v = 0.5 * (X[r, c] + X[c, r])
            X[r, c] = v
            X[c, r] = v


@njit(cache=True)
def smooth_passes(chain: ChainArrays, A: np.ndarray, b: np.ndarray, covariance: bool,
                  values: np.ndarray, cov: np.ndarray) -> None:
    """The three passes of filter.smooth in scaled units (the caller unscales): ``values``
    (frames × 3n, derivative-major) and, with ``covariance``, ``cov`` (frames × 3n × 3n)."""
    F, Q, mean0, cov0 = chain
    n, p = F.shape[0], F.shape[1]
    m = n * p
    N = A.shape[0]
    o = 3 * n
    out = np.empty(o, dtype=np.int64)
    for j in range(3):
        for k in range(n):
            out[j * n + k] = k * p + j
    rows = np.empty((N, o, m))
    Us = np.empty((N, m, n))
    xs = np.empty((N, o))
    nus = np.zeros((N, n))
    Ms = np.zeros((N, n, n))
    Ns = np.zeros((N, n, n))
    tails = np.empty((N if covariance else 0, o, o))
    x = mean0.copy()
    P = np.zeros((m, m))
    for k in range(n):
        P[k * p:(k + 1) * p, k * p:(k + 1) * p] = cov0[k]
    work = np.empty((m, m))
    xw = np.empty(m)
    eye = np.eye(n)
    B = np.empty((n, n))
    Ex = np.empty(n)
    for f in range(N):
        if f:
            _apply(F, x, xw, False)
            x[:] = xw
            _predict(F, P, work)
            for k in range(n):
                for i in range(p):
                    for j in range(p):
                        P[k * p + i, k * p + j] += Q[k, i, j]
        for r in range(o):
            rows[f, r] = P[out[r]]
            xs[f, r] = x[out[r]]
        for a in range(n):
            Us[f, :, a] = P[:, a * p]
        if not np.any(A[f] != 0.0):
            continue
        U = Us[f]
        for a in range(n):
            Ex[a] = x[a * p]
            for c in range(n):
                B[a, c] = U[a * p, c]
        G = eye + A[f] @ B
        nus[f] = np.linalg.solve(G, b[f] - A[f] @ Ex)
        Mf = np.linalg.solve(G, A[f])
        Ms[f] = 0.5 * (Mf + Mf.T)
        Nf = np.linalg.solve(G, np.linalg.solve(G, A[f]).T)
        Ns[f] = 0.5 * (Nf + Nf.T)
        x += U @ nus[f]
        # Joseph's form C P Cᵀ + U N Uᵀ, which is P − U K Uᵀ with K = 2M − M B M − N (= M in
        # exact arithmetic, and like Joseph's first-order insensitive to M's rounding: the
        # short form P − U M Uᵀ drifts off positive definite over hundreds of frames)
        K = 2.0 * Ms[f] - Ms[f] @ B @ Ms[f] - Ns[f]
        K = 0.5 * (K + K.T)
        P -= (U @ K) @ U.T
        _symmetrize(P)
    lam = np.zeros(m)
    lam_t = np.empty(m)
    Lam = np.zeros((m, m))
    Gam = np.zeros((m, m))
    a_mat = np.empty((m, n))
    for f in range(N - 1, -1, -1):
        U, Mf = Us[f], Ms[f]
        corr = Mf @ (U.T @ lam)  # λ̃ = −Eᵀν + Cᵀλ̂, Cᵀλ̂ = λ̂ − Eᵀ M Uᵀ λ̂
        lam_t[:] = lam
        for a in range(n):
            lam_t[a * p] -= nus[f, a] + corr[a]
        Prow = rows[f]
        values[f] = xs[f] - Prow @ lam_t
        _apply(F, lam_t, lam, True)
        if not covariance:
            continue
        LU = _ct_x_c(Lam, U, Mf, p)  # Ω = Eᵀ M E + Cᵀ Λ̂ C; LU = Λ̂ U
        corr2 = Mf @ (U.T @ LU)  # a = Cᵀ Λ̂ U − Eᵀ
        a_mat[:, :] = LU
        for a in range(n):
            for c in range(n):
                a_mat[a * p, c] -= corr2[a, c]
            a_mat[a * p, a] -= 1.0
        for a in range(n):
            for c in range(n):
                Lam[a * p, c * p] += Mf[a, c]
        _symmetrize(Lam)
        _ct_x_c(Gam, U, Mf, p)  # Γ = a N aᵀ + Cᵀ Γ̂ C
        Gam += (a_mat @ Ns[f]) @ a_mat.T
        _symmetrize(Gam)
        tails[f] = (Prow @ Gam) @ Prow.T
        T = -(Prow @ Lam)
        for r in range(o):
            T[r, out[r]] += 1.0
        rows[f] = T
        _predict_t(F, Gam, work)
        _predict_t(F, Lam, work)
    if not covariance:
        return
    Pi = np.zeros((m, m))
    for f in range(N):
        if f:
            _predict(F, Pi, work)
        T = rows[f]
        cov[f] = (T @ Pi) @ T.T + tails[f]
        if np.any(Ms[f] != 0.0):
            _c_x_ct(Pi, Us[f], Ms[f], Ns[f], p)
            _symmetrize(Pi)


@njit(cache=True)
def log_likelihood(z: np.ndarray, variance: np.ndarray, F: np.ndarray, Q: np.ndarray,
                   mean0: np.ndarray, cov0: np.ndarray, skip: int) -> float:
    """filter.log_likelihood, compiled (F upper-triangular)."""
    p = F.shape[0]
    x = mean0.copy()
    xw = np.empty(p)
    P = cov0.copy()
    W = np.empty((p, p))
    total = 0.0
    seen = 0
    for f in range(len(z)):
        if f:
            for i in range(p):
                s = 0.0
                for j in range(i, p):
                    s += F[i, j] * x[j]
                xw[i] = s
            x[:] = xw
            for i in range(p):
                for c in range(p):
                    s = 0.0
                    for j in range(i, p):
                        s += F[i, j] * P[j, c]
                    W[i, c] = s
            for r in range(p):
                for i in range(p):
                    s = 0.0
                    for j in range(i, p):
                        s += W[r, j] * F[i, j]
                    P[r, i] = s + Q[r, i]
        r = variance[f]
        if not np.isfinite(r):
            continue
        S = P[0, 0] + r
        if not S > 0.0:
            return -np.inf
        v = z[f] - x[0]
        if seen >= skip:
            total -= 0.5 * (np.log(S) + v * v / S)
        seen += 1
        for i in range(p):
            xw[i] = P[i, 0] / S  # the gain K; P ← (I − K e₀ᵀ) P (I − K e₀ᵀ)ᵀ + r K Kᵀ
        for i in range(p):
            x[i] += xw[i] * v
        p00 = P[0, 0]
        for i in range(p):
            W[i] = P[i]
        for i in range(p):
            for c in range(p):
                P[i, c] = (W[i, c] - xw[i] * W[0, c] - W[i, 0] * xw[c]
                           + xw[i] * xw[c] * (p00 + r))
    return total

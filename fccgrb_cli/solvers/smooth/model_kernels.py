"""The measurement model of ``coordinates.py`` compiled (numba), for classical systems with
fully-defined bodies: per frame, Newton–Raphson on Φ(q; d) = 0 from a guess (the normal
equations on NRM's envelope, as kernels.driven_frames does it; after the first factorization
chord steps on it while they contract by ``CHORD_RATE``, until max |Φ| < ``RESIDUAL``: the
smoother's guesses are q + S Δd from the iterate before, ~Δd² off), then the sensitivity
S = ∂q/∂d column by column on the same factor (Φ_qᵀΦ_q S_k = Φ_qᵀ ν_k: exact for a square Φ_q,
least squares for a taller one whose equations hold), the tracked points and their Jacobian
H = C S. The numpy path (coordinates.Coordinates.linearize) is the reference; the tests compare.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from fccgrb_cli.solvers.kernels import cholesky, jacobian, normal_equations, residual, substitute
from fccgrb_cli.solvers.smooth.arrays import Linearization, Points, SmoothedDrivers
from fccgrb_cli.system.sparse import SparseSystem

RESIDUAL = 1e-13  # max |Φ| (m, or unit-vector components) that ends a frame's iteration
CHORD_RATE = 0.1  # a chord step must shrink the step before it this much, else factor afresh


@njit(cache=True)
def _largest(v: np.ndarray) -> float:
    """‖v‖∞ (inf where v holds a NaN)."""
    out = 0.0
    for x in v:
        if not abs(x) <= out:
            out = abs(x) if np.isfinite(x) else np.inf
    return out


@njit(cache=True)
def _unit_nu(s: SparseSystem, theta: np.ndarray, k: int, n_angles: int,
             base_unit: np.ndarray, nu: np.ndarray) -> None:
    """ν of a unit rate of coordinate k: g′(θ_k) on its angle's row (cos θ_k on a sine row),
    or the floating bases' features' rates ∂ref/∂d_k (``base_unit``: slots × 3) on their rows."""
    nu[:] = 0.0
    if k < n_angles:
        for i in range(len(s.angle_rows)):
            if i == k:
                nu[s.n_lin + s.angle_rows[i]] = 1.0 if s.distance[i] else -np.sin(theta[i])
        for j in range(len(s.sine_rows)):
            if s.sine_of[j] == k:
                nu[s.n_lin + s.sine_rows[j]] = np.cos(theta[k])
        return
    for t in range(len(s.trk_slot)):
        for a in range(3):
            nu[s.trk_start + 3 * t + a] = base_unit[s.trk_slot[t], a]


@njit(cache=True)
def linearize_frames(s: SparseSystem, drivers: SmoothedDrivers, tracked: Points, max_iter: int,
                     out_arrays: Linearization) -> None:
    """Every frame: q from its guess (max |Φ(q; θ, ref)| < RESIDUAL), S (nq × n),
    the tracked points and H (3 markers × n)."""
    guesses, theta, ref, base_units = drivers
    offsets, local = tracked
    q_out, S_out, points, H, converged = out_arrays
    n_rows, nq = len(s.c_const) + len(s.dot_c), s.nq
    n_angles = theta.shape[1]
    n = S_out.shape[2]
    F = np.empty(len(s.f0))
    values = np.empty(len(s.j_col))
    N, L = np.zeros((nq, nq)), np.zeros((nq, nq))
    w, phi, nu = np.ones(n_rows), np.empty(n_rows), np.empty(n_rows)
    g, out, q = np.empty(nq), np.empty(nq), np.empty(nq)
    empty = np.zeros((0, 3))
    for f in range(len(guesses)):
        q[:] = guesses[f]
        ok = factored = refresh = False
        previous = np.inf
        for _ in range(max_iter):
            residual(s, q, theta[f], ref[f], F, phi)
            if factored and _largest(phi) < RESIDUAL:
                ok = True
                break
            if factored and not refresh:  # a chord step on the frame's factor
                for p in range(nq):
                    g[p] = 0.0
                for r in range(n_rows):
                    for m in range(s.j_ptr[r], s.j_ptr[r + 1]):
                        g[s.j_col[m]] += values[m] * phi[r]
            else:
                jacobian(s, q, F, values)
                normal_equations(s, values, phi, w, N, g)
                factored = cholesky(s.first, N, L)
                if not factored:
                    break
            substitute(s.first, L, g, out)
            size = 0.0
            for p in range(nq):
                q[s.perm[p]] -= out[p]
                size = max(size, abs(out[p]))
            if not np.isfinite(size):
                break
            refresh = size > CHORD_RATE * previous  # slow contraction: factor afresh
            previous = size
        if not ok:
            continue
        converged[f] = True
        q_out[f] = q
        for k in range(n):  # on the factor of the last step (‖Δq‖ < tol away)
            unit = base_units[f, k - n_angles] if k >= n_angles else empty
            _unit_nu(s, theta[f], k, n_angles, unit, nu)
            for p in range(nq):
                g[p] = 0.0
            for r in range(n_rows):
                for m in range(s.j_ptr[r], s.j_ptr[r + 1]):
                    g[s.j_col[m]] += values[m] * nu[r]
            substitute(s.first, L, g, out)
            for p in range(nq):
                S_out[f, s.perm[p], k] = out[p]
        for i in range(len(offsets)):
            o = offsets[i]
            a, b, c = local[i, 0], local[i, 1], local[i, 2]
            for axis in range(3):
                points[f, i, axis] = (q[o + axis] + a * q[o + 3 + axis] + b * q[o + 6 + axis]
                                      + c * q[o + 9 + axis])
                for k in range(n):
                    H[f, 3 * i + axis, k] = (S_out[f, o + axis, k] + a * S_out[f, o + 3 + axis, k]
                                             + b * S_out[f, o + 6 + axis, k]
                                             + c * S_out[f, o + 9 + axis, k])

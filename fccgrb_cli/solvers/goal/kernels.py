"""Goal attainment's active-set SQP (solvers/goal/sqp.py) in the compiled kernels: the same
iteration on :class:`~fccgrb_cli.system.sparse.SparseSystem`, N = Φ_top,qᵀΦ_top,q + δρI (+ δH)
factored inside its envelope, N⁻¹Gᵀ by substitution, and the working-set rounds on small dense
systems (the loop over frames: optimize/kernels.py's solve_frames)."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from fccgrb_cli.solvers.cno.sqp import DELTA, FEASIBLE_TOP
from fccgrb_cli.solvers.goal.sqp import (
    ACTIVE,
    CEILING,
    MAX_SWAPS,
    PROX,
    PROX_MIN_TC,
    STALL,
    STALL_RATE,
    STATIONARY,
    VALLEY,
)
from fccgrb_cli.solvers.kernels import (
    Limits,
    add_hessian,
    cholesky,
    jacobian,
    normal_equations,
    residual,
    substitute,
)
from fccgrb_cli.solvers.optimize.problem import ED_SMOOTHING
from fccgrb_cli.system.sparse import SparseSystem


def ed_fits(s: SparseSystem, n_points: int) -> bool:
    """Whether each tracked point's distance curvature Jd_pᵀ M Jd_p (its three rows' column
    pairs) lies inside the factor's envelope, so that 'ed' can run compiled."""
    for t in range(n_points):
        cols = np.concatenate([s.j_col[s.j_ptr[r]:s.j_ptr[r + 1]]
                               for r in range(s.trk_start + 3 * t, s.trk_start + 3 * t + 3)])
        high, low = np.maximum.outer(cols, cols), np.minimum.outer(cols, cols)
        if (low < s.first[high]).any():
            return False
    return True


class GoalArrays(NamedTuple):
    """A frame's goals: which tracked points have a marker (and a weight), their weights, and
    whether each point's distance is one goal ('ed') or each residual component two ('tc')."""

    present: np.ndarray
    point_w: np.ndarray
    ed: bool


class GoalWorkspace(NamedTuple):
    """The arrays of one frame's iteration beside kernels.workspace's (m = 6 per point at
    most): constraint values c, weights w, their Jacobian G (factor order), U = N⁻¹Gᵀ (by
    rows), M = GN⁻¹Gᵀ, the base values, ζ, the working set, the curved matrix, N⁻¹rhs, the
    small system, its right-hand side, constraint values at the current and the target point,
    its solution, a column, 'ed''s unit directions and distances (4 per point), the slacks
    c − wγ and the Newton right-hand side."""

    c: np.ndarray
    w: np.ndarray
    G: np.ndarray
    U: np.ndarray
    M: np.ndarray
    base: np.ndarray
    zeta: np.ndarray
    working: np.ndarray
    curved: np.ndarray
    u0: np.ndarray
    K: np.ndarray
    small_rhs: np.ndarray
    values: np.ndarray
    target: np.ndarray
    x: np.ndarray
    col: np.ndarray
    normals: np.ndarray
    slack: np.ndarray
    rhs_q: np.ndarray


@njit(cache=True)
def goal_workspace(s: SparseSystem, n_points: int) -> GoalWorkspace:
    """A :class:`GoalWorkspace` for ``n_points`` tracked points, allocated once per solve."""
    nq, m = s.nq, 6 * n_points
    return GoalWorkspace(
        np.empty(m), np.empty(m), np.zeros((m, nq)), np.zeros((m, nq)), np.zeros((m, m)),
        np.empty(m), np.zeros(m), np.zeros(m + 1, dtype=np.int64), np.zeros((nq, nq)),
        np.empty(nq), np.zeros((m + 1, m + 1)), np.empty(m + 1), np.empty(m), np.empty(m),
        np.zeros(m + 1), np.empty(nq), np.zeros(4 * n_points), np.empty(m), np.empty(nq))


@njit(cache=True)
def _goals(s: SparseSystem, phi: np.ndarray, values: np.ndarray, goals: GoalArrays,
           gw: GoalWorkspace) -> int:
    """goal_sqp.goals: c, w and G (factor order) of the points with markers, into ``gw``; the
    number m. 'ed' keeps each point's unit direction n = d/s and s in ``gw.normals``."""
    present, point_w, ed = goals
    c, w, G, normals = gw.c, gw.w, gw.G, gw.normals
    n_present = 0
    for t in range(len(present)):
        n_present += present[t]
    half = 3 * n_present
    m = 2 * half if not ed else n_present
    G[:m] = 0.0
    j = 0
    for t in range(len(present)):
        if not present[t]:
            continue
        r0 = s.trk_start + 3 * t
        if not ed:
            for d in range(3):
                r = r0 + d
                c[j], c[j + half] = phi[r], -phi[r]
                w[j] = w[j + half] = point_w[t]
                for k in range(s.j_ptr[r], s.j_ptr[r + 1]):
                    G[j, s.j_col[k]] = values[k]
                    G[j + half, s.j_col[k]] = -values[k]
                j += 1
        else:
            total = ED_SMOOTHING * ED_SMOOTHING
            for d in range(3):
                total += phi[r0 + d] * phi[r0 + d]
            smooth = np.sqrt(total)
            c[j], w[j] = smooth - ED_SMOOTHING, point_w[t]
            normals[4 * j + 3] = smooth
            for d in range(3):
                n = phi[r0 + d] / smooth
                normals[4 * j + d] = n
                for k in range(s.j_ptr[r0 + d], s.j_ptr[r0 + d + 1]):
                    G[j, s.j_col[k]] += n * values[k]
            j += 1
    return m


@njit(cache=True)
def _add_distance_curvature(s: SparseSystem, present: np.ndarray, values: np.ndarray,
                            normals: np.ndarray, zeta: np.ndarray, N: np.ndarray) -> None:
    """N += Σ_p ζ_p Jd_pᵀ (I − nnᵀ)/s Jd_p (lower triangle, inside the envelope: ed_fits)."""
    j = 0
    for t in range(len(present)):
        if not present[t]:
            continue
        if zeta[j] != 0.0:
            r0 = s.trk_start + 3 * t
            scale = zeta[j] / normals[4 * j + 3]
            for k in range(3):
                for m in range(3):
                    coef = scale * ((1.0 if k == m else 0.0)
                                    - normals[4 * j + k] * normals[4 * j + m])
                    for a in range(s.j_ptr[r0 + k], s.j_ptr[r0 + k + 1]):
                        for b in range(s.j_ptr[r0 + m], s.j_ptr[r0 + m + 1]):
                            ca, cb = s.j_col[a], s.j_col[b]
                            if ca >= cb:
                                N[ca, cb] += coef * values[a] * values[b]
        j += 1


@njit(cache=True)
def _small_solve(K: np.ndarray, rhs: np.ndarray, n: int, out: np.ndarray) -> bool:
    """out[:n] = K[:n, :n]⁻¹ rhs[:n] by Gaussian elimination with partial pivoting (K and rhs
    are overwritten); False if a pivot vanishes."""
    for col in range(n):
        pivot = col
        for r in range(col + 1, n):
            if abs(K[r, col]) > abs(K[pivot, col]):
                pivot = r
        if K[pivot, col] == 0.0:
            return False
        if pivot != col:
            for k in range(n):
                K[col, k], K[pivot, k] = K[pivot, k], K[col, k]
            rhs[col], rhs[pivot] = rhs[pivot], rhs[col]
        for r in range(col + 1, n):
            f = K[r, col] / K[col, col]
            if f != 0.0:
                for k in range(col, n):
                    K[r, k] -= f * K[col, k]
                rhs[r] -= f * rhs[col]
    for r in range(n - 1, -1, -1):
        total = rhs[r]
        for k in range(r + 1, n):
            total -= K[r, k] * out[k]
        out[r] = total / K[r, r]
    return True


@njit(cache=True)
def _columns(s: SparseSystem, L: np.ndarray, gw: GoalWorkspace, have: np.ndarray, n_w: int,
             m: int) -> None:
    """U_j = N⁻¹G_jᵀ and M's column j = GU_j for the working set's constraints that lack
    them (computed once per iteration, as a constraint first enters the working set)."""
    G, U, M, working, col = gw.G, gw.U, gw.M, gw.working, gw.col
    for a in range(n_w):
        j = working[a]
        if have[j]:
            continue
        substitute(s.first, L, G[j], col)
        U[j] = col
        for i in range(m):
            total = 0.0
            for k in range(s.nq):
                total += G[i, k] * col[k]
            M[i, j] = total
        have[j] = True


@njit(cache=True)
def _minimizer(gw: GoalWorkspace, n_w: int, m: int, values: np.ndarray) -> bool:
    """goal_sqp's ``minimizer``: ζ_W and Δγ in gw.x[:n_w], gw.x[n_w]; constraint values there
    in ``values`` (M's columns of the working set are in place: :func:`_columns`)."""
    M, base, w, working, K, rhs, x = gw.M, gw.base, gw.w, gw.working, gw.K, gw.small_rhs, gw.x
    for a in range(n_w):
        for b in range(n_w):
            K[a, b] = M[working[a], working[b]]
        K[a, n_w] = K[n_w, a] = w[working[a]]
        rhs[a] = base[working[a]]
    K[n_w, n_w] = 0.0
    rhs[n_w] = DELTA
    if not _small_solve(K, rhs, n_w + 1, x):
        return False
    for j in range(m):
        total = base[j] - w[j] * x[n_w]
        for a in range(n_w):
            total -= M[j, working[a]] * x[a]
        values[j] = total
    return True


@njit(cache=True)
def _working_step(s: SparseSystem, N: np.ndarray, L: np.ndarray, m: int, n_w: int,
                  gw: GoalWorkspace, step: np.ndarray, zeta: np.ndarray) -> tuple[int, float]:
    """goal_sqp._working_step from the slacks and the right-hand side in ``gw``: Δq (factor
    order) in ``step``, ζ (every constraint) in ``zeta``, the working set in ``gw.working``;
    returns (its size, Δγ), size −1 on failure."""
    w, G, U, base, u0, values, target, x = gw.w, gw.G, gw.U, gw.base, gw.u0, gw.values, \
        gw.target, gw.x
    rhs_q, slack, working = gw.rhs_q, gw.slack, gw.working
    if not cholesky(s.first, N, L):
        return -1, 0.0
    substitute(s.first, L, rhs_q, u0)
    have = np.zeros(m, dtype=np.bool_)
    for a in range(m):
        total = slack[a]
        for k in range(s.nq):
            total += G[a, k] * u0[k]
        base[a] = total
    _columns(s, L, gw, have, n_w, m)
    feasible = _minimizer(gw, n_w, m, values)
    for j in range(m):
        feasible = feasible and values[j] <= ACTIVE
    if not feasible:  # not a feasible start: restart from the largest constraint
        best = 0
        for j in range(m):
            if base[j] / w[j] > base[best] / w[best]:
                best = j
        n_w = 1
        working[0] = best
        for j in range(m):
            values[j] = base[j] - w[j] * base[best] / w[best]
    inside = np.zeros(m, dtype=np.bool_)
    for a in range(n_w):
        inside[working[a]] = True
    for _ in range(MAX_SWAPS):
        _columns(s, L, gw, have, n_w, m)
        if not _minimizer(gw, n_w, m, target):
            return -1, 0.0
        alpha, blocking = np.inf, -1
        for j in range(m):
            if target[j] > ACTIVE and not inside[j]:
                ratio = -values[j] / (target[j] - values[j])
                if ratio < alpha:
                    alpha, blocking = ratio, j
        if blocking >= 0:
            if n_w == m:
                return -1, 0.0
            alpha = min(max(alpha, 0.0), 1.0)
            for j in range(m):
                values[j] += alpha * (target[j] - values[j])
            working[n_w] = blocking
            inside[blocking] = True
            n_w += 1
            continue
        for j in range(m):
            values[j] = target[j]
        drop = 0
        for a in range(n_w):
            if x[a] < x[drop]:
                drop = a
        if x[drop] < -1e-12 * DELTA:
            inside[working[drop]] = False
            for a in range(drop, n_w - 1):
                working[a] = working[a + 1]
            n_w -= 1
            continue
        for k in range(s.nq):
            step[k] = u0[k]
        zeta[:m] = 0.0
        for a in range(n_w):
            zeta[working[a]] = x[a]
            for k in range(s.nq):
                step[k] -= x[a] * U[working[a], k]
        return n_w, x[n_w]
    return -1, 0.0


@njit(cache=True)
def goal_frame(s: SparseSystem, q0: np.ndarray, ref: np.ndarray, goals: GoalArrays,
               limits: Limits, q: np.ndarray, ws, gw: GoalWorkspace) -> tuple[int, bool]:
    """One frame of goal_sqp.active_set_sqp from q0; the iterate in ``q``."""
    n_rows, nq = len(s.c_const) + len(s.dot_c), s.nq
    tol, max_iter = limits
    ed = goals.ed
    F, phi, values, shifted, shift, N, L, g, step_p, step, _ = ws
    c, w, zeta, working, curved = gw.c, gw.w, gw.zeta, gw.working, gw.curved
    slack, rhs_q, normals = gw.slack, gw.rhs_q, gw.normals
    w_top = np.zeros(n_rows)
    for r in s.top_rows:
        w_top[r] = 1.0
    trial_zeta = np.empty(len(c))
    kept = np.empty_like(working)
    q[:] = q0
    shift[:] = 0.0
    residual(s, q, q[s.nb:], ref, F, phi)
    jacobian(s, q, F, values)
    m = _goals(s, phi, values, goals, gw)
    if m == 0:  # no marker: nothing to attain
        return 0, False
    best = 0
    for j in range(m):
        if c[j] / w[j] > c[best] / w[best]:
            best = j
    gamma = c[best] / w[best]
    ceiling = gamma + ACTIVE
    for r in s.top_rows:
        ceiling = max(ceiling, gamma + ACTIVE + CEILING * abs(phi[r]))
    working[0] = best
    n_w = 1
    zeta[:] = 0.0
    size, stalled, settled = np.inf, 0, False
    for k in range(max_iter + 1):
        residual(s, q, q[s.nb:], ref, F, phi)
        jacobian(s, q, F, values)
        m = _goals(s, phi, values, goals, gw)
        violation, worst = 0.0, -np.inf
        for r in s.top_rows:
            violation = max(violation, abs(phi[r]))
        for j in range(m):
            slack[j] = c[j] - w[j] * gamma
            worst = max(worst, slack[j])
        if (size < tol or settled) and violation <= FEASIBLE_TOP and worst <= ACTIVE:
            return k, gamma <= ceiling
        if k == max_iter:
            break
        for r in range(n_rows):
            shifted[r] = phi[r] + shift[r]
        normal_equations(s, values, shifted, w_top, N, g)
        rho = PROX if ed else max(PROX_MIN_TC, PROX * 0.1**k)
        for i in range(nq):
            N[i, i] += DELTA * rho
            rhs_q[i] = -g[i]
        for i in range(nq):
            for j in range(s.first[i], i + 1):
                curved[i, j] = N[i, j]
        add_hessian(s, q, shift, curved)
        if ed:
            _add_distance_curvature(s, goals.present, values, normals, zeta, curved)
        kept[:] = working
        n_kept = n_w
        n_w, d_gamma = _working_step(s, curved, L, m, n_w, gw, step_p, trial_zeta)
        exact = n_w >= 0
        if not exact:  # the Lagrangian's curvature not convex here, or the rounds failed
            working[:] = kept
            n_w, d_gamma = _working_step(s, N, L, m, n_kept, gw, step_p, trial_zeta)
        if n_w < 0:
            return k + 1, False
        zeta[:m] = trial_zeta[:m]
        before, largest = size, 0.0
        for p in range(nq):
            step[s.perm[p]] = step_p[p]
            largest = max(largest, abs(step_p[p]))
        size = max(largest, abs(d_gamma))
        settled = exact and abs(d_gamma) < tol and rho * largest < STATIONARY
        stalled = stalled + 1 if size > STALL_RATE * before and abs(d_gamma) < VALLEY else 0
        if not np.isfinite(size) or stalled == STALL:
            return k + 1, False
        for r in s.top_rows:
            total = phi[r]
            for t in range(s.j_ptr[r], s.j_ptr[r + 1]):
                total += values[t] * step[s.perm[s.j_col[t]]]
            shift[r] += total
        for i in range(nq):
            q[i] += step[i]
        gamma += d_gamma
    return max_iter, False

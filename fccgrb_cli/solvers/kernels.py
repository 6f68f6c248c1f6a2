"""Compiled per-frame kernels of NRM (numba): Φ, Φ_q's non-zeros, the normal equations, the
exact Hessian's terms and an envelope Cholesky factorization, all on the constant arrays of
:class:`~fccgrb_cli.system.sparse.SparseSystem`, and a loop over frames that does what
``solve_nrm``'s numpy path does frame by frame (same guesses, same Gauss–Newton / Newton
iteration, line search and stopping test: docs/formulation.md §3.1), without leaving machine code.

The loop hands control back to Python where Python knows more: a frame without a history (the
first, or after a failure) needs ``initial_guess``; a frame whose set of missing markers is new
needs the rank test. ``solve_frames`` returns the frame index and the reason, and is called
again from there.

Compiled on first use and cached on disk (``cache=True``): the first call of a new install
takes a few seconds, later processes load the machine code.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from fccgrb_cli.solvers.cno.sqp import (
    DELTA,
    FEASIBLE_TOP,
    KAPPA,
    MU_END,
    MU_START,
    TAU,
    THETA,
)
from fccgrb_cli.solvers.kernel_arrays import (
    BaseRates,
    Bounds,
    DrivenMotion,
    Drivers,
    FrameOutputs,
    Limits,
    NrmTrial,
    WarmStart,
)
from fccgrb_cli.solvers.moving_kernels import row_terms
from fccgrb_cli.solvers.newton import LARGE, NEAR, ROUNDING, SLOW
from fccgrb_cli.system.sparse import SparseSystem

DONE, NEED_GUESS, NEED_RANK, NEED_FALLBACK = 0, 1, 2, 3
UNKNOWN, UNSOLVABLE, SOLVABLE = -1, 0, 1
# A chord step (an earlier point's factor) is kept while it is at most this fraction of the step
# before it; slower, Φ_q is factored afresh (driven_frames).
CHORD_RATE = 0.1
# driven_frames without the inverse dynamics: mass blocks, g_x, the loads' bodies, forces,
# points and moments, then λ, misfit, power and the frames done (all empty).
NO_INVERSE = (np.zeros((0, 4, 4)), np.zeros(0), np.zeros(0, dtype=np.int64),
              np.zeros((0, 0, 3)), np.zeros((0, 0, 3)), np.zeros((0, 0, 3)), np.zeros((0, 0)),
              np.zeros(0), np.zeros(0), np.zeros(0, dtype=np.bool_))
_EXTRAPOLATION = np.array([[1.0, 0.0, 0.0, 0.0, 0.0], [2.0, -1.0, 0.0, 0.0, 0.0],
                           [3.0, -3.0, 1.0, 0.0, 0.0], [4.0, -6.0, 4.0, -1.0, 0.0],
                           [5.0, -10.0, 10.0, -5.0, 1.0]])


@njit(cache=True)
def features(s: SparseSystem, q: np.ndarray, F: np.ndarray) -> None:
    """F = A x + f0 (flattened, Eq. 2–3), x = q's body part."""
    for i in range(len(F)):
        total = s.f0[i]
        for k in range(s.a_ptr[i], s.a_ptr[i + 1]):
            total += s.a_val[k] * q[s.a_col[k]]
        F[i] = total


@njit(cache=True)
def residual(s: SparseSystem, q: np.ndarray, theta: np.ndarray, ref: np.ndarray,
             F: np.ndarray, phi: np.ndarray) -> None:
    """Φ: linear and tracking rows from the constant rows, dot rows F_a·F_b − c − g(θ), a signed
    angle's sine row − sin θ (docs/formulation.md §2), a moving joint's or coupling's row − h(θ)
    (system/moving.py); θ is q's tail in a mixed system, the drivers' θ* in a classical one."""
    _fixed_residual(s, q, theta, ref, F, phi)
    m = s.moving
    if len(m.rows):
        h = np.empty(len(m.rows))
        row_terms(m, theta, 0, h, np.empty((0, 0)), np.empty((0, 0, 0)))
        for i in range(len(m.rows)):
            phi[s.n_lin + m.rows[i]] -= h[i]


@njit(cache=True)
def residual_sloped(s: SparseSystem, q: np.ndarray, theta: np.ndarray, ref: np.ndarray,
                    F: np.ndarray, phi: np.ndarray, h: np.ndarray, d1: np.ndarray) -> None:
    """:func:`residual`, the function rows' ∂h/∂θ at the same θ kept in ``d1`` (rows × width;
    ``h`` scratch) for :func:`jacobian_sloped`: an iteration that takes its Jacobian where it
    evaluated Φ evaluates the joints' transforms once (~10–15 µs of a Gait2354 iteration's
    ~90)."""
    _fixed_residual(s, q, theta, ref, F, phi)
    m = s.moving
    if len(m.rows):
        row_terms(m, theta, 1, h, d1, np.empty((0, 0, 0)))
        for i in range(len(m.rows)):
            phi[s.n_lin + m.rows[i]] -= h[i]


@njit(cache=True)
def _fixed_residual(s: SparseSystem, q: np.ndarray, theta: np.ndarray, ref: np.ndarray,
                    F: np.ndarray, phi: np.ndarray) -> None:
    """Every row of :func:`residual` but the function rows' − h(θ)."""
    features(s, q, F)
    for r in range(s.n_lin):
        total = s.c_const[r]
        for k in range(s.j_ptr[r], s.j_ptr[r + 1]):
            total += s.j_const[k] * q[s.perm[s.j_col[k]]]
        phi[r] = total
    for t in range(len(s.trk_slot)):
        for d in range(3):
            phi[s.trk_start + 3 * t + d] -= ref[s.trk_slot[t], d]
    for i in range(len(s.dot_a)):
        a, b = 3 * s.dot_a[i], 3 * s.dot_b[i]
        phi[s.n_lin + i] = F[a] * F[b] + F[a + 1] * F[b + 1] + F[a + 2] * F[b + 2] - s.dot_c[i]
    for k in range(len(s.angle_rows)):
        g = theta[k] if s.distance[k] else np.cos(theta[k])
        phi[s.n_lin + s.angle_rows[k]] -= g
    for j in range(len(s.sine_rows)):
        phi[s.n_lin + s.sine_rows[j]] -= np.sin(theta[s.sine_of[j]])


@njit(cache=True)
def jacobian(s: SparseSystem, q: np.ndarray, F: np.ndarray, values: np.ndarray) -> None:
    """Φ_q's non-zeros at the features F: constant rows, the dot rows' c ⊗ F_other scattered
    block by block (Eq. 2–3), −g′(θ) and −cos θ of the mixed coordinates (Eq. 13–22), −∂h/∂θ
    of the function rows (moving joints and couplings)."""
    _fixed_jacobian(s, q, F, values)
    m = s.moving
    if len(m.rows):
        d1 = np.empty((len(m.rows), m.cols.shape[1]))
        row_terms(m, q[s.nb:], 1, np.empty(len(m.rows)), d1, np.empty((0, 0, 0)))
        _slopes_in(m, d1, values)


@njit(cache=True)
def jacobian_sloped(s: SparseSystem, q: np.ndarray, F: np.ndarray, values: np.ndarray,
                    d1: np.ndarray) -> None:
    """:func:`jacobian` with the function rows' ∂h/∂θ that :func:`residual_sloped` kept at
    this q."""
    _fixed_jacobian(s, q, F, values)
    if len(s.moving.rows):
        _slopes_in(s.moving, d1, values)


@njit(cache=True)
def _fixed_jacobian(s: SparseSystem, q: np.ndarray, F: np.ndarray, values: np.ndarray) -> None:
    """Every entry of :func:`jacobian` but the function rows' −∂h/∂θ."""
    values[:] = s.j_const
    for k in range(len(s.scat_pos)):
        values[s.scat_pos[k]] += s.scat_coef[k] * F[s.scat_feat[k]]
    nb = s.nb
    for k in range(len(s.ang_pos)):  # mixed systems only (a classical one has no θ columns)
        values[s.ang_pos[k]] = -1.0 if s.distance[k] else np.sin(q[nb + k])
    for j in range(len(s.sin_pos)):
        values[s.sin_pos[j]] = -np.cos(q[nb + s.sine_of[j]])


@njit(cache=True)
def _slopes_in(m, d1: np.ndarray, values: np.ndarray) -> None:
    """−∂h/∂θ of the function rows into Φ_q's non-zeros."""
    width = m.cols.shape[1]
    for i in range(len(m.rows)):
        for a in range(width):
            if m.pos[i, a] >= 0:
                values[m.pos[i, a]] = -d1[i, a]


@njit(cache=True)
def cost_of(phi: np.ndarray, w: np.ndarray) -> float:
    total = 0.0
    for r in range(len(phi)):
        total += w[r] * phi[r] * phi[r]
    return total


@njit(cache=True)
def normal_equations(s: SparseSystem, values: np.ndarray, phi: np.ndarray, w: np.ndarray,
                     N: np.ndarray, g: np.ndarray) -> None:
    """The lower triangle of Φ_qᵀWΦ_q and Φ_qᵀWΦ in the factor's order, row by row
    (Σ_r w_r J_rᵀJ_r costs Σ nnz_r²)."""
    n = len(g)
    for i in range(n):
        g[i] = 0.0
        for j in range(s.first[i], i + 1):
            N[i, j] = 0.0
    for r in range(len(phi)):
        wr = w[r]
        if wr == 0.0:
            continue
        start = s.j_ptr[r]
        for k in range(start, s.j_ptr[r + 1]):
            vk = wr * values[k]
            ck = s.j_col[k]
            g[ck] += vk * phi[r]
            for m in range(start, k + 1):
                N[ck, s.j_col[m]] += vk * values[m]


@njit(cache=True)
def add_hessian(s: SparseSystem, q: np.ndarray, c: np.ndarray, N: np.ndarray) -> None:
    """N += Σ_i c_i ∇²_q Φ_i (lower triangle): the dot rows' constant C_aᵀC_b + C_bᵀC_a, and
    −c_k g″(θ_k) (c_k cos θ_k for an angle), c_s sin θ for a sine row on the diagonal, and
    −Σ c_r ∂²h_r/∂θ² of the function rows (see System.residual_hessian)."""
    for t in range(len(s.h_row)):
        N[s.h_row[t], s.h_col[t]] += s.h_coef[t] * c[s.n_lin + s.h_dot[t]]
    nb = s.nb
    for k in range(len(s.angle_rows)):
        if not s.distance[k]:
            p = s.inverse[nb + k]
            N[p, p] += c[s.n_lin + s.angle_rows[k]] * np.cos(q[nb + k])
    for j in range(len(s.sine_rows)):
        p = s.inverse[nb + s.sine_of[j]]
        N[p, p] += c[s.n_lin + s.sine_rows[j]] * np.sin(q[nb + s.sine_of[j]])
    m = s.moving
    if len(m.rows):
        width = m.cols.shape[1]
        d2 = np.empty((len(m.rows), width, width))
        row_terms(m, q[nb:], 2, np.empty(len(m.rows)), np.empty((len(m.rows), width)), d2)
        for i in range(len(m.rows)):
            weight = c[s.n_lin + m.rows[i]]
            for a in range(width):
                if m.cols[i, a] < 0:
                    continue
                pa = s.inverse[nb + m.cols[i, a]]
                for b in range(width):  # each pair once, in the lower triangle
                    if m.cols[i, b] < 0:
                        continue
                    pb = s.inverse[nb + m.cols[i, b]]
                    if pa > pb or a == b:
                        N[pa, pb] -= weight * d2[i, a, b]


@njit(cache=True)
def cholesky_solve(first: np.ndarray, N: np.ndarray, L: np.ndarray, rhs: np.ndarray,
                   out: np.ndarray) -> bool:
    """Solve N out = rhs with N = LLᵀ factored inside its envelope (row i from column
    first[i]); False where N is not positive definite."""
    if not cholesky(first, N, L):
        return False
    substitute(first, L, rhs, out)
    return True


@njit(cache=True)
def cholesky(first: np.ndarray, N: np.ndarray, L: np.ndarray) -> bool:
    """N = LLᵀ inside the envelope (the lower triangle of N is read)."""
    n = len(first)
    for i in range(n):
        fi = first[i]
        for j in range(fi, i):
            k0 = max(fi, first[j])
            total = N[i, j]
            for k in range(k0, j):
                total -= L[i, k] * L[j, k]
            L[i, j] = total / L[j, j]
        total = N[i, i]
        for k in range(fi, i):
            total -= L[i, k] * L[i, k]
        if not total > 0.0:
            return False
        L[i, i] = np.sqrt(total)
    return True


@njit(cache=True)
def substitute(first: np.ndarray, L: np.ndarray, rhs: np.ndarray, out: np.ndarray) -> None:
    """out = (LLᵀ)⁻¹ rhs, forward then backward within the envelope."""
    n = len(rhs)
    for i in range(n):
        total = rhs[i]
        for k in range(first[i], i):
            total -= L[i, k] * out[k]
        out[i] = total / L[i, i]
    for i in range(n - 1, -1, -1):
        out[i] /= L[i, i]
        value = out[i]
        for k in range(first[i], i):
            out[k] -= L[i, k] * value


@njit(cache=True)
def workspace(s: SparseSystem, n_rows: int):
    """The arrays one frame's iteration writes into, allocated once per solve: features,
    Φ, Φ_q's values, the trial's Φ, WΦ, the normal matrix and its factor, the gradient, the
    step (factor order and q order) and the trial point."""
    nq = s.nq
    return (np.empty(len(s.f0)), np.empty(n_rows), np.empty(len(s.j_col)), np.empty(n_rows),
            np.empty(n_rows), np.zeros((nq, nq)), np.zeros((nq, nq)), np.empty(nq),
            np.empty(nq), np.empty(nq), np.empty(nq))


@njit(cache=True)
def gauss_newton(s: SparseSystem, q0: np.ndarray, ref: np.ndarray, w: np.ndarray,
                 limits: Limits, hessian: int, q: np.ndarray, ws) -> tuple[int, bool]:
    """One frame of fccgrb_cli.solvers.newton.gauss_newton (hessian 0 Gauss–Newton, 1 exact,
    2 auto): the iterate is left in ``q``; returns (iterations, converged). ``ws``: see
    :func:`workspace`."""
    n_rows, nq = len(w), s.nq
    tol, max_iter = limits
    F, phi, values, trial_phi, c, N, L, g, step_p, step, trial = ws
    h, d1 = np.empty(len(s.moving.rows)), np.empty((len(s.moving.rows), s.moving.cols.shape[1]))
    q[:] = q0
    residual_sloped(s, q, q[s.nb:], ref, F, phi, h, d1)
    jacobian_sloped(s, q, F, values, d1)
    cost = cost_of(phi, w)
    size = previous = np.inf
    full = True
    exact = hessian == 1
    for k in range(1, max_iter + 1):
        largest = 0.0
        for r in range(n_rows):
            largest = max(largest, abs(w[r] * phi[r]))
        near = size < NEAR and largest > LARGE
        exact = exact or (hessian == 2 and (near or size > SLOW * previous))
        normal_equations(s, values, phi, w, N, g)
        for i in range(nq):
            g[i] = -g[i]
        ok = False
        if exact:
            for r in range(n_rows):
                c[r] = w[r] * phi[r]
            add_hessian(s, q, c, N)
            ok = cholesky_solve(s.first, N, L, g, step_p)
            if not ok:
                normal_equations(s, values, phi, w, N, g)
                for i in range(nq):
                    g[i] = -g[i]
        if not ok:
            ok = cholesky_solve(s.first, N, L, g, step_p)
        if not ok:
            return k, False
        previous, size = size if full else np.inf, 0.0
        slope = 0.0
        for p in range(nq):
            step[s.perm[p]] = step_p[p]
            slope -= g[p] * step_p[p]
            size = max(size, abs(step_p[p]))
        if not np.isfinite(size):
            return k, False
        if size < tol:
            for i in range(nq):
                q[i] += step[i]
            return k, True
        alpha = 1.0
        for i in range(nq):
            trial[i] = q[i] + step[i]
        residual_sloped(s, trial, trial[s.nb:], ref, F, trial_phi, h, d1)
        trial_cost = cost_of(trial_phi, w)
        while trial_cost > cost + 2e-4 * alpha * slope + ROUNDING * cost and alpha >= 1e-3:
            alpha *= 0.5
            for i in range(nq):
                trial[i] = q[i] + alpha * step[i]
            residual_sloped(s, trial, trial[s.nb:], ref, F, trial_phi, h, d1)
            trial_cost = cost_of(trial_phi, w)
        full = alpha == 1.0
        q[:] = trial
        phi[:] = trial_phi
        cost = trial_cost
        jacobian_sloped(s, q, F, values, d1)  # F and d1 hold the last trial's, now q's
    return max_iter, False


@njit(cache=True)
def solve_frames(s: SparseSystem, trial: NrmTrial, limits: Limits, hessian: int, start: int,
                 stop: int, warm: WarmStart, out: FrameOutputs) -> tuple[int, int]:
    """Frames ``start`` to ``stop`` of solve_nrm's loop (the history holds up to 5 solutions).
    Returns (frame, DONE | NEED_GUESS | NEED_RANK): Python supplies the warm start's guess
    (use_guess) and calls again from that frame."""
    targets, missing, pattern_of, solvable, base_w = trial
    tol, max_iter = limits
    guess, use_guess, history, state, extrapolate = warm
    q_all, iterations, phi_norm, phi_top, converged, unsolved = out
    n_rows, nq = len(base_w), s.nq
    ws = workspace(s, n_rows)
    w = np.empty(n_rows)
    y = np.empty((targets.shape[1], 3))
    q0 = np.empty(nq)
    q = np.empty(nq)
    F = np.empty(len(s.f0))
    phi = np.empty(n_rows)
    for f in range(start, stop):
        count = state[0]
        points = min(count, 5 if state[1] <= 5 else 3)
        if not _warm_start(use_guess and f == start, guess, history, count, points,
                           extrapolate, q0):
            return f, NEED_GUESS
        key = pattern_of[f]
        if solvable[key] == UNKNOWN:
            guess[:] = q0
            return f, NEED_RANK
        if solvable[key] == UNSOLVABLE:
            q_all[f] = np.nan
            unsolved[f] = True
            continue
        for r in range(n_rows):
            w[r] = base_w[r]
        for t in range(targets.shape[1]):
            for d in range(3):
                y[t, d] = 0.0 if missing[f, t] else targets[f, t, d]
            if missing[f, t]:
                for d in range(3):
                    w[s.trk_start + 3 * t + d] = 0.0
        cap = max_iter if count else 4 * max_iter
        k, ok = gauss_newton(s, q0, y, w, Limits(tol, cap), hessian, q, ws)
        if not ok and count and extrapolate:
            k2, ok = gauss_newton(s, history[count - 1], y, w, limits, hessian, q, ws)
            k += k2
        q_all[f] = q
        iterations[f] = k
        converged[f] = ok
        state[1] = k
        state[0] = pushed(history, count, q) if ok else 0
        phi_norm[f], phi_top[f] = _statistics(s, q, y, w, F, phi)
    return stop, DONE


@njit(cache=True)
def _warm_start(given: bool, guess: np.ndarray, history: np.ndarray, count: int, points: int,
                extrapolate: bool, out: np.ndarray) -> bool:
    """A frame's starting point in ``out`` (nrm.predict): Python's ``guess`` where given, else
    the last solution ('previous') or the polynomial through the last ``points`` of the
    ``count`` solutions; False when there is no history (Python supplies the guess)."""
    if given:
        out[:] = guess
        return True
    if count == 0:
        return False
    if not extrapolate:
        out[:] = history[count - 1]
        return True
    coef = _EXTRAPOLATION[points - 1]
    out[:] = 0.0
    for j in range(points):
        out += coef[j] * history[count - 1 - j]
    return True


@njit(cache=True)
def pushed(history: np.ndarray, count: int, q: np.ndarray) -> int:
    """``q`` appended to the history (the oldest dropped when full); the new count."""
    if count == len(history):
        for j in range(count - 1):
            history[j] = history[j + 1]
        history[count - 1] = q
        return count
    history[count] = q
    return count + 1


@njit(cache=True)
def _statistics(s: SparseSystem, q: np.ndarray, y: np.ndarray, keep: np.ndarray,
                F: np.ndarray, phi: np.ndarray) -> tuple[float, float]:
    """‖Φ‖ over the rows where ``keep`` > 0 and max |Φ_top| at a frame's solution."""
    residual(s, q, q[s.nb:], y, F, phi)
    total, top = 0.0, 0.0
    for r in range(len(phi)):
        if keep[r] > 0.0:
            total += phi[r] * phi[r]
    for r in s.top_rows:
        top = max(top, abs(phi[r]))
    return np.sqrt(total), top


@njit(cache=True)
def stabilized_sqp(s: SparseSystem, q0: np.ndarray, ref: np.ndarray, w: np.ndarray,
                   limits: Limits, q: np.ndarray, ws, bounds: Bounds) -> tuple[int, bool]:
    """One frame of fccgrb_cli.solvers.sqp.stabilized_sqp (``w`` from sqp_weights); with
    ``interior``, its interior point on ``lower`` ≤ q ≤ ``upper`` (sqp.Barrier), the bound
    multipliers z_l, z_u in ``z`` (4 × nq: z_l, z_u, 0 where unbounded, and their steps).
    The iterate is left in ``q``; returns (iterations, converged)."""
    n_rows, nq = len(w), s.nq
    tol, max_iter = limits
    lower, upper, interior, z = bounds
    F, phi, values, shifted, shift, N, L, g, step_p, step, _ = ws
    q[:] = q0
    shift[:] = 0.0
    mu = MU_START if interior else 0.0
    mu_end = MU_END * tol
    if interior:
        for i in range(nq):
            span = upper[i] - lower[i] if np.isfinite(upper[i] - lower[i]) else 1.0
            q[i] = min(max(q[i], lower[i] + 1e-6 * span), upper[i] - 1e-6 * span)
            z[0, i] = mu / (q[i] - lower[i]) if np.isfinite(lower[i]) else 0.0
            z[1, i] = mu / (upper[i] - q[i]) if np.isfinite(upper[i]) else 0.0
    size = np.inf
    h, d1 = np.empty(len(s.moving.rows)), np.empty((len(s.moving.rows), s.moving.cols.shape[1]))
    for k in range(max_iter + 1):
        residual_sloped(s, q, q[s.nb:], ref, F, phi, h, d1)
        violation = 0.0
        for r in s.top_rows:
            violation = max(violation, abs(phi[r]))
        if size < tol and violation <= FEASIBLE_TOP and mu <= mu_end:
            return k, True
        if k == max_iter:
            break
        jacobian_sloped(s, q, F, values, d1)
        for r in range(n_rows):
            shifted[r] = phi[r] + shift[r]
        normal_equations(s, values, shifted, w, N, g)
        _negated_with_barrier(s, q, lower, upper, z, mu, N, g)
        add_hessian(s, q, shift, N)
        ok = cholesky_solve(s.first, N, L, g, step_p)
        if not ok:
            normal_equations(s, values, shifted, w, N, g)
            _negated_with_barrier(s, q, lower, upper, z, mu, N, g)
            ok = cholesky_solve(s.first, N, L, g, step_p)
        if not ok:
            return k + 1, False
        size = 0.0
        for p in range(nq):
            step[s.perm[p]] = step_p[p]
            size = max(size, abs(step_p[p]))
        if not np.isfinite(size):
            return k + 1, False
        alpha = 1.0
        if interior:
            alpha = _barrier_advance(q, step, lower, upper, z, mu)
            mu = max(mu_end, min(KAPPA * mu, mu**THETA))
        for r in s.top_rows:
            total = phi[r]
            for m in range(s.j_ptr[r], s.j_ptr[r + 1]):
                total += values[m] * step[s.perm[s.j_col[m]]]
            shift[r] += alpha * total
        for i in range(nq):
            q[i] += alpha * step[i]
    return max_iter, False


@njit(cache=True)
def _negated_with_barrier(s: SparseSystem, q: np.ndarray, lower: np.ndarray, upper: np.ndarray,
                          z: np.ndarray, mu: float, N: np.ndarray, g: np.ndarray) -> None:
    """g ← −g, and with μ > 0 the barrier's terms (sqp.Barrier.add_terms) in factor order."""
    for i in range(len(g)):
        g[i] = -g[i]
    if mu == 0.0:
        return
    for i in range(s.nq):
        p = s.inverse[i]
        if np.isfinite(lower[i]):
            sl = q[i] - lower[i]
            N[p, p] += DELTA * z[0, i] / sl
            g[p] += DELTA * mu / sl
        if np.isfinite(upper[i]):
            su = upper[i] - q[i]
            N[p, p] += DELTA * z[1, i] / su
            g[p] -= DELTA * mu / su


@njit(cache=True)
def _barrier_advance(q: np.ndarray, step: np.ndarray, lower: np.ndarray, upper: np.ndarray,
                     z: np.ndarray, mu: float) -> float:
    """sqp.Barrier.advance: the bound multipliers' update (their steps in z[2:]) and the
    primal step length."""
    alpha, alpha_z = 1.0, 1.0
    for side in range(2):
        for i in range(len(q)):
            bound = lower[i] if side == 0 else upper[i]
            z[2 + side, i] = 0.0
            if not np.isfinite(bound):
                continue
            slack = q[i] - bound if side == 0 else bound - q[i]
            d = step[i] if side == 0 else -step[i]
            dz = (mu - z[side, i] * slack - z[side, i] * d) / slack
            z[2 + side, i] = dz
            if d < 0.0:
                alpha = min(alpha, -TAU * slack / d)
            if dz < 0.0:
                alpha_z = min(alpha_z, -TAU * z[side, i] / dz)
    for side in range(2):
        for i in range(len(q)):
            z[side, i] += alpha_z * z[2 + side, i]
    return alpha


@njit(cache=True)
def rates_frames(s: SparseSystem, q_all: np.ndarray, theta_d: np.ndarray,
                 theta_dd: np.ndarray, base: BaseRates, qd: np.ndarray, qdd: np.ndarray
                 ) -> None:
    """Consistent q̇ and q̈ of every frame (fccgrb_cli/solvers/rates.py): with θ̇, θ̈ given,
    the body rates solve Φ_top,b q̇_b = −Φ_top,θ θ̇ and Φ_top,b q̈_b = γ_top − Φ_top,θ θ̈, with a
    floating base's differenced rates as extra rows, in the least-squares sense (exact where
    they are consistent, as rates.py's LU or QR). Normal equations on NRM's envelope with the
    θ rows and columns set to the identity: one factorization per frame serves both. Frames
    with a NaN are left NaN."""
    base_cols, base_d, base_dd = base
    n_rows, nq, nb = len(s.c_const) + len(s.dot_c), s.nq, s.nb
    F, Fd = np.empty(len(s.f0)), np.empty(len(s.f0))
    values = np.empty(len(s.j_col))
    N, L = np.zeros((nq, nq)), np.zeros((nq, nq))
    w, rhs, gamma = np.zeros(n_rows), np.zeros(n_rows), np.zeros(n_rows)
    g, out = np.empty(nq), np.empty(nq)
    inverse = s.inverse
    for r in s.top_rows:
        w[r] = 1.0
    for f in range(len(q_all)):
        q = q_all[f]
        if not (np.isfinite(q).all() and np.isfinite(theta_d[f]).all()
                and np.isfinite(theta_dd[f]).all()):
            continue
        features(s, q, F)
        jacobian(s, q, F, values)
        _moved_to_rhs(s, values, gamma, theta_d[f], rhs, zero_first=True)
        normal_equations(s, values, rhs, w, N, g)
        _theta_fixed(s, N)
        for j in range(len(base_cols)):
            p = inverse[base_cols[j]]
            N[p, p] += 1.0
            g[p] += base_d[f, j]
        for k in range(nq - nb):
            g[inverse[nb + k]] = theta_d[f, k]
        if not cholesky(s.first, N, L):
            continue
        substitute(s.first, L, g, out)
        for p in range(nq):
            qd[f, s.perm[p]] = out[p]
        qd[f, nb:] = theta_d[f]  # as given, also where a base rate is NaN
        _gamma_top(s, q, qd[f], Fd, gamma)
        _moved_to_rhs(s, values, gamma, theta_dd[f], rhs, zero_first=False)
        for p in range(nq):
            g[p] = 0.0
        for r in s.top_rows:
            for m in range(s.j_ptr[r], s.j_ptr[r + 1]):
                g[s.j_col[m]] += values[m] * rhs[r]
        for j in range(len(base_cols)):
            g[inverse[base_cols[j]]] += base_dd[f, j]
        for k in range(nq - nb):
            g[inverse[nb + k]] = theta_dd[f, k]
        substitute(s.first, L, g, out)
        for p in range(nq):
            qdd[f, s.perm[p]] = out[p]
        qdd[f, nb:] = theta_dd[f]


@njit(cache=True)
def _theta_fixed(s: SparseSystem, N: np.ndarray) -> None:
    """θ given: its rows and columns of the normal matrix N (lower triangle, factor order)
    become the identity, leaving Φ_xᵀWΦ_x on the body columns."""
    nq, nb = s.nq, s.nb
    for k in range(nq - nb):
        p = s.inverse[nb + k]
        for j in range(s.first[p], p):
            N[p, j] = 0.0
        for i in range(p + 1, nq):
            if s.first[i] <= p:
                N[i, p] = 0.0
        N[p, p] = 1.0


@njit(cache=True)
def coordinate_multipliers_frames(s: SparseSystem, q_all: np.ndarray, rhs: np.ndarray,
                                  lam: np.ndarray, tau: np.ndarray, misfit: np.ndarray
                                  ) -> None:
    """The inverse dynamics of a mixed system along prescribed coordinates (dynamics/moving.py,
    docs/opensim.md §5), every frame: the multipliers of the topological rows (``s.top_rows``,
    in their order) λ = Φ_x (Φ_xᵀΦ_x)⁻¹ rhs, the minimum-norm solution of Φ_xᵀλ = rhs with
    rhs = g_x + Q_x − M ẍ (frames × body columns); the coordinates' forces τ = Φ_θᵀλ; the
    misfit ‖Φ_xᵀλ − rhs‖. Normal equations on NRM's envelope with the θ rows and columns set to
    the identity (as rates_frames), so the θ columns of the solution are zero. Frames with a
    NaN, or whose Φ_x loses column rank, are left NaN."""
    nq, nb = s.nq, s.nb
    n_rows = len(s.c_const) + len(s.dot_c)
    F = np.empty(len(s.f0))
    values = np.empty(len(s.j_col))
    N, L = np.zeros((nq, nq)), np.zeros((nq, nq))
    w, zero = np.zeros(n_rows), np.zeros(n_rows)
    g, y, back = np.empty(nq), np.empty(nq), np.empty(nq)
    for r in s.top_rows:
        w[r] = 1.0
    for f in range(len(q_all)):
        lam[f] = np.nan
        tau[f] = np.nan
        misfit[f] = np.nan
        q = q_all[f]
        if not (np.isfinite(q).all() and np.isfinite(rhs[f]).all()):
            continue
        features(s, q, F)
        jacobian(s, q, F, values)
        normal_equations(s, values, zero, w, N, g)
        _theta_fixed(s, N)
        if not cholesky(s.first, N, L):
            continue
        g[:] = 0.0
        for j in range(nb):
            g[s.inverse[j]] = rhs[f, j]
        substitute(s.first, L, g, y)
        tau[f] = 0.0
        back[:] = 0.0
        for i in range(len(s.top_rows)):
            r = s.top_rows[i]
            acc = 0.0
            for m in range(s.j_ptr[r], s.j_ptr[r + 1]):
                acc += values[m] * y[s.j_col[m]]
            lam[f, i] = acc
            for m in range(s.j_ptr[r], s.j_ptr[r + 1]):
                column = s.perm[s.j_col[m]]
                if column >= nb:
                    tau[f, column - nb] += values[m] * acc
                else:
                    back[column] += values[m] * acc
        acc = 0.0
        for j in range(nb):
            acc += (back[j] - rhs[f, j]) ** 2
        misfit[f] = np.sqrt(acc)


@njit(cache=True)
def _moved_to_rhs(s: SparseSystem, values: np.ndarray, gamma: np.ndarray, rate: np.ndarray,
                  rhs: np.ndarray, zero_first: bool) -> None:
    """rhs_r = γ_r − Φ_r,θ · rate on the topological rows (γ taken as 0 when ``zero_first``)."""
    nb = s.nb
    for r in s.top_rows:
        total = 0.0 if zero_first else gamma[r]
        for m in range(s.j_ptr[r], s.j_ptr[r + 1]):
            column = s.perm[s.j_col[m]]
            if column >= nb:
                total -= values[m] * rate[column - nb]
        rhs[r] = total


@njit(cache=True)
def _gamma_top(s: SparseSystem, q: np.ndarray, qd: np.ndarray, Fd: np.ndarray,
               gamma: np.ndarray) -> None:
    """γ of the topological rows of a mixed system with fully-defined bodies: 0 on the linear
    rows, −2Ḟ_a·Ḟ_b on the dot rows, + g″(θ)θ̇² on an angle's or distance's row (−cos θ θ̇²,
    0), − sin θ θ̇² on a sine row and θ̇ᵀ ∂²h/∂θ² θ̇ on a function row (System.gamma)."""
    for i in range(len(Fd)):
        total = 0.0
        for k in range(s.a_ptr[i], s.a_ptr[i + 1]):
            total += s.a_val[k] * qd[s.a_col[k]]
        Fd[i] = total
    for r in range(s.n_lin):
        gamma[r] = 0.0
    for i in range(len(s.dot_a)):
        a, b = 3 * s.dot_a[i], 3 * s.dot_b[i]
        gamma[s.n_lin + i] = -2.0 * (Fd[a] * Fd[b] + Fd[a + 1] * Fd[b + 1]
                                     + Fd[a + 2] * Fd[b + 2])
    nb = s.nb
    for k in range(len(s.angle_rows)):
        if not s.distance[k]:
            gamma[s.n_lin + s.angle_rows[k]] -= np.cos(q[nb + k]) * qd[nb + k] ** 2
    for j in range(len(s.sine_rows)):
        k = s.sine_of[j]
        gamma[s.n_lin + s.sine_rows[j]] -= np.sin(q[nb + k]) * qd[nb + k] ** 2
    m = s.moving
    if len(m.rows):
        width = m.cols.shape[1]
        d2 = np.empty((len(m.rows), width, width))
        row_terms(m, q[nb:], 2, np.empty(len(m.rows)), np.empty((len(m.rows), width)), d2)
        for i in range(len(m.rows)):
            total = 0.0
            for a in range(width):
                for b in range(width):
                    if m.cols[i, a] >= 0 and m.cols[i, b] >= 0:
                        total += d2[i, a, b] * qd[nb + m.cols[i, a]] * qd[nb + m.cols[i, b]]
            gamma[s.n_lin + m.rows[i]] += total


@njit(cache=True)
def driven_frames(s: SparseSystem, guesses: np.ndarray, drivers: Drivers, limits: Limits,
                  motion: DrivenMotion, inverse) -> None:
    """The classical model driven by θ*(t) (and a floating base's features), every frame from
    its own guess moved by the correction (solution − guess) of the frames before it,
    extrapolated linearly (the drivers' filtering and the WLS topology misfit change slowly;
    7e-6 → 1e-6 m on the five-bar sample at P30): Newton–Raphson on Φ = 0 until a step
    ‖Δq‖∞ < tol (newton.newton_raphson), then Φ_q q̇ = ν and Φ_q q̈ = γ (docs/formulation.md §3)
    and, with ``inverse`` (see :data:`NO_INVERSE`), the multipliers of the inverse dynamics
    (docs/formulation.md §4), all through the normal equations on the envelope (Φ_q square, or
    taller with full column rank: the same solution as LU or least squares).

    The factorization at each frame's solution serves q̇, q̈ and λ and, where Φ_q is square,
    the next frame's Newton iteration as a chord (simplified Newton) matrix: frames 10 ms apart
    move Φ_q little, so the chord steps contract fast; where a step shrinks by less than
    ``CHORD_RATE`` of the one before, Φ_q is evaluated and factored afresh at the current
    point, and so it is where the chord's rate would not meet tol within ``max_iter`` steps.
    A chord step below tol ends the iteration only where its contraction is known (the
    error left is then ≤ rate · tol), so the solution agrees with full Newton's to far below
    tol. (A taller Φ_q keeps full Gauss–Newton: where its equations are not all met, a chord
    matrix's fixed point J_Lᵀ Φ = 0 is not the least-squares one Φ_qᵀ Φ = 0.) Frames that do
    not converge within ``max_iter`` steps are left for Python (converged False); frames with
    a non-finite guess are skipped."""
    theta, theta_d, theta_dd, ref, ref_d, ref_dd = drivers
    tol, max_iter = limits
    q_out, qd_out, qdd_out, phi_out, iterations, converged = motion
    n_rows, nq = phi_out.shape[1], s.nq
    square = n_rows == nq
    F, Fd = np.empty(len(s.f0)), np.empty(len(s.f0))
    values = np.empty(len(s.j_col))
    N, L = np.zeros((nq, nq)), np.zeros((nq, nq))
    w, phi, rhs = np.ones(n_rows), np.empty(n_rows), np.empty(n_rows)
    g, out, q, total = np.empty(nq), np.empty(nq), np.empty(nq), np.empty(nq)
    offset, older = np.zeros(nq), np.zeros(nq)  # the last two frames' solution − guess
    known = 0  # how many of them there are (consecutive frames solved)
    factored = False  # L holds the factor of Φ_qᵀΦ_q at some point, ``values`` its Φ_q
    for f in range(len(guesses)):
        if not np.isfinite(guesses[f]).all():
            known = 0
            continue
        q[:] = guesses[f]
        if known:
            q += offset
        if known > 1:
            q += offset - older
        ok = refresh = False
        previous = np.inf
        for k in range(1, max_iter + 1):
            residual(s, q, theta[f], ref[f], F, phi)
            size = np.inf
            chord = factored and square and not refresh
            if chord:  # the factor of an earlier point: kept while its steps contract fast
                _transposed_product(s, values, phi, g)
                substitute(s.first, L, g, out)
                size = _largest(out)
                chord = size <= CHORD_RATE * previous or (previous == np.inf and size < np.inf)
            if not chord:
                jacobian(s, q, F, values)
                normal_equations(s, values, phi, w, N, g)
                factored = cholesky(s.first, N, L)
                if not factored:
                    break
                substitute(s.first, L, g, out)
                size = _largest(out)
            for p in range(nq):
                q[s.perm[p]] -= out[p]
            iterations[f] = k
            if not np.isfinite(size):
                factored = False
                break
            if size < tol and (not chord or previous < np.inf):
                ok = True
                break
            # a chord's linear rate: factored afresh where it would not meet tol in the steps left
            refresh = (chord and previous < np.inf and size > 0.0
                       and k + np.log(size / tol) / np.log(previous / size) > max_iter - 1)
            previous = size
        if not ok:
            known = 0
            continue
        residual(s, q, theta[f], ref[f], F, phi)
        jacobian(s, q, F, values)
        normal_equations(s, values, phi, w, N, g)
        factored = cholesky(s.first, N, L)
        if not factored:
            known = 0
            continue
        older[:] = offset
        offset[:] = q - guesses[f]
        known += 1
        converged[f] = True
        q_out[f] = q
        phi_out[f] = phi
        _driven_nu(s, theta[f], theta_d[f], ref_d[f], rhs)
        _transposed_product(s, values, rhs, g)
        substitute(s.first, L, g, out)
        for p in range(nq):
            qd_out[f, s.perm[p]] = out[p]
        _driven_gamma(s, qd_out[f], theta[f], theta_d[f], theta_dd[f], ref_dd[f], Fd, rhs)
        _transposed_product(s, values, rhs, g)
        substitute(s.first, L, g, out)
        for p in range(nq):
            qdd_out[f, s.perm[p]] = out[p]
        if len(inverse[-1]):
            _frame_multipliers(s, values, L, f, motion, inverse, (total, g, out))


@njit(cache=True)
def _largest(v: np.ndarray) -> float:
    """‖v‖∞, inf where v holds a NaN."""
    size = 0.0
    for i in range(len(v)):
        a = abs(v[i])
        if a > size:
            size = a
        elif a != a:
            return np.inf
    return size


@njit(cache=True)
def _frame_multipliers(s: SparseSystem, values: np.ndarray, L: np.ndarray, f: int,
                       motion: DrivenMotion, inverse, work) -> None:
    """One frame of the inverse dynamics on the factor of its Φ_qᵀΦ_q (inverse.py, x = q):
    rhs = g_x + Σ C_Pᵀf + ½ n × (u, v, w) − M_x q̈ with M_x = blockdiag(K_i ⊗ I3), λ = Φ_q
    (Φ_qᵀΦ_q)⁻¹ rhs (exact, or min-norm for a taller Φ_q of full column rank), the misfit
    ‖Φ_qᵀλ − rhs‖ and the loads' power f · ṙ_P + n · ω (= Q_load · ẋ, loads.py)."""
    mass, gravity, load_at, force, point, moment, lam, misfit, power, solved = inverse
    q, qd, qdd = motion.q[f], motion.qd[f], motion.qdd[f]
    total, rhs, y = work  # scratch: nq each
    nq = s.nq
    for b in range(len(mass)):
        for i in range(4):
            for d in range(3):
                acc = gravity[12 * b + 3 * i + d]
                for j in range(4):
                    acc -= mass[b, i, j] * qdd[12 * b + 3 * j + d]
                total[12 * b + 3 * i + d] = acc
    work = 0.0
    for k in range(len(load_at)):
        _load_forces(q[load_at[k]:load_at[k] + 12], force[k, f], point[k, f], moment[k, f],
                     y)
        for i in range(12):
            total[load_at[k] + i] += y[i]
            work += y[i] * qd[load_at[k] + i]
    power[f] = work
    for p in range(nq):
        rhs[p] = total[s.perm[p]]
    misfit[f] = _min_norm_multipliers(s, values, L, rhs, lam[f], y)
    solved[f] = True


@njit(cache=True)
def _min_norm_multipliers(s: SparseSystem, values: np.ndarray, L: np.ndarray, rhs: np.ndarray,
                          lam: np.ndarray, work: np.ndarray) -> float:
    """λ = Φ_q (Φ_qᵀΦ_q)⁻¹ rhs into ``lam`` on the factor L of Φ_qᵀΦ_q (rhs in factor order):
    the solution of Φ_qᵀλ = rhs for a square Φ_q, the minimum-norm one for a taller Φ_q of
    full column rank; returns the misfit ‖Φ_qᵀλ − rhs‖ (``work``: nq of scratch)."""
    substitute(s.first, L, rhs, work)
    for r in range(len(lam)):
        acc = 0.0
        for m in range(s.j_ptr[r], s.j_ptr[r + 1]):
            acc += values[m] * work[s.j_col[m]]
        lam[r] = acc
    _transposed_product(s, values, lam, work)
    acc = 0.0
    for p in range(s.nq):
        acc += (work[p] - rhs[p]) ** 2
    return np.sqrt(acc)


@njit(cache=True)
def _load_forces(x: np.ndarray, force: np.ndarray, point: np.ndarray, moment: np.ndarray,
                 out: np.ndarray) -> None:
    """ExternalLoad.generalized at one frame (loads.py): [f, a f + ½ n × u, b f + ½ n × v,
    c f + ½ n × w] on the body's x = [r, u, v, w], (a, b, c) solving [u v w] (a, b, c) = P − r
    (Cramer's rule)."""
    dx, dy, dz = point[0] - x[0], point[1] - x[1], point[2] - x[2]
    ux, uy, uz, vx, vy, vz, wx, wy, wz = x[3], x[4], x[5], x[6], x[7], x[8], x[9], x[10], x[11]
    det = ux * (vy * wz - vz * wy) - vx * (uy * wz - uz * wy) + wx * (uy * vz - uz * vy)
    local = ((dx * (vy * wz - vz * wy) - vx * (dy * wz - dz * wy) + wx * (dy * vz - dz * vy)) / det,
             (ux * (dy * wz - dz * wy) - dx * (uy * wz - uz * wy) + wx * (uy * dz - uz * dy)) / det,
             (ux * (vy * dz - vz * dy) - vx * (uy * dz - uz * dy) + dx * (uy * vz - uz * vy)) / det)
    for i in range(3):
        out[i] = force[i]
    for axis in range(3):
        e = 3 + 3 * axis
        out[e] = local[axis] * force[0] + 0.5 * (moment[1] * x[e + 2] - moment[2] * x[e + 1])
        out[e + 1] = local[axis] * force[1] + 0.5 * (moment[2] * x[e] - moment[0] * x[e + 2])
        out[e + 2] = local[axis] * force[2] + 0.5 * (moment[0] * x[e + 1] - moment[1] * x[e])


@njit(cache=True)
def multipliers_frames(s: SparseSystem, q_all: np.ndarray, rhs: np.ndarray, lam: np.ndarray,
                       misfit: np.ndarray) -> None:
    """λ with Φ_qᵀλ = rhs for every frame of a classical motion (the inverse dynamics, Eq. of
    docs/formulation.md §4): λ = Φ_q (Φ_qᵀΦ_q)⁻¹ rhs, the solution for a square Φ_q and the
    minimum-norm one for a taller Φ_q of full column rank; ``misfit`` = ‖Φ_qᵀλ − rhs‖."""
    n_rows, nq = lam.shape[1], s.nq
    F = np.empty(len(s.f0))
    values = np.empty(len(s.j_col))
    N, L = np.zeros((nq, nq)), np.zeros((nq, nq))
    w, zero = np.ones(n_rows), np.zeros(n_rows)
    g, out = np.empty(nq), np.empty(nq)
    for f in range(len(q_all)):
        features(s, q_all[f], F)
        jacobian(s, q_all[f], F, values)
        normal_equations(s, values, zero, w, N, g)
        if not cholesky(s.first, N, L):
            lam[f] = np.nan
            continue
        for p in range(nq):
            g[p] = rhs[f, s.perm[p]]
        misfit[f] = _min_norm_multipliers(s, values, L, g, lam[f], out)


@njit(cache=True)
def _transposed_product(s: SparseSystem, values: np.ndarray, v: np.ndarray,
                        out: np.ndarray) -> None:
    """out = Φ_qᵀ v (factor order)."""
    out[:] = 0.0
    for r in range(len(v)):
        for m in range(s.j_ptr[r], s.j_ptr[r + 1]):
            out[s.j_col[m]] += values[m] * v[r]


@njit(cache=True)
def _driven_nu(s: SparseSystem, theta: np.ndarray, theta_d: np.ndarray, ref_d: np.ndarray,
               nu: np.ndarray) -> None:
    """ν = −Φ_t of a classical system (System.nu): the base drivers' ṙ*, g′(θ*) θ̇* on an
    angle's or distance's row, cos θ* θ̇* on a sine row."""
    nu[:] = 0.0
    for t in range(len(s.trk_slot)):
        for d in range(3):
            nu[s.trk_start + 3 * t + d] = ref_d[s.trk_slot[t], d]
    for k in range(len(s.angle_rows)):
        g1 = 1.0 if s.distance[k] else -np.sin(theta[k])
        nu[s.n_lin + s.angle_rows[k]] = g1 * theta_d[k]
    for j in range(len(s.sine_rows)):
        k = s.sine_of[j]
        nu[s.n_lin + s.sine_rows[j]] = np.cos(theta[k]) * theta_d[k]


@njit(cache=True)
def _driven_gamma(s: SparseSystem, qd: np.ndarray, theta: np.ndarray, theta_d: np.ndarray,
                  theta_dd: np.ndarray, ref_dd: np.ndarray, Fd: np.ndarray,
                  gamma: np.ndarray) -> None:
    """γ of a classical system with fully-defined bodies (System.gamma): −2Ḟ_a·Ḟ_b on the dot
    rows, g″(θ*)θ̇*² + g′(θ*)θ̈* on an angle's row, −sin θ* θ̇*² + cos θ* θ̈* on a sine row,
    the base drivers' r̈*."""
    for i in range(len(Fd)):
        total = 0.0
        for k in range(s.a_ptr[i], s.a_ptr[i + 1]):
            total += s.a_val[k] * qd[s.a_col[k]]
        Fd[i] = total
    gamma[:] = 0.0
    for t in range(len(s.trk_slot)):
        for d in range(3):
            gamma[s.trk_start + 3 * t + d] = ref_dd[s.trk_slot[t], d]
    for i in range(len(s.dot_a)):
        a, b = 3 * s.dot_a[i], 3 * s.dot_b[i]
        gamma[s.n_lin + i] = -2.0 * (Fd[a] * Fd[b] + Fd[a + 1] * Fd[b + 1]
                                     + Fd[a + 2] * Fd[b + 2])
    for k in range(len(s.angle_rows)):
        if s.distance[k]:
            gamma[s.n_lin + s.angle_rows[k]] += theta_dd[k]
        else:
            gamma[s.n_lin + s.angle_rows[k]] -= (np.cos(theta[k]) * theta_d[k] ** 2
                                                 + np.sin(theta[k]) * theta_dd[k])
    for j in range(len(s.sine_rows)):
        k = s.sine_of[j]
        gamma[s.n_lin + s.sine_rows[j]] += (-np.sin(theta[k]) * theta_d[k] ** 2
                                            + np.cos(theta[k]) * theta_dd[k])

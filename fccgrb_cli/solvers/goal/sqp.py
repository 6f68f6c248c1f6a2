"""Goal attainment (docs/formulation.md §3, MO) by an active-set SQP on the engine's linear algebra:
over (q, γ), min γ subject to c_j(q) − w_j γ ≤ 0 and Φ_top(q) = 0, with c_j = ±d_k, each
tracking residual component with both signs ('tc'), or c_j = ‖d_p‖, each point's distance
smoothed at zero as in FrameProblem.distances ('ed').

Each iteration solves the SQP's quadratic subproblem with the exact Lagrangian Hessian
H = Σ λ_i ∇²Φ_top,i + Σ z_j ∇²c_j and the topological block stabilized as in the CNO-SQP
(cno/sqp.py: −δI, the multipliers carried as the shift s = δλ), plus a proximal term ρ‖Δq‖²/2
(ρ = 1e-2 m⁻¹, with 'tc' down to 1e-4 over the first iterations: :func:`proximal`) that
keeps it strictly convex where the minimax is flat: the optimum of a noisy frame is often a
face, not a point, and the term picks its point nearest the current iterate.
Eliminating Δλ leaves, in the scaled multipliers ζ = δz,

    min over (Δq, Δγ):  δΔγ + ½ΔqᵀNΔq − rhsᵀΔq,   N = Φ_top,qᵀΦ_top,q + δ(H + ρI),
                        rhs = −Φ_top,qᵀ(Φ_top + s)
    subject to          G Δq − w Δγ ≤ −(c − wγ)        (G = ∂c/∂q)

(the γ row of its KKT conditions is w_Wᵀζ = δ, i.e. Σ w_j z_j = 1). It is solved by a primal
active-set method on the Schur complement of N (:func:`_working_step`); the working set carries
over between iterations, so near the solution one small solve confirms it. At a vertex of the
minimax (dimension + 1 constraints active, the usual case with 'tc') the step is Newton's on a
square system, whatever ρ. Where H is not convex (large multipliers, as at an exact fit where
every constraint is active) the iteration uses N without it.

A frame is converged when the step is below tol at a KKT point: Φ_top = 0 to FEASIBLE_TOP,
every c_j ≤ w_j γ to 1e-12 m, z ≥ 0 (the subproblem's multipliers are kept ≥ 0; stationarity
holds by its first row once Δq = 0), or, after a step with the exact Hessian, when γ moved by
less than tol and the proximal term's share of the unregularized problem's first-order
conditions, ρ‖Δq‖∞ (relative to ∂γ = 1), is below 1e-8 (after a step without H the share left
is (ρI + H)Δq, which ρ‖Δq‖ does not bound). Some noisy
frames have no such point within reach: the minimax falls along a valley by nanometres per
millimetre, and the steps keep their length; after STALL steps in a row that shrink by less
than a quarter while γ moves by less than a micron, the frame is given up. A frame that is not
converged, or whose optimum leaves the bounds, goes to SLSQP (goal/reference.py) from the same guess
(SLSQP's function-change test stops in such a valley; started where this method stopped, it
found the crank-rocker's other assembly branch at an exact fit); a guess far off the
constraints first goes through NRM-WLS (optimize/frame.py). The iteration has no line search: a KKT
point whose γ exceeds the guess's by more than 10 times the guess's max |Φ_top| (the optimum
near a guess exceeds the guess's γ by up to 1.3 times it on the five-bar) is another local
optimum it wandered to (the RSSR's other assembly branch at an exact fit, 89° away), and is not
converged either.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fccgrb_cli.core.blas import lapack
from fccgrb_cli.solvers.cno.sqp import DELTA, FEASIBLE_TOP
from fccgrb_cli.solvers.newton import Iterate
from fccgrb_cli.solvers.optimize.problem import ED_SMOOTHING, FrameProblem

MAX_ITER = 50
MAX_SWAPS = 200  # working-set changes per iteration
FAR = 1e-2  # max |Φ_top| of a guess that goes through NRM-WLS first (the proximal term damps
# the first steps: the CNO-SQP's 1e-3 sent a third of the extrapolated guesses there at 30 mm)
CEILING = 10.0  # a converged γ may exceed the guess's by this many times its max |Φ_top|
STATIONARY = 1e-8  # ρ‖Δq‖∞: the unregularized problem's first-order error, relative to ∂γ = 1
STALL, STALL_RATE, VALLEY = 5, 0.75, 1e-6  # steps in a row that shrink by less than a quarter
# while γ moves by less than a micron: a flat valley, left to SLSQP (the smoothed distance's
# double root at an exact fit halves each step, and is not one)
ACTIVE = 1e-12  # c_j − w_j γ (m) at which a constraint counts as satisfied
PROX = 1e-2
PROX_MIN_TC = 1e-4


def proximal(k: int, ed: bool) -> float:
    """ρ (m⁻¹) of iteration k. 'tc': PROX, then a tenth of it each iteration down to
    PROX_MIN_TC, so that on a face whose only curvature is the constraints' (h ~ 1e-3 on the
    five-bar) the proximal term's linear rate ρ/(ρ + h) turns small after the first steps (a
    rule on the step's size would have a fixed point where the face is flat: steps of constant
    length, each set by the last). 'ed': PROX throughout, since the distances' own curvature
    z/‖d‖ dominates it, and a smaller ρ lets the iterate wander along flat valleys."""
    return PROX if ed else max(PROX_MIN_TC, PROX * 0.1**k)


@dataclass(frozen=True)
class Goals:
    """The inequality constraints at one q: values c (m), their Jacobian G (m × nq), weights w,
    and for 'ed' the pieces of Σ ζ_j ∇²c_j: each residual row's coefficient per unit ζ (n = d/s)
    and each point's Jd_pᵀ(I − nnᵀ)/s Jd_p."""

    c: np.ndarray
    G: np.ndarray
    w: np.ndarray
    rows_c: np.ndarray | None
    point_blocks: np.ndarray | None


def goals(problem: FrameProblem, q: np.ndarray, objective: str) -> Goals:
    """c, G and the pieces of their second derivatives for the tracked points with markers."""
    d, Jd = problem.residuals(q)
    present = problem.point_weights > 0
    w_pts = problem.point_weights[present]
    d, Jd = d[present], Jd[present]
    if objective == "tc":
        flat, Jflat = d.ravel(), Jd.reshape(-1, Jd.shape[-1])
        w = np.tile(np.repeat(w_pts, 3), 2)
        return Goals(np.concatenate([flat, -flat]), np.vstack([Jflat, -Jflat]), w, None, None)
    s = np.sqrt((d * d).sum(axis=1) + ED_SMOOTHING**2)
    n = d / s[:, None]
    G = np.einsum("pk,pkq->pq", n, Jd)
    M = np.eye(3)[None] / s[:, None, None] - np.einsum("pk,pl->pkl", d, d) / s[:, None, None]**3
    blocks = np.einsum("pkq,pkl,plr->pqr", Jd, M, Jd)
    return Goals(s - ED_SMOOTHING, G, w_pts, n, blocks)


def _curvature(problem: FrameProblem, q: np.ndarray, shift: np.ndarray, g: Goals,
               zeta: np.ndarray, objective: str) -> np.ndarray:
    """δH = Σ s_i ∇²Φ_top,i + Σ ζ_j ∇²c_j, through the engine's residual Hessian."""
    system = problem.system
    c = shift.copy()
    present = np.repeat(problem.point_weights > 0, 3)
    rows = problem.trk[present]
    if objective == "tc":
        half = len(zeta) // 2
        c[rows] = zeta[:half] - zeta[half:]
        return system.residual_hessian(q, c)
    assert g.rows_c is not None and g.point_blocks is not None  # goals() gives them for 'ed'
    c[rows] = (zeta[:, None] * g.rows_c).ravel()
    return system.residual_hessian(q, c) + np.einsum("p,pqr->qr", zeta, g.point_blocks)


def active_set_sqp(problem: FrameProblem, q0: np.ndarray, objective: str, tol: float,
                   max_iter: int = MAX_ITER) -> tuple[Iterate, float]:
    """One frame from q0 (on or near Φ_top = 0): the iterate and its γ."""
    system = problem.system
    top = problem.top
    q = q0.copy()
    g = goals(problem, q, objective)
    if len(g.c) == 0:  # no marker: nothing to attain
        return Iterate(q, 0, False), np.nan
    gamma = float((g.c / g.w).max())
    working = [int(np.argmax(g.c / g.w))]
    zeta = np.zeros(len(g.c))
    shift = np.zeros(system.n_rows)
    size, stalled, settled = np.inf, 0, False
    for k in range(max_iter + 1):
        phi, J = system.evaluate(q, problem.drive)
        if k == 0:  # the guess's γ and distance from Φ_top = 0 bound a converged frame's γ
            ceiling = gamma + CEILING * np.abs(phi[top]).max(initial=0.0) + ACTIVE
        g = goals(problem, q, objective)
        slack = g.c - g.w * gamma
        if ((size < tol or settled) and np.abs(phi[top]).max(initial=0.0) <= FEASIBLE_TOP
                and slack.max() <= ACTIVE):
            return Iterate(q, k, gamma <= ceiling), gamma
        if k == max_iter:
            break
        Jt = J[top]
        N = Jt.T @ Jt
        rho = proximal(k, objective == "ed")
        N[np.diag_indices(len(q))] += DELTA * rho
        rhs_q = -(Jt.T @ (phi[top] + shift[top]))
        curved = N + _curvature(problem, q, shift, g, zeta, objective)
        found = _working_step(curved, rhs_q, g, slack, list(working))
        exact = found is not None
        if not exact:  # the Lagrangian's curvature not convex here, or the rounds failed
            found = _working_step(N, rhs_q, g, slack, list(working))
        if found is None:
            return Iterate(q, k + 1, False), gamma
        step, d_gamma, zeta, working = found
        size, before = max(np.abs(step).max(), abs(d_gamma)), size
        settled = exact and abs(d_gamma) < tol and rho * np.abs(step).max() < STATIONARY
        stalled = stalled + 1 if size > STALL_RATE * before and abs(d_gamma) < VALLEY else 0
        if not np.isfinite(size) or stalled == STALL:
            return Iterate(q, k + 1, False), gamma
        shift[top] += phi[top] + Jt @ step
        q = q + step
        gamma += d_gamma
    return Iterate(q, max_iter, False), gamma


def _working_step(N: np.ndarray, rhs_q: np.ndarray, g: Goals, slack: np.ndarray,
                  working: list[int]) -> tuple[np.ndarray, float, np.ndarray, list[int]] | None:
    """The QP step (module doc) by a primal active-set method on the Schur complement of N:
    with N = LLᵀ factored once, U = N⁻¹Gᵀ and M = GU, the minimizer with the constraints W
    held active is Δq = N⁻¹rhs_q − U_W ζ_W with [[M_WW, w_W], [w_Wᵀ, 0]] [ζ_W; Δγ] =
    [slack_W + G_W N⁻¹rhs_q; δ]. From a feasible point (``working``'s own minimizer if it is
    feasible, else Δq = N⁻¹rhs_q with Δγ raising γ to the largest constraint), each round
    moves towards W's minimizer until a constraint outside W blocks (it joins W) or drops the
    constraint with the most negative multiplier, until neither is needed (only the constraint
    values along the way matter: the multipliers and Δγ are the last minimizer's). Returns Δq,
    Δγ, ζ and the final W (``working`` is changed); None if N is not positive definite, the
    rounds do not settle or every constraint has joined W."""
    L, info = lapack.dpotrf(N, lower=1)
    if info != 0:
        return None
    U, info = lapack.dpotrs(L, np.column_stack([rhs_q, g.G.T]), lower=1)
    if info != 0:
        return None
    u0, U = U[:, 0], U[:, 1:]
    M = g.G @ U
    base = slack + g.G @ u0  # constraint values at Δq = N⁻¹rhs_q, Δγ = 0

    def minimizer(W: list[int]) -> tuple[np.ndarray, float, np.ndarray]:
        A = np.array(W)
        m = len(A)
        K = np.zeros((m + 1, m + 1))
        K[:m, :m] = M[np.ix_(A, A)]
        K[:m, m] = K[m, :m] = g.w[A]
        x = np.linalg.solve(K, np.concatenate([base[A], [DELTA]]))
        zeta, d_gamma = x[:m], float(x[m])
        return zeta, d_gamma, base - M[:, A] @ zeta - g.w * d_gamma

    try:
        values = minimizer(working)[2] if working else None
    except np.linalg.LinAlgError:
        values = None
    if values is None or not values.max() <= ACTIVE:  # not a feasible start: restart
        working[:] = [int(np.argmax(base / g.w))]
        values = base - g.w * float((base / g.w).max())
    try:
        for _ in range(MAX_SWAPS):
            zeta, d_gamma, target = minimizer(working)
            rising = target > ACTIVE
            rising[working] = False
            if rising.any():
                if len(working) == len(slack):
                    return None
                ratios = -values[rising] / (target[rising] - values[rising])
                alpha = min(max(float(ratios.min()), 0.0), 1.0)
                values = values + alpha * (target - values)
                working.append(int(np.flatnonzero(rising)[np.argmin(ratios)]))
                continue
            values = target
            if zeta.min() < -1e-12 * DELTA:
                working.pop(int(np.argmin(zeta)))
                continue
            full = np.zeros(len(slack))
            full[working] = zeta
            return u0 - U[:, working] @ zeta, d_gamma, full, working
    except np.linalg.LinAlgError:
        return None
    return None

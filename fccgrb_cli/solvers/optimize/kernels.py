"""The sequential loop over frames of the structured optimizers in the compiled kernels
(optimize/solve.py's _run_frames with the stabilized SQP, its interior point or goal attainment's
active-set SQP per frame: kernels.stabilized_sqp, goal/kernels.py's goal_frame). Each frame starts
from the quadratic extrapolation of up to 3 solutions; a guess far off the constraints goes
through NRM-WLS first, as in optimize.structured_frame."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from fccgrb_cli.solvers.cno.sqp import DELTA, FAR
from fccgrb_cli.solvers.cno.sqp import MAX_ITER as MAX_SQP
from fccgrb_cli.solvers.goal import sqp as goal_sqp
from fccgrb_cli.solvers.goal.kernels import GoalArrays, goal_frame, goal_workspace
from fccgrb_cli.solvers.kernels import (
    DONE,
    NEED_FALLBACK,
    NEED_GUESS,
    Bounds,
    FrameOutputs,
    Limits,
    WarmStart,
    _statistics,
    _warm_start,
    gauss_newton,
    pushed,
    residual,
    stabilized_sqp,
    workspace,
)
from fccgrb_cli.system.sparse import SparseSystem

SQP, INTERIOR, GOAL_TC, GOAL_ED = 0, 1, 2, 3
KINDS = {"cno-sqp": SQP, "cno-ip": INTERIOR, "mo-tc": GOAL_TC, "mo-ed": GOAL_ED}


class OptimizerTrial(NamedTuple):
    """A trial as the optimizers' loop reads it: targets (frames × points × 3, m), the gaps
    (frames × points), each tracked point's weight, NRM-WLS's row weights (for a guess far off
    the constraints) and the bounds on q."""

    targets: np.ndarray
    missing: np.ndarray
    point_weights: np.ndarray
    nrm_w: np.ndarray
    lower: np.ndarray
    upper: np.ndarray


@njit(cache=True)
def solve_frames(s: SparseSystem, kind: int, trial: OptimizerTrial, limits: Limits,
                 start: int, stop: int, warm: WarmStart, out: FrameOutputs) -> tuple[int, int]:
    """Frames ``start`` to ``stop`` by the optimizer ``kind`` (KINDS), each from the quadratic
    extrapolation of up to 3 solutions (the warm start's history, ``state[0]`` of them).
    Returns (frame, DONE | NEED_GUESS | NEED_FALLBACK): a frame the kernel cannot solve within
    the bounds goes back to Python (scipy's optimizer) with its guess in the warm start's
    ``guess``, the kernel's iterate in ``out.q``, its iterations and whether it converged
    (outside the bounds) in ``out.converged``."""
    targets, missing, point_weights, nrm_w, lower, upper = trial
    tol, max_iter = limits
    guess, use_guess, history, state, extrapolate = warm
    q_all, iterations, phi_norm, phi_top, converged, _ = out
    n_rows, nq = len(s.c_const) + len(s.dot_c), s.nq
    n_points = targets.shape[1]
    goal = kind >= GOAL_TC
    far = goal_sqp.FAR if goal else FAR
    ws = workspace(s, n_rows)
    gw = goal_workspace(s, n_points)
    goals = GoalArrays(np.zeros(n_points, dtype=np.bool_), point_weights, kind == GOAL_ED)
    present = goals.present
    bounds = Bounds(lower, upper, kind == INTERIOR, np.zeros((4, nq)))
    w = np.zeros(n_rows)
    w_nrm = np.empty(n_rows)
    active = np.ones(n_rows)
    y = np.empty((n_points, 3))
    q0, q, start_q = np.empty(nq), np.empty(nq), np.empty(nq)
    F = np.empty(len(s.f0))
    phi = np.empty(n_rows)
    for r in s.top_rows:
        w[r] = 1.0
    for f in range(start, stop):
        count = state[0]
        if not _warm_start(use_guess and f == start, guess, history, count, count,
                           extrapolate, q0):
            return f, NEED_GUESS
        for t in range(n_points):
            gone = missing[f, t]
            present[t] = not gone and point_weights[t] > 0.0
            for d in range(3):
                row = s.trk_start + 3 * t + d
                y[t, d] = 0.0 if gone else targets[f, t, d]
                w[row] = 0.0 if gone else 2.0 * DELTA * point_weights[t]
                active[row] = 0.0 if gone else 1.0
        residual(s, q0, q0[s.nb:], y, F, phi)
        before = 0
        violation = 0.0
        for r in s.top_rows:
            violation = max(violation, abs(phi[r]))
        start_q[:] = q0
        if violation > far:  # a guess far off the constraints: NRM-WLS first
            for r in range(n_rows):
                w_nrm[r] = nrm_w[r] * active[r]
            before, _ = gauss_newton(s, q0, y, w_nrm, Limits(tol, min(max_iter, 50)), 2, q, ws)
            start_q[:] = q
        if goal:
            k, ok = goal_frame(s, start_q, y, goals, Limits(tol, min(max_iter, goal_sqp.MAX_ITER)),
                               q, ws, gw)
        else:
            k, ok = stabilized_sqp(s, start_q, y, w, Limits(tol, min(max_iter, MAX_SQP)), q, ws,
                                   bounds)
        k += before
        converged[f] = ok
        for i in range(nq):
            ok = ok and lower[i] <= q[i] <= upper[i]
        q_all[f] = q
        iterations[f] = k
        if not ok:
            guess[:] = q0
            return f, NEED_FALLBACK
        state[0] = pushed(history, count, q)
        phi_norm[f], phi_top[f] = _statistics(s, q, y, active, F, phi)
    return stop, DONE

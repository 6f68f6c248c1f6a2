"""The sequential structured optimizers through the compiled kernels (CNO-SQP and CNO-IP with
the TC objective, goal attainment): frames the kernel solves within the bounds stay in machine
code; a frame without a history gets Python's initial guess, and a frame the kernel cannot solve
goes through the numpy path's ``solve_frame`` (SLSQP or trust-constr, then the retry from
NRM-WLS), exactly as the numpy path would."""

from __future__ import annotations

import time as clock
from collections.abc import Callable

import numpy as np

from fccgrb_cli.solvers import kernels
from fccgrb_cli.solvers.engine import ready
from fccgrb_cli.solvers.initial import initial_guess
from fccgrb_cli.solvers.newton import Iterate
from fccgrb_cli.solvers.nrm.compiled import BLOCK
from fccgrb_cli.solvers.nrm.problem import row_weights
from fccgrb_cli.solvers.optimize import kernels as optimizer_kernels
from fccgrb_cli.solvers.optimize.frame import STRUCTURED, FrameRecord, Settings, solve_frame
from fccgrb_cli.solvers.optimize.kernels import KINDS
from fccgrb_cli.solvers.optimize.problem import FrameProblem
from fccgrb_cli.system import System
from fccgrb_cli.system.sparse import sparse_of

SQP_HISTORY = 3


def run_frames_compiled(system: System, settings: Settings, targets: np.ndarray,
                        progress: Callable[[int, int], None] | None = None
                        ) -> list[FrameRecord]:
    """optimize/solve.py's _run_frames over every frame, chained, with the structured optimizer
    compiled."""
    s = sparse_of(system)
    n, nq = len(targets), system.nq
    targets = np.ascontiguousarray(targets, dtype=float)
    missing = ~np.all(np.isfinite(targets), axis=2)
    weights = np.array([1.0 if w is None else w for w in system.trk_weight])
    lower, upper = FrameProblem(system, targets[0]).bound_arrays()
    nrm_weights = row_weights(system, 1e-3)
    q_all, iterations = np.zeros((n, nq)), np.zeros(n, dtype=np.int64)
    phi_norm, phi_top = np.full(n, np.nan), np.full(n, np.nan)
    converged, seconds = np.zeros(n, dtype=bool), np.zeros(n)
    history, state = np.zeros((SQP_HISTORY, nq)), np.zeros(1, dtype=np.int64)
    fallback: dict[int, FrameRecord] = {}
    done = STRUCTURED[settings.method][1]
    guess, use_guess = initial_guess(system, targets[0]), True
    trial = optimizer_kernels.OptimizerTrial(targets, missing, weights, nrm_weights, lower,
                                             upper)
    limits = kernels.Limits(settings.tol, settings.max_iter)
    extrapolate = settings.warm_start != "previous"
    outputs = kernels.FrameOutputs(q_all, iterations, phi_norm, phi_top, converged,
                                   np.zeros(n, dtype=bool))
    ready(optimizer_kernels.solve_frames, s, KINDS[settings.method], trial, limits, 0, 0,
          kernels.WarmStart(guess, use_guess, history, state, extrapolate), outputs)
    f = 0
    while f < n:
        started = clock.perf_counter()
        g, reason = optimizer_kernels.solve_frames(
            s, KINDS[settings.method], trial, limits, f, min(n, f + BLOCK),
            kernels.WarmStart(guess, use_guess, history, state, extrapolate), outputs)
        if g > f:
            seconds[f:g] = (clock.perf_counter() - started) / (g - f)
        use_guess = False
        if reason == kernels.NEED_GUESS:
            guess, use_guess = initial_guess(system, targets[g]), True
        elif reason == kernels.NEED_FALLBACK:
            record = solve_frame(system, settings, guess.copy(), targets[g],
                                 Iterate(q_all[g].copy(), int(iterations[g]), bool(converged[g])))
            fallback[g] = record
            state[0] = kernels.pushed(history, int(state[0]), record.q) \
                if record.converged else 0
            g += 1
        if progress is not None:
            progress(g, n)
        f = g
    return [fallback.get(k) or FrameRecord(q_all[k], int(iterations[k]), True, done,
                                           float(seconds[k]), float(phi_norm[k]),
                                           float(phi_top[k]))
            for k in range(n)]


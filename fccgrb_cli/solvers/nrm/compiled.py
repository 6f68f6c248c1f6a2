"""NRM through the compiled kernels: the frames run in machine code in blocks; Python steps in
for what only it does (the first guess after a gap in the history, the rank test of a new set
of missing markers, progress, messages). Same iteration as the numpy path in nrm/solve.py, to
rounding (tests/test_kernels.py)."""

from __future__ import annotations

import time as clock
from collections.abc import Callable

import numpy as np

from fccgrb_cli.core.errors import InputError
from fccgrb_cli.solvers import kernels
from fccgrb_cli.solvers.engine import ready
from fccgrb_cli.solvers.initial import initial_guess
from fccgrb_cli.solvers.mixed import mixed_result
from fccgrb_cli.solvers.nrm.problem import (
    HISTORY,
    NrmSettings,
    no_convergence_text,
    row_weights,
    solvable,
    unsolvable_text,
    without_gaps,
)
from fccgrb_cli.solvers.result import FrameStats, KinematicResult
from fccgrb_cli.system import System
from fccgrb_cli.system.sparse import sparse_of

BLOCK = 2000  # frames per call between progress reports
HESSIAN_CODES = {"gauss-newton": 0, "exact": 1, "auto": 2}


def solve_compiled(system: System, time: np.ndarray, targets: np.ndarray,
                   settings: NrmSettings, *, labels: tuple[str, ...], source: str = "",
                   progress: Callable[[int, int], None] | None = None) -> KinematicResult:
    """solve_nrm with the compiled kernels. Per-frame seconds are each block's time shared
    equally among its frames (the kernels do not read the clock)."""
    s = sparse_of(system)
    n, nq = len(time), system.nq
    targets = np.ascontiguousarray(targets, dtype=float)
    missing = ~np.all(np.isfinite(targets), axis=2)
    patterns, pattern_of = np.unique(missing, axis=0, return_inverse=True)
    pattern_of = pattern_of.ravel().astype(np.int64)
    state = FrameState(n, nq, len(patterns))
    base_w = row_weights(system, settings.tracking_weight)
    guess, use_guess = np.zeros(nq), False
    trial = kernels.NrmTrial(targets, missing, pattern_of, state.solvable, base_w)
    limits = kernels.Limits(settings.tol, settings.max_iter)
    extrapolate = settings.warm_start != "previous"
    outputs = kernels.FrameOutputs(state.q, state.iterations, state.phi_norm, state.phi_top,
                                   state.converged, state.unsolved)
    ready(kernels.solve_frames, s, trial, limits, HESSIAN_CODES[settings.hessian], 0, 0,
          kernels.WarmStart(guess, use_guess, state.history, state.counts, extrapolate),
          outputs)
    f = 0
    while f < n:
        stop = min(n, f + BLOCK)
        started = clock.perf_counter()
        g, reason = kernels.solve_frames(
            s, trial, limits, HESSIAN_CODES[settings.hessian], f, stop,
            kernels.WarmStart(guess, use_guess, state.history, state.counts, extrapolate),
            outputs)
        if g > f:
            state.seconds[f:g] = (clock.perf_counter() - started) / (g - f)
        use_guess = False
        if reason == kernels.NEED_GUESS:
            guess, use_guess = initial_guess(system, targets[g]), True
        elif reason == kernels.NEED_RANK:
            ok = solvable(system, guess, without_gaps(base_w, system, missing[g]))
            state.solvable[pattern_of[g]] = kernels.SOLVABLE if ok else kernels.UNSOLVABLE
            if not ok and not settings.skip_unsolvable:
                raise InputError(unsolvable_text(g, time, missing[g], labels, source))
            use_guess = True
        if progress is not None and g > f:
            progress(g, n)
        f = g
    return mixed_result(
        system, time, state.q,
        FrameStats(state.iterations, state.seconds, state.phi_norm, state.phi_top,
                   state.converged, messages=state.messages(time, missing, labels, source)),
        method=settings.method, tol=settings.tol, compiled=True)


class FrameState:
    """The per-frame outputs and the loop's carried state, as the kernels fill them."""

    def __init__(self, n: int, nq: int, n_patterns: int) -> None:
        self.q = np.zeros((n, nq))
        self.iterations = np.zeros(n, dtype=np.int64)
        self.seconds = np.zeros(n)
        self.phi_norm = np.full(n, np.nan)
        self.phi_top = np.full(n, np.nan)
        self.converged = np.zeros(n, dtype=bool)
        self.unsolved = np.zeros(n, dtype=bool)
        self.history = np.zeros((HISTORY, nq))
        self.counts = np.zeros(2, dtype=np.int64)
        self.solvable = np.full(n_patterns, kernels.UNKNOWN, dtype=np.int64)

    def messages(self, time: np.ndarray, missing: np.ndarray, labels: tuple[str, ...],
                 source: str) -> list[str]:
        """Frame by frame, as the numpy path words them."""
        out = []
        for f in np.flatnonzero(self.unsolved | ~self.converged):
            if self.unsolved[f]:
                out.append(unsolvable_text(int(f), time, missing[f], labels, source)
                           + "; frame left unsolved")
            else:
                out.append(no_convergence_text(int(f), time, int(self.iterations[f])))
        return out

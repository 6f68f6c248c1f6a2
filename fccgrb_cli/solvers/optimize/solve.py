"""Frames through the optimization methods, sequentially or over a process pool.

Sequential: each frame starts from the previous solution (extrapolated, or as it is), the first
from the rigid-fit initializer. Parallel (the paper's §4.2): every frame is solved independently
from the same initial guess, which the paper found noisy; two remedies are offered: contiguous
chunks solved sequentially within each worker ('chunks'), or NRM-WLS positions as each frame's
initial guess ('nrm', the default). After a remedy's parallel pass, every frame the quality
checks flag (unconverged, a jump, another assembly branch) is re-solved in order from a trusted
neighbour (:func:`repair`), which gives the sequential answer; 'same' is kept without it, to
reproduce the paper. The compiled system reaches each worker once, at its start.
"""

from __future__ import annotations

import os
import time as clock
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, replace
from itertools import pairwise
from typing import TYPE_CHECKING

import numpy as np

from fccgrb_cli.blas import limit_this_process, single_threaded
from fccgrb_cli.solvers.cno.reference import solve_cno_frame
from fccgrb_cli.solvers.optimize.problem import FrameProblem
from fccgrb_cli.solvers.goal.reference import FrameOutcome, solve_goal_frame
from fccgrb_cli.solvers.goal.sqp import FAR as FAR_GOAL
from fccgrb_cli.solvers.goal.sqp import MAX_ITER as MAX_GOAL
from fccgrb_cli.solvers.goal.sqp import active_set_sqp
from fccgrb_cli.solvers.initial import initial_guess
from fccgrb_cli.solvers.newton import Iterate, gauss_newton
from fccgrb_cli.solvers.nrm.solve import (
    NrmSettings,
    mixed_result,
    predict,
    row_weights,
    solve_nrm,
    use_kernels,
    without_gaps,
)
from fccgrb_cli.solvers.quality import flags_of
from fccgrb_cli.solvers.result import FrameStats, KinematicResult
from fccgrb_cli.solvers.cno.sqp import FAR, sqp_weights, stabilized_sqp
from fccgrb_cli.solvers.cno.sqp import MAX_ITER as MAX_SQP
from fccgrb_cli.system import System

if TYPE_CHECKING:
    from fccgrb_cli.options import SolveOptions

METHODS = ("cno-sqp", "cno-ip", "mo-tc", "mo-ed")
PARALLEL_INITS = ("same", "chunks", "nrm")
REJOINED = 1e-6
COMPILED_FROM = 200
STRUCTURED = {method: (name, f"{name}: converged successfully") for method, name in
              (("cno-sqp", "stabilized SQP"), ("cno-ip", "interior point"),
               ("mo-tc", "active-set SQP"), ("mo-ed", "active-set SQP"))}
CONVERGED = STRUCTURED["cno-sqp"][1]


@dataclass(frozen=True)
class Settings:
    """An optimization method: ``method`` (one of METHODS), CNO ``objective`` ('tc' or 'ed'),
    tolerance and iteration cap per frame, the warm start of each frame; ``parallel``: frames
    over ``workers`` processes, each from its ``init`` guess (PARALLEL_INITS; 'nrm' solves
    NRM-WLS first with tracking weight ``nrm_weight``)."""

    method: str
    objective: str = "tc"
    tol: float = 1e-10
    max_iter: int = 500
    warm_start: str = "extrapolate"
    parallel: bool = False
    workers: int | None = None
    init: str = "nrm"
    nrm_weight: float = 1e-3
    optimizer: str = "auto"
    engine: str = "auto"

    @classmethod
    def from_options(cls, o: SolveOptions) -> Settings:
        return cls(o.method, o.objective, o.tol, o.max_iter or 500, o.warm_start, o.parallel,
                   o.workers, o.parallel_init, o.tracking_weight, o.optimizer, o.engine)

    @property
    def structured(self) -> bool:
        """Whether the engine's own optimizer runs: CNO with the TC objective by the stabilized
        SQP or its interior point (solvers/sqp.py), goal attainment by the active-set SQP
        (solvers/goal_sqp.py). 'auto' takes it for CNO only: goal attainment's optimum on noisy
        markers is a face, the structured method's point on it drifts smoothly from frame to
        frame where SLSQP's jumps, and the jump flag (solvers/quality.py) that marks MO's
        frames as untrustworthy then misses some (4 frames of the five-bar at 30 mm, whose
        joint moments are 3–3.5× NRM-WLS's worst); 'structured' takes it for MO too. CNO-ED,
        and ``optimizer='scipy'``, run through scipy (the paper's reference)."""
        if self.optimizer == "scipy" or (self.method.startswith("cno")
                                         and self.objective != "tc"):
            return False
        return self.optimizer == "structured" or self.method.startswith("cno")

    @property
    def reference(self) -> str:
        """The scipy method a structured frame falls back to."""
        return "trust-constr" if self.method == "cno-ip" else "SLSQP"


@dataclass(frozen=True)
class FrameRecord:
    q: np.ndarray
    iterations: int
    converged: bool
    message: str
    seconds: float
    phi_norm: float
    phi_top: float


def _optimize(problem: FrameProblem, settings: Settings, q0: np.ndarray,
              attempt: Iterate | None = None) -> FrameOutcome:
    """One frame from q0; ``attempt``: the structured optimizer's result from q0 where the
    compiled kernels already ran it."""
    if settings.structured:
        out = verdict(problem, settings, attempt or structured_frame(problem, settings, q0))
        if out.converged:
            return out
        scipy = _optimize(problem, replace(settings, optimizer="scipy"), q0)
        return FrameOutcome(scipy.q, out.iterations + scipy.iterations, scipy.converged,
                            f"{out.message}; {settings.reference}: {scipy.message}")
    if problem.system.redundant_topology:  # SLSQP and trust-constr need independent equalities
        problem.keep_independent(q0)
    if settings.method.startswith("cno"):
        return solve_cno_frame(problem, q0, algorithm=settings.method[4:],
                               objective=settings.objective, tol=settings.tol,
                               max_iter=settings.max_iter)
    return solve_goal_frame(problem, q0, objective=settings.method[3:], tol=settings.tol,
                            max_iter=settings.max_iter)


def structured_frame(problem: FrameProblem, settings: Settings, q0: np.ndarray) -> Iterate:
    """One frame by the engine's structured optimizer (the stabilized SQP, its interior point
    inside the problem's bounds, or goal attainment's active-set SQP). A guess far off the
    constraints (a rigid fit: the first frame, or after a failure) first goes through NRM-WLS,
    whose line search these iterations lack; from the previous frames' extrapolation they start
    at once."""
    system, tol, max_iter = problem.system, settings.tol, settings.max_iter
    before = 0
    goal = settings.method.startswith("mo")
    if np.abs(problem.constraints(q0)).max(initial=0.0) > (FAR_GOAL if goal else FAR):
        weights = without_gaps(row_weights(system, 1e-3), system, problem.missing)
        start = gauss_newton(system, q0, problem.drive, weights, tol, min(max_iter, 50), "auto")
        q0, before = start.q, start.iterations
    interior = settings.method == "cno-ip"
    if goal:
        it, _ = active_set_sqp(problem, q0, settings.method[3:], tol, min(max_iter, MAX_GOAL))
    else:
        it = stabilized_sqp(system, q0, problem.drive,
                            sqp_weights(system, problem.point_weights), tol,
                            min(max_iter, MAX_SQP), problem.bound_arrays() if interior else None)
    return Iterate(it.q, before + it.iterations, it.converged)


def verdict(problem: FrameProblem, settings: Settings, it: Iterate) -> FrameOutcome:
    """A structured optimizer's iterate judged: converged, and inside the problem's bounds."""
    name, done = STRUCTURED[settings.method]
    if not it.converged:
        return FrameOutcome(it.q, it.iterations, False,
                            f"{name}: no convergence in {it.iterations} iterations")
    if not within_bounds(problem, it.q):
        return FrameOutcome(it.q, it.iterations, False,
                            f"{name}: the optimum lies outside the bounds")
    return FrameOutcome(it.q, it.iterations, True, done)


def within_bounds(problem: FrameProblem, q: np.ndarray) -> bool:
    lower, upper = problem.bound_arrays()
    return bool(np.all((q >= lower) & (q <= upper)))


def solve_frame(system: System, settings: Settings, q0: np.ndarray, y: np.ndarray,
                attempt: Iterate | None = None) -> FrameRecord:
    """One frame with the chosen optimizer, timed, with its statistics (``attempt``: see
    :func:`_optimize`). A frame the optimizer fails from q0 is retried once from that frame's
    NRM-WLS solution (goal attainment's optimum is flat where markers are noisy, and SLSQP can
    wander off it); both tries are counted."""
    started = clock.perf_counter()
    problem = FrameProblem(system, y)
    out = _optimize(problem, settings, q0, attempt)
    if not out.converged:
        weights = without_gaps(row_weights(system, 1e-3), system, problem.missing)
        start = gauss_newton(system, q0, problem.drive, weights, settings.tol, 50, "auto")
        retry = _optimize(problem, settings, start.q)
        out = FrameOutcome(retry.q, out.iterations + start.iterations + retry.iterations,
                           retry.converged,
                           f"{out.message}; retried from the NRM-WLS solution: {retry.message}")
    seconds = clock.perf_counter() - started
    phi_norm, phi_top = problem.statistics(out.q)
    return FrameRecord(out.q, out.iterations, out.converged, out.message, seconds, phi_norm,
                       phi_top)


def _run_frames(system: System, settings: Settings, targets: np.ndarray, frames: list[int],
                guess: Callable[[int], np.ndarray], chained: bool,
                progress: Callable[[int, int], None] | None = None) -> list[FrameRecord]:
    """Frames in order; ``chained``: each starts from the previous solution (the first, and any
    after a failure, from ``guess(frame)``), else each from ``guess(frame)``."""
    out: list[FrameRecord] = []
    history: list[np.ndarray] = []
    for f in frames:
        q0 = predict(history, settings.warm_start, points=3) if (chained and history) \
            else guess(f)
        record = solve_frame(system, settings, q0, targets[f])
        out.append(record)
        history = [*history[-2:], record.q] if record.converged else []
        if progress is not None:
            progress(len(out), len(frames))
    return out


_WORKER: dict = {}


def _install(system: System, targets: np.ndarray, settings: Settings) -> None:
    limit_this_process()
    _WORKER.update(system=system, targets=targets, settings=settings)


def _work(frames: list[int], guesses: list[np.ndarray], chained: bool) -> list[FrameRecord]:
    w = _WORKER
    by_frame = dict(zip(frames, guesses, strict=True))
    return _run_frames(w["system"], w["settings"], w["targets"], frames, by_frame.__getitem__,
                       chained)


@single_threaded
def solve_optimization(system: System, time: np.ndarray, targets: np.ndarray,
                       settings: Settings,
                       progress: Callable[[int, int], None] | None = None) -> KinematicResult:
    """Every frame (targets: frames × n_targets × 3, m, NaN in gaps) with one optimizer."""
    if settings.method not in METHODS:
        raise ValueError(f"unknown optimization method {settings.method!r}")
    n = len(time)
    started = clock.perf_counter()
    first = initial_guess(system, targets[0])
    label = settings.method + ("-ed" if settings.method.startswith("cno")
                               and settings.objective == "ed" else "")
    init = settings.init
    compiled = not settings.parallel and compiled_structured(system, settings, n)
    if compiled:
        from fccgrb_cli.solvers.optimize.compiled import run_frames_compiled

        records = run_frames_compiled(system, settings, targets, progress)
        wall = float("nan")
    elif not settings.parallel:
        records = _run_frames(
            system, settings, targets, list(range(n)),
            lambda f: first if f == 0 else initial_guess(system, targets[f]), True, progress)
        wall = float("nan")
    else:
        records = _parallel(system, time, targets, settings, first, progress)
        resolved = 0 if init == "same" else repair(system, settings, targets, records)
        wall = clock.perf_counter() - started
        label += "-parallel" + ("" if init == "same" else f"-{init}")
    messages = [f"frame index {f} (t = {time[f]:.3f} s): {r.message}"
                for f, r in enumerate(records) if not r.converged]
    if settings.parallel and init != "same" and resolved:
        messages.append(f"{label}: {resolved} frames re-solved in order from a trusted "
                        "neighbour after the parallel pass (frames that failed, jumped or "
                        "left the branch of their neighbours)")
    stats = FrameStats(np.array([r.iterations for r in records]),
                       np.array([r.seconds for r in records]),
                       np.array([r.phi_norm for r in records]),
                       np.array([r.phi_top for r in records]),
                       np.array([r.converged for r in records]),
                       tuple(r.message for r in records))
    return mixed_result(system, time, np.array([r.q for r in records]), stats, method=label,
                        tol=settings.tol, messages=messages, wall_s=wall, compiled=compiled)


def compiled_structured(system: System, settings: Settings, n_frames: int) -> bool:
    """Whether the sequential structured optimizer runs in the compiled kernels
    (nrm.use_kernels), 'auto' from ``COMPILED_FROM`` frames (its numpy path costs ~1 ms a
    frame, so numba's ~0.25 s start pays from a few hundred). MO-ED needs each point's distance
    curvature inside the factor's envelope (goal_kernels.ed_fits)."""
    from fccgrb_cli.system.sparse import supported

    fits = supported(system)
    if fits and settings.method == "mo-ed":
        from fccgrb_cli.solvers.goal.kernels import ed_fits
        from fccgrb_cli.solvers.nrm.compiled import sparse_of

        fits = ed_fits(sparse_of(system), len(system.trk_weight))
    return settings.structured and use_kernels(settings.engine, fits, n_frames,
                                               COMPILED_FROM)


def _parallel(system: System, time: np.ndarray, targets: np.ndarray, settings: Settings,
              first: np.ndarray, progress: Callable[[int, int], None] | None
              ) -> list[FrameRecord]:
    init = settings.init
    if init not in PARALLEL_INITS:
        raise ValueError(f"unknown parallel initialization {init!r}")
    workers = settings.workers or os.cpu_count() or 1
    n = len(time)
    if init == "nrm":
        guesses = list(solve_nrm(system, time, targets,
                                 NrmSettings(settings.nrm_weight, settings.tol)).q)
    else:
        guesses = [first] * n
    pieces = workers if init == "chunks" else max(1, min(n, 4 * workers))
    bounds = np.linspace(0, n, pieces + 1).round().astype(int)
    tasks = []
    for a, b in pairwise(bounds):
        frames = list(range(a, b))
        if not frames:
            continue
        chunk_guesses = [guesses[f] for f in frames]
        if init == "chunks":
            chunk_guesses[0] = initial_guess(system, targets[a])
        tasks.append((frames, chunk_guesses, init == "chunks"))
    records: list[FrameRecord | None] = [None] * n
    done = 0
    with ProcessPoolExecutor(max_workers=workers, initializer=_install,
                             initargs=(system, targets, settings)) as pool:
        futures = [(task[0], pool.submit(_work, *task)) for task in tasks]
        for frames, future in futures:
            for f, record in zip(frames, future.result(), strict=True):
                records[f] = record
            done += len(frames)
            if progress is not None:
                progress(done, n)
    return records


def tracked_points(system: System, q: np.ndarray) -> np.ndarray:
    """The tracked model points (frames × points × 3) along a solution q (frames × nq)."""
    rows = system.trk_a[: len(system.model.tracked_points)]
    return np.array([system.features(system.layout.expand(qf))[rows] for qf in q])


def objective_value(problem: FrameProblem, settings: Settings, q: np.ndarray) -> float:
    """What the method minimizes at q: Σ w‖d‖² or Σ w‖d‖ (CNO), the largest weighted
    component or distance (MO)."""
    if settings.method.startswith("cno"):
        return (problem.tc if settings.objective == "tc" else problem.ed)(q)[0]
    active = problem.point_weights > 0
    if settings.method == "mo-tc":
        d = np.abs(problem.residuals(q)[0][active]) / problem.point_weights[active, None]
    else:
        d = problem.distances(q)[0][active] / problem.point_weights[active]
    return float(d.max(initial=0.0))


def repair(system: System, settings: Settings, targets: np.ndarray,
           records: list[FrameRecord], passes: int = 2) -> int:
    """Re-solve, in place, the frames a parallel pass got wrong, and say how many solves it took.

    Frames flagged by the quality checks (solvers/quality.py: unconverged, broken topology,
    a jump) are solved again in order, each from its trusted neighbour's solution, forwards and
    then backwards; the continuation goes on past the flagged frames while its solutions differ
    from the stored ones (frames between two jumps sit on another assembly branch without
    jumping themselves) and fit no worse, and stops where it rejoins them. A flagged frame keeps
    its first solution when the continued one fits worse (the jump is then the trial's own)."""
    n = len(records)
    markers = targets[:, : len(system.model.tracked_points)]
    resolved = 0
    for _ in range(passes):
        bad = flags_of(settings.method, np.array([r.converged for r in records]),
                       np.array([r.phi_top for r in records]),
                       tracked_points(system, np.array([r.q for r in records])), markers) != 0
        if not bad.any() or bad.all():
            break
        changed = False
        for step in (1, -1):
            for f in range(n) if step == 1 else range(n - 1, -1, -1):
                if not bad[f] or not 0 <= f - step < n or bad[f - step]:
                    continue
                history, g = [records[f - step].q], f
                while 0 <= g < n:
                    new, old = solve_frame(system, settings,
                                           predict(history, settings.warm_start, 3),
                                           targets[g]), records[g]
                    resolved += 1
                    rejoined = bool(np.abs(new.q - old.q).max() <= REJOINED)
                    problem = FrameProblem(system, targets[g])
                    better = objective_value(problem, settings, new.q) <= \
                        objective_value(problem, settings, old.q) * (1 + 1e-6) + 1e-12
                    if not new.converged or not (better or not old.converged):
                        break
                    records[g], bad[g], changed = new, False, True
                    if rejoined:
                        break
                    history = [*history[-2:], new.q]
                    g += step
        if not changed:
            break
    return resolved

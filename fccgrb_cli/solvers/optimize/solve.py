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
from itertools import pairwise
from typing import TYPE_CHECKING

import numpy as np

from fccgrb_cli.core.blas import limit_this_process, single_threaded
from fccgrb_cli.core.scratch import die_with_parent
from fccgrb_cli.solvers.engine import use_kernels
from fccgrb_cli.solvers.initial import initial_guess
from fccgrb_cli.solvers.mixed import mixed_result
from fccgrb_cli.solvers.nrm.problem import NrmSettings, predict
from fccgrb_cli.solvers.nrm.solve import solve_nrm
from fccgrb_cli.solvers.optimize.frame import (
    FrameRecord,
    Settings,
    method_label,
    solve_frame,
)
from fccgrb_cli.solvers.optimize.problem import FrameProblem
from fccgrb_cli.solvers.quality import flags_of
from fccgrb_cli.solvers.result import FrameStats, KinematicResult
from fccgrb_cli.system import System

if TYPE_CHECKING:
    pass

METHODS = ("cno-sqp", "cno-ip", "mo-tc", "mo-ed")
PARALLEL_INITS = ("same", "chunks", "nrm")
REJOINED = 1e-6


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


def _install(system: System, targets: np.ndarray, settings: Settings, parent: int) -> None:
    die_with_parent(parent)
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
    label = method_label(settings.method, settings.objective, settings.parallel, settings.init)
    init = settings.init
    compiled = not settings.parallel and compiled_structured(system, settings)
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
                       tuple(r.message for r in records), messages, wall)
    return mixed_result(system, time, np.array([r.q for r in records]), stats, method=label,
                        tol=settings.tol, compiled=compiled)


def compiled_structured(system: System, settings: Settings) -> bool:
    """Whether the sequential structured optimizer runs in the compiled kernels
    (engine.use_kernels). MO-ED needs each point's distance curvature inside the factor's
    envelope (goal/kernels.py's ed_fits)."""
    from fccgrb_cli.system.sparse import supported

    fits = supported(system)
    if fits and settings.method == "mo-ed":
        from fccgrb_cli.solvers.goal.kernels import ed_fits
        from fccgrb_cli.system.sparse import sparse_of

        fits = ed_fits(sparse_of(system), len(system.trk_weight))
    return settings.structured and use_kernels(settings.engine, fits)


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
                             initargs=(system, targets, settings, os.getpid())) as pool:
        futures = [(task[0], pool.submit(_work, *task)) for task in tasks]
        for frames, future in futures:
            for f, record in zip(frames, future.result(), strict=True):
                records[f] = record
            done += len(frames)
            if progress is not None:
                progress(done, n)
    assert all(record is not None for record in records)  # the tasks cover every frame
    return [record for record in records if record is not None]


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

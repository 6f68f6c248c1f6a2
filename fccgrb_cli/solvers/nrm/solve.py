"""Mixed coordinates solved with Newton–Raphson on weighted least squares (NRM LS / WLS).

Topology + MCR + TC/TOC is over-determined; each frame solves the Gauss–Newton normal equations
(Φ_qᵀ W Φ_q) Δq = −Φ_qᵀ W Φ with W = diag(1 for topological rows, w for tracking rows): LS is
W = I, WLS takes w = 1e-3 unless a tracked point has its own weight (docs/formulation.md §3, paper
§2.5). A marker missing in a frame (NaN) drops its tracking rows for that frame only.
"""

from __future__ import annotations

import time as clock
from collections.abc import Callable

import numpy as np

from fccgrb_cli.core.blas import single_threaded
from fccgrb_cli.core.errors import InputError
from fccgrb_cli.solvers.initial import initial_guess
from fccgrb_cli.solvers.mixed import mixed_result
from fccgrb_cli.solvers.newton import Iterate, gauss_newton
from fccgrb_cli.solvers.nrm.problem import (
    HISTORY,
    SMOOTH,
    NrmSettings,
    no_convergence_text,
    predict,
    row_weights,
    solvable,
    unsolvable_text,
    without_gaps,
)
from fccgrb_cli.solvers.result import FrameStats, KinematicResult
from fccgrb_cli.system import Drive, System


@single_threaded
def solve_nrm(system: System, time: np.ndarray, targets: np.ndarray,
              settings: NrmSettings = NrmSettings(), *, labels: tuple[str, ...] = (),
              source: str = "", progress: Callable[[int, int], None] | None = None
              ) -> KinematicResult:
    """Solve every frame; ``targets`` is (frames × n_targets × 3), metres, NaN in gaps;
    ``labels`` name the targets and ``source`` the trial in messages."""
    tracking_weight, tol, max_iter = settings.tracking_weight, settings.tol, settings.max_iter
    warm_start, hessian = settings.warm_start, settings.hessian
    if not system.mixed or not system.n_targets:
        raise ValueError("solve_nrm needs angles='coordinate' and track=True")
    labels = labels or tuple(f"target {k}" for k in range(system.n_targets))
    if settings.compiled(system):
        from fccgrb_cli.solvers.nrm.compiled import solve_compiled

        return solve_compiled(system, time, targets, settings, labels=labels, source=source,
                              progress=progress)
    n, nq = len(time), system.nq
    base_w = row_weights(system, tracking_weight)
    top = system.masks()["topology"]
    q_all = np.zeros((n, nq))
    iterations = np.zeros(n, dtype=int)
    seconds = np.zeros(n)
    phi_norm = np.full(n, np.nan)
    phi_top = np.full(n, np.nan)
    converged = np.zeros(n, dtype=bool)
    messages: list[str] = []
    checked: dict[bytes, bool] = {}
    history: list[np.ndarray] = []
    last_iterations = 0
    for f in range(n):
        started = clock.perf_counter()
        y = targets[f]
        missing = ~np.all(np.isfinite(y), axis=1)
        w = without_gaps(base_w, system, missing)
        if missing.any():
            y = np.where(missing[:, None], 0.0, y)
        drive = Drive(ref=y)
        # high-order extrapolation only while the motion is smooth (the last frame converged
        # quickly); on rough data it overshoots, and the quadratic guess is the safer one
        points = HISTORY if last_iterations <= SMOOTH else 3
        q = predict(history, warm_start, points) if history else initial_guess(system,
                                                                                targets[f])
        key = missing.tobytes()
        if key not in checked:
            checked[key] = solvable(system, q, w)
        if not checked[key]:
            text = unsolvable_text(f, time, missing, labels, source)
            if not settings.skip_unsolvable:
                raise InputError(text)
            messages.append(text + "; frame left unsolved")
            q_all[f] = np.nan
            continue
        it = gauss_newton(system, q, drive, w, tol, max_iter if history else 4 * max_iter,
                          hessian=hessian)
        if not it.converged and history and warm_start != "previous":
            # rough data can send an extrapolated guess astray: retry from the last solution
            again = gauss_newton(system, history[-1], drive, w, tol, max_iter, hessian=hessian)
            it = Iterate(again.q, it.iterations + again.iterations, again.converged)
        seconds[f] = clock.perf_counter() - started
        q_all[f] = it.q
        iterations[f], converged[f] = it.iterations, it.converged
        last_iterations = it.iterations
        if it.converged:
            history = [*history[-(HISTORY - 1):], it.q]
        else:
            messages.append(no_convergence_text(f, time, it.iterations))
            history = []
        phi = system.residual(it.q, drive)
        phi_norm[f] = np.linalg.norm(phi[w > 0])
        phi_top[f] = np.abs(phi[top]).max()
        if progress is not None:
            progress(f + 1, n)
    return mixed_result(system, time, q_all,
                        FrameStats(iterations, seconds, phi_norm, phi_top, converged,
                                   messages=messages),
                        method=settings.method, tol=tol)



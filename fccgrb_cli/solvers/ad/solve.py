"""Kinematic analysis with angular drivers (AD): Φ(q, t) = 0 with AR drivers (Eq. 23–28).

Positions by Newton–Raphson frame by frame, each frame warm-started from the previous one
(extrapolated with its velocity and acceleration), then Φ_q q̇ = ν and Φ_q q̈ = γ
(``solve_ad``). When a good guess is known for every frame (the converted model of
docs/formulation.md §4: the mixed-coordinate solution's bodies already satisfy the topology and the
drivers it becomes), the frames are independent and ``solve_ad_batched`` solves them all at
once on stacked arrays, the frames that do not converge in a few iterations going through the
frame-by-frame path.
"""

from __future__ import annotations

import time as clock
from collections.abc import Callable
from dataclasses import replace

import numpy as np

from fccgrb_cli.core.blas import single_threaded
from fccgrb_cli.core.errors import InputError
from fccgrb_cli.solvers.batched import Drives, Stacked, blocks, factor, newton_stacked
from fccgrb_cli.solvers.kernel_arrays import DrivenMotion, Drivers, Limits
from fccgrb_cli.solvers.newton import linear_solve, newton_raphson
from fccgrb_cli.solvers.quality import BRANCH, FLAG_DTYPE
from fccgrb_cli.solvers.result import KinematicResult
from fccgrb_cli.system import Drive, System

ASSEMBLY_STEP = np.radians(5.0)
ASSEMBLY_STEP_DISTANCE = 0.02  # m
# Newton iterations a frame gets in the batch before it goes through the frame-by-frame path
BATCH_ITER = 8
MAX_ITER = 50  # Newton iterations of a frame on its own
Base = tuple[np.ndarray, np.ndarray, np.ndarray]


def assemble(system: System, q_guess: np.ndarray, theta: np.ndarray, tol: float,
             max_iter: int, base: np.ndarray | None = None) -> np.ndarray:
    """Bring a guess (e.g. the model's stated pose) to the configuration with coordinates θ,
    moving the drivers from the guess's own values to θ in steps of at most 5° for an angle and
    2 cm for a distance (a homotopy)."""
    start = system.angles_at(q_guess)
    # a signed angle is met at its nearest turn: the homotopy never sweeps whole turns
    full = system.full_angles
    start[full] += 2 * np.pi * np.round((theta[full] - start[full]) / (2 * np.pi))
    step = np.where(system.distance_rows, ASSEMBLY_STEP_DISTANCE, ASSEMBLY_STEP)
    n_steps = max(1, int(np.ceil(np.max(np.abs(theta - start) / step, initial=0.0))))
    zeros = np.zeros_like(theta)
    q = q_guess
    for k in range(1, n_steps + 1):
        target = start + (theta - start) * k / n_steps
        ref = np.zeros((0, 3)) if base is None else base
        it = newton_raphson(system, q, Drive(target, zeros, zeros, ref), tol, max_iter)
        if not it.converged:
            raise InputError(
                f"{system.model.source}: could not assemble the model from its initial pose to "
                f"the first frame's angles (step {k} of {n_steps}); check the bodies' poses")
        q = it.q
    return q


def stacked_drives(system: System, theta: np.ndarray, theta_d: np.ndarray,
                   theta_dd: np.ndarray, base: Base | None) -> Drives:
    """Every frame's drive: θ*, θ̇*, θ̈* and the floating bases' driven features and their
    rates (frames × slots × 3 each, see ``System.base_reference``; required when the model has
    floating bases)."""
    if system.n_base_slots and base is None:
        raise ValueError("a model with a floating base needs its base trajectory")
    if system.mixed:
        raise ValueError("solve_ad needs a system compiled with angles='driver'")
    empty = np.zeros((len(theta), system.n_base_slots, 3))
    ref, ref_d, ref_dd = base if base is not None else (empty, empty, empty)
    return Drives(np.asarray(theta), np.asarray(theta_d), np.asarray(theta_dd), ref, ref_d,
                  ref_dd)


def frame_rates(system: System, q: np.ndarray, drive: Drive) -> tuple[np.ndarray, np.ndarray]:
    """q̇ and q̈ of one frame: Φ_q q̇ = ν, Φ_q q̈ = γ (docs/formulation.md §3)."""
    J = system.jacobian(q)
    qd = linear_solve(J, system.nu(q, drive))
    return qd, linear_solve(J, system.gamma(q, qd, drive))


@single_threaded
def solve_ad(system: System, time: np.ndarray, drives: Drives, q_guess: np.ndarray, *,
             tol: float = 1e-10, max_iter: int = MAX_ITER,
             progress: Callable[[int, int], None] | None = None,
             continuation: bool = False) -> KinematicResult:
    """AD analysis over all frames driven by ``drives`` (see :func:`stacked_drives`: θ, θ̇, θ̈
    frames × n_coordinates in rad, rad/s, rad/s², m, m/s, m/s² for distances, and the floating
    bases' driven features and rates).

    ``q_guess``: the first frame's starting configuration (nq; the model is assembled from it),
    each later frame starting from the previous one's q + q̇ dt + ½ q̈ dt²; or one start per
    frame (frames × nq: the classical model from the mixed solution's configuration, which keeps
    it on the mixed solution's assembly branch), a frame that does not converge from its own
    then starting from the previous frame's, and flagged ``BRANCH`` (solvers/quality.py): its
    branch is not known to be the mixed solution's. ``continuation``: predict from the last
    three solutions (q[f−3] − 3q[f−2] + 3q[f−1]) instead of the rates: at a singular position
    (a parallelogram's change point) Φ_q q̇ = ν has no unique solution and a rate-based step
    can leave the branch, while the solutions' own curve keeps to it (``synth``)."""
    n, nq = len(time), system.nq
    out = {k: np.zeros((n, nq)) for k in ("q", "qd", "qdd")}
    iterations = np.zeros(n, dtype=int)
    seconds = np.zeros(n)
    converged = np.zeros(n, dtype=bool)
    fallback = np.zeros(n, dtype=bool)
    phi = np.zeros((n, system.n_rows))
    starts = np.asarray(q_guess, dtype=float)
    own = starts.ndim == 2
    q = assemble(system, starts[0] if own else starts, drives.theta[0], tol, max_iter,
                 drives.ref[0])
    qd = qdd = np.zeros(nq)
    for f in range(n):
        drive = drives.frame(f)
        started = clock.perf_counter()
        predicted = q
        if f > 0:
            dt = time[f] - time[f - 1]  # rates undefined (NaN: too few frames) add nothing
            predicted = (out["q"][f - 3] - 3 * out["q"][f - 2] + 3 * q
                         if continuation and f >= 3 and converged[f - 3:f].all()
                         else q + np.nan_to_num(qd) * dt + 0.5 * np.nan_to_num(qdd) * dt * dt)
        it = None
        if own and f > 0 and np.isfinite(starts[f]).all():
            it = newton_raphson(system, starts[f], drive, tol, max_iter)
            fallback[f] = not it.converged
        if it is None or not it.converged:
            it = newton_raphson(system, predicted, drive, tol, max_iter)
        q = it.q
        qd, qdd = frame_rates(system, q, drive)
        seconds[f] = clock.perf_counter() - started
        phi[f] = system.residual(q, drive)
        out["q"][f], out["qd"][f], out["qdd"][f] = q, qd, qdd
        iterations[f], converged[f] = it.iterations, it.converged
        if progress is not None:
            progress(f + 1, n)
    motion = DrivenMotion(out["q"], out["qd"], out["qdd"], phi, iterations, converged)
    result = _result(system, time, drives, motion, seconds, tol)
    return replace(result, flags=np.where(fallback, BRANCH, 0).astype(FLAG_DTYPE)) if own \
        else result


@single_threaded
def solve_ad_batched(system: System, time: np.ndarray, drives: Drives, guesses: np.ndarray, *,
                     tol: float = 1e-10, progress: Callable[[int, int], None] | None = None,
                     compiled: bool = False, inverse: tuple | None = None) -> KinematicResult:
    """``solve_ad`` with every frame solved at once from its own guess (``guesses``: frames
    × nq, e.g. the mixed-coordinate solution's body coordinates): Newton–Raphson on the
    stacked frames (``batched.newton_stacked``, ``BATCH_ITER`` iterations), then each frame
    the batch left unconverged by Newton–Raphson from its guess with every iteration, and
    failing that (or without a finite guess) by ``solve_ad``'s own path, in order: assembled
    from its guess (the first frame) or extrapolated from the previous frame's q, q̇, q̈ —
    flagged ``BRANCH`` (solvers/quality.py), since that start may lie on another assembly
    branch than the guesses. Velocities and accelerations by stacked solves of Φ_q q̇ = ν and
    Φ_q q̈ = γ. Same answers as ``solve_ad`` wherever both reach the configuration the guesses
    lie by; ``time_s`` is the whole solve's time shared evenly among the frames. ``compiled``:
    each frame's Newton iterations and rates in the compiled kernels (kernels.driven_frames)
    instead of the stacked numpy arrays, the same equations; ``inverse``: the kernels'
    inverse-dynamics arrays (dynamics.inverse.KernelInverse), filled for the frames they
    solve."""
    max_iter = MAX_ITER
    stacked = Stacked(system)
    started = clock.perf_counter()
    n = len(time)
    q = np.array(guesses, dtype=float)
    iterations = np.zeros(n, dtype=int)
    converged = np.zeros(n, dtype=bool)
    finite = np.flatnonzero(np.isfinite(q).all(axis=1))
    done = np.zeros(n, dtype=bool)  # q, q̇, q̈ and Φ in place (the compiled kernels')
    phi, qd, qdd = np.empty((n, system.n_rows)), np.empty_like(q), np.empty_like(q)
    if compiled:
        from fccgrb_cli.solvers.engine import ready
        from fccgrb_cli.solvers.kernels import NO_INVERSE, driven_frames
        from fccgrb_cli.system.sparse import sparse_of

        arrays = (drives.theta, drives.theta_d, drives.theta_dd, drives.ref, drives.ref_d,
                  drives.ref_dd)
        drivers = Drivers(*(np.ascontiguousarray(a, dtype=float) for a in arrays))
        limits = Limits(tol, min(BATCH_ITER, max_iter))
        motion = DrivenMotion(q, qd, qdd, phi, iterations, converged)
        inverse = NO_INVERSE if inverse is None else inverse
        s = sparse_of(system)
        started += ready(driven_frames, s, q[:0], drivers, limits,
                         DrivenMotion(*(a[:0] for a in motion)), inverse)
        driven_frames(s, q, drivers, limits, motion, inverse)
        done[:] = converged
    for block in blocks(len(finite)) if not compiled else ():
        frames = finite[block]
        it = newton_stacked(stacked, q[frames], drives.take(frames), tol,
                            min(BATCH_ITER, max_iter))
        q[frames], iterations[frames], converged[frames] = it.q, it.iterations, it.converged
    fallback = np.zeros(n, dtype=bool)
    for f in np.flatnonzero(~converged):
        one = None
        if f > 0 and np.isfinite(guesses[f]).all():  # its own guess, given every iteration
            one = newton_raphson(system, guesses[f], drives.frame(f), tol, max_iter)
            iterations[f] += one.iterations
        if one is None or not one.converged:
            fallback[f] = f > 0
            if f == 0:
                start = assemble(system, guesses[0], drives.theta[0], tol, max_iter,
                                 drives.ref[0])
            else:
                velocity, acceleration = frame_rates(system, q[f - 1], drives.frame(f - 1))
                dt = time[f] - time[f - 1]
                start = q[f - 1] + np.nan_to_num(velocity) * dt \
                    + 0.5 * np.nan_to_num(acceleration) * dt * dt
            one = newton_raphson(system, start, drives.frame(f), tol, max_iter)
            iterations[f] += one.iterations
        q[f], converged[f] = one.q, one.converged
    rest = np.flatnonzero(~done)
    for block in blocks(len(rest)):
        frames = rest[block]
        some = drives.take(frames)
        phi[frames], J = stacked.evaluate(q[frames], some)
        rates = factor(J)
        qd[frames] = rates.solve(stacked.nu(some))
        qdd[frames] = rates.solve(stacked.gamma(q[frames], qd[frames], some))
    seconds = np.full(n, (clock.perf_counter() - started) / max(n, 1))
    if progress is not None:
        progress(n, n)
    result = _result(system, time, drives, DrivenMotion(q, qd, qdd, phi, iterations, converged),
                     seconds, tol)
    return replace(result, flags=np.where(fallback, BRANCH, 0).astype(FLAG_DTYPE))


def _result(system: System, time: np.ndarray, drives: Drives, motion: DrivenMotion,
            seconds: np.ndarray, tol: float) -> KinematicResult:
    """The AD run's KinematicResult, with ‖Φ‖ and max |topological Φ| per frame (a block of
    frames at a time: a long trial's frames × rows temporaries would each be as large as Φ)."""
    q, qd, qdd, phi, iterations, converged = motion
    topology = system.masks()["topology"]
    phi_norm, phi_top = np.empty(len(q)), np.zeros(len(q))
    for b in blocks(len(q)):
        phi_norm[b] = np.linalg.norm(phi[b], axis=1)
        if topology.any():
            phi_top[b] = np.abs(phi[b][:, topology]).max(axis=1)
    return KinematicResult(
        method="ad", tol=tol, time=np.asarray(time, dtype=float), q=q, qd=qd, qdd=qdd,
        theta=drives.theta, theta_d=drives.theta_d, theta_dd=drives.theta_dd,
        angle_names=tuple(a.name for a in system.model.angles), iterations=iterations,
        time_s=seconds, phi_norm=phi_norm, phi_top_max=phi_top,
        converged=converged)

"""Kinematic analysis with angular drivers (AD): Φ(q, t) = 0 with AR drivers (Eq. 23–28).

Positions by Newton–Raphson frame by frame, each frame warm-started from the previous one
(extrapolated with its velocity and acceleration), then Φ_q q̇ = ν and Φ_q q̈ = γ.
"""

from __future__ import annotations

import time as clock
from collections.abc import Callable

import numpy as np

from fccgrb_cli.blas import single_threaded
from fccgrb_cli.errors import InputError
from fccgrb_cli.solvers.newton import linear_solve, newton_raphson
from fccgrb_cli.solvers.result import KinematicResult
from fccgrb_cli.system import Drive, System

ASSEMBLY_STEP = np.radians(5.0)
ASSEMBLY_STEP_DISTANCE = 0.02  # m


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


@single_threaded
def solve_ad(system: System, time: np.ndarray, theta: np.ndarray, theta_d: np.ndarray,
             theta_dd: np.ndarray, q_guess: np.ndarray, *, tol: float = 1e-10,
             max_iter: int = 50, base: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
             progress: Callable[[int, int], None] | None = None) -> KinematicResult:
    """AD analysis over all frames; θ, θ̇, θ̈ are (frames × n_coordinates) in rad, rad/s, rad/s²
    (m, m/s, m/s² for distances);
    ``base``: the floating bases' driven features and their rates (frames × slots × 3 each,
    see ``System.base_reference``), required when the model has floating bases."""
    if system.n_base_slots and base is None:
        raise ValueError("a model with a floating base needs its base trajectory")
    n_slots = system.n_base_slots
    empty = np.zeros((len(time), n_slots, 3))
    base_ref, base_d, base_dd = base if base is not None else (empty, empty, empty)
    if system.mixed:
        raise ValueError("solve_ad needs a system compiled with angles='driver'")
    n, nq = len(time), system.nq
    out = {k: np.zeros((n, nq)) for k in ("q", "qd", "qdd")}
    iterations = np.zeros(n, dtype=int)
    seconds = np.zeros(n)
    phi_norm = np.zeros(n)
    phi_top = np.zeros(n)
    converged = np.zeros(n, dtype=bool)
    topology = system.masks()["topology"]
    q = assemble(system, q_guess, theta[0], tol, max_iter, base_ref[0])
    qd = qdd = np.zeros(nq)
    for f in range(n):
        drive = Drive(theta[f], theta_d[f], theta_dd[f], base_ref[f], base_d[f], base_dd[f])
        started = clock.perf_counter()
        if f > 0:
            dt = time[f] - time[f - 1]
            q = q + qd * dt + 0.5 * qdd * dt * dt
        it = newton_raphson(system, q, drive, tol, max_iter)
        q = it.q
        J = system.jacobian(q)
        qd = linear_solve(J, system.nu(q, drive))
        qdd = linear_solve(J, system.gamma(q, qd, drive))
        seconds[f] = clock.perf_counter() - started
        phi = system.residual(q, drive)
        out["q"][f], out["qd"][f], out["qdd"][f] = q, qd, qdd
        iterations[f], converged[f] = it.iterations, it.converged
        phi_norm[f] = np.linalg.norm(phi)
        phi_top[f] = np.abs(phi[topology]).max() if topology.any() else 0.0
        if progress is not None:
            progress(f + 1, n)
    return KinematicResult(
        method="ad", tol=tol, time=np.asarray(time, dtype=float), q=out["q"], qd=out["qd"],
        qdd=out["qdd"], theta=np.asarray(theta), theta_d=np.asarray(theta_d),
        theta_dd=np.asarray(theta_dd), angle_names=tuple(a.name for a in system.model.angles),
        iterations=iterations, time_s=seconds, phi_norm=phi_norm, phi_top_max=phi_top,
        converged=converged)

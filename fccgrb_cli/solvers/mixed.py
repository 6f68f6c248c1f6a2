"""The result of any mixed-coordinate method from its solved q per frame: θ, θ̇, θ̈, q̇ and q̈
consistent with the topology (angles near 0 or π are the quality checks': solvers/quality.py)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from fccgrb_cli.solvers.rates import central_derivatives, consistent_rates
from fccgrb_cli.solvers.result import FrameStats, KinematicResult
from fccgrb_cli.solvers.turns import counted, gap_messages
from fccgrb_cli.system import System
from fccgrb_cli.system.constraints import floating_bases


def mixed_result(system: System, time: np.ndarray, q_all: np.ndarray, stats: FrameStats, *,
                 method: str, tol: float, compiled: bool = False) -> KinematicResult:
    """The result of any mixed-coordinate method: θ from q, θ̇ and θ̈ by central differences,
    consistent q̇ and q̈. A signed angle is the same
    configuration every 2π: frames solved apart (in parallel, or from a fresh guess after a gap)
    are brought onto one continuous count of turns (``turns.counted``: the converged frames
    only). ``compiled``: the rates through the compiled kernels (a solve that ran in them)."""
    n_body = system.layout.n_body_q
    full = n_body + np.flatnonzero(system.full_angles)
    gaps: list[str] = []
    if len(full):
        q_all = q_all.copy()
        solved = np.isfinite(q_all[:, full]).all(axis=1) & np.asarray(stats.converged, bool)
        q_all[:, full], uncertain = counted(q_all[:, full], solved)
        gaps = gap_messages(uncertain, time)
    theta = q_all[:, n_body:]
    dt = float(time[1] - time[0]) if len(time) > 1 else 1.0
    theta_d, theta_dd = central_derivatives(theta, dt)
    columns = np.concatenate([np.arange(n_body)[system.layout.q_slice(b)]
                              for b in floating_bases(system.model)] or [np.zeros(0, int)])
    base = (columns, *central_derivatives(q_all[:, columns], dt)) if columns.size else None
    qd, qdd = consistent_rates(system, q_all, theta_d, theta_dd, base, compiled=compiled)
    return KinematicResult(
        method=method, tol=tol, time=np.asarray(time, dtype=float), q=q_all, qd=qd, qdd=qdd,
        theta=theta, theta_d=theta_d, theta_dd=theta_dd, angle_names=system.layout.angle_names,
        iterations=stats.iterations, time_s=stats.seconds, phi_norm=stats.phi_norm,
        phi_top_max=stats.phi_top, converged=stats.converged,
        messages=(*stats.messages, *gaps),
        wall_s=stats.wall_s, status=stats.status)


def recounted(system: System, result: KinematicResult) -> KinematicResult:
    """A result merged from stretches solved apart (``stretches.merged``) with its signed angles
    on one count of turns over the whole trial (``turns.counted``, which each stretch's own
    result applied within it only); whole turns move θ (and the mixed coordinates in q) but not
    their rates. Gaps the count was carried across at over half a turn are warned of."""
    columns = np.flatnonzero(system.full_angles)
    if not len(columns):
        return result
    solved = np.isfinite(result.theta[:, columns]).all(axis=1) & np.asarray(result.converged,
                                                                            bool)
    new, uncertain = counted(result.theta[:, columns], solved)
    shift = np.where(solved[:, None], new - result.theta[:, columns], 0.0)
    theta = result.theta.copy()
    theta[:, columns] += shift
    q = result.q
    if q.shape[1] > system.layout.n_body_q:  # the angles are coordinates (mixed methods)
        q = q.copy()
        q[:, system.layout.n_body_q + columns] += shift
    return replace(result, theta=theta, q=q,
                   messages=(*result.messages, *gap_messages(uncertain, result.time)))

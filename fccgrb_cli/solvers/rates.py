"""Velocities and accelerations of a mixed-coordinate solution, consistent with the topology.

θ̇ and θ̈ come from the solved θ(t) by central differences; the body coordinates then follow
from the topological equations (rigid body, joints, MCR) as in the converted model of
docs/formulation.md §4: Φ_q,body q̇_b = −Φ_θ θ̇ and Φ_q,body q̈_b = γ − Φ_θ θ̈.
"""

from __future__ import annotations

import numpy as np

from fccgrb_cli.solvers.batched import Drives, Stacked, blocks, factor
from fccgrb_cli.system import System

MIN_FRAMES = 3  # a second derivative needs three samples


def central_derivatives(y: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """First and second derivatives along axis 0: 3-point central stencils inside, second-order
    one-sided stencils at the ends (4 samples; 3 give the one central second derivative at
    every sample; 2 a first difference and no second derivative). What fewer samples leave
    undefined is NaN, never a zero that reads as a body at rest."""
    y = np.asarray(y, dtype=float)
    d1, d2 = np.full_like(y, np.nan), np.full_like(y, np.nan)
    n = len(y)
    if n >= 3:
        d1[1:-1] = (y[2:] - y[:-2]) / (2 * dt)
        d2[1:-1] = (y[2:] - 2 * y[1:-1] + y[:-2]) / dt**2
        d1[0] = (-3 * y[0] + 4 * y[1] - y[2]) / (2 * dt)
        d1[-1] = (3 * y[-1] - 4 * y[-2] + y[-3]) / (2 * dt)
    elif n == 2:
        d1[:] = (y[1] - y[0]) / dt
    if n >= 4:
        d2[0] = (2 * y[0] - 5 * y[1] + 4 * y[2] - y[3]) / dt**2
        d2[-1] = (2 * y[-1] - 5 * y[-2] + 4 * y[-3] - y[-4]) / dt**2
    elif n == 3:
        d2[0], d2[-1] = d2[1], d2[1]
    return d1, d2


def consistent_rates(system: System, q: np.ndarray, theta_d: np.ndarray, theta_dd: np.ndarray,
                     base: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None, *,
                     compiled: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """q̇, q̈ (frames × nq) of a mixed system given θ̇, θ̈ (frames × n_angles); NaN where the
    frame or its neighbours were left unsolved. A floating base's rates are not fixed by the
    topology: ``base`` = (its coordinates' columns, their q̇ and q̈ by central differences)
    joins the equations (least squares: the differenced rates need not be exactly rigid).
    Every frame at once on stacked arrays (batched.Stacked with the solved θ as drivers; LU
    for a square Φ_top,b, QR or ``linear_solve`` frame by frame otherwise, as ``factor``
    does); ``compiled``: the same equations in the compiled kernels (kernels.rates_frames), for
    systems the kernels take."""
    if compiled:
        return _compiled_rates(system, q, theta_d, theta_dd, base)
    n_body = system.layout.n_body_q
    top = system.masks()["topology"]
    columns = base[0] if base is not None else np.zeros(0, dtype=int)
    qd, qdd = np.full_like(q, np.nan), np.full_like(q, np.nan)
    solved = np.flatnonzero(np.isfinite(q).all(axis=1) & np.isfinite(theta_d).all(axis=1)
                            & np.isfinite(theta_dd).all(axis=1))
    stacked = Stacked(system)
    slots = int(system.trk_slot.max()) + 1 if len(system.trk_slot) else 0
    for block in blocks(len(solved)):
        frames = solved[block]
        n = len(frames)
        unmoved = np.zeros((n, slots, 3))  # the tracking rows, not among the topology's
        drives = Drives(q[frames, n_body:], theta_d[frames], theta_dd[frames], unmoved,
                        unmoved, unmoved)
        body = q[frames, :n_body]
        J = stacked.jacobian(body)[:, top]
        rows = np.zeros((n, len(columns), n_body))
        rows[:, np.arange(len(columns)), columns] = 1.0
        rates = factor(np.concatenate([J, rows], axis=1))
        base_d, base_dd = ((base[1][frames], base[2][frames]) if base is not None
                           else (np.zeros((n, 0)), np.zeros((n, 0))))
        qd[frames, n_body:], qdd[frames, n_body:] = theta_d[frames], theta_dd[frames]
        qd[frames, :n_body] = rates.solve(np.concatenate([stacked.nu(drives)[:, top], base_d],
                                                         axis=1))
        gamma = stacked.gamma(body, qd[frames, :n_body], drives)[:, top]
        qdd[frames, :n_body] = rates.solve(np.concatenate([gamma, base_dd], axis=1))
    return qd, qdd


def _compiled_rates(system: System, q: np.ndarray, theta_d: np.ndarray, theta_dd: np.ndarray,
                    base: tuple[np.ndarray, np.ndarray, np.ndarray] | None
                    ) -> tuple[np.ndarray, np.ndarray]:
    from fccgrb_cli.solvers.engine import ready
    from fccgrb_cli.solvers.kernels import BaseRates, rates_frames
    from fccgrb_cli.system.sparse import sparse_of

    n = len(q)
    columns = np.asarray(base[0] if base is not None else np.zeros(0), dtype=np.int64)
    base_d = base[1] if base is not None else np.zeros((n, 0))
    base_dd = base[2] if base is not None else np.zeros((n, 0))
    qd, qdd = np.full_like(q, np.nan), np.full_like(q, np.nan)
    args = (np.ascontiguousarray(q), np.ascontiguousarray(theta_d),
            np.ascontiguousarray(theta_dd),
            BaseRates(columns, np.ascontiguousarray(base_d), np.ascontiguousarray(base_dd)),
            qd, qdd)
    s = sparse_of(system)
    ready(rates_frames, s, *(a[:0] for a in args[:3]), args[3], *(a[:0] for a in args[4:]))
    rates_frames(s, *args)
    return qd, qdd

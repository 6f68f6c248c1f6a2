"""Velocities and accelerations of a mixed-coordinate solution, consistent with the topology.

θ̇ and θ̈ come from the solved θ(t) by central differences; the body coordinates then follow
from the topological equations (rigid body, joints, MCR) as in the converted model of
FORMULATION §4: Φ_q,body q̇_b = −Φ_θ θ̇ and Φ_q,body q̈_b = γ − Φ_θ θ̈.
"""

from __future__ import annotations

import numpy as np

from fccgrb_cli.solvers.newton import linear_solve
from fccgrb_cli.system import Drive, System


def central_derivatives(y: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """First and second derivatives along axis 0: 3-point central stencils inside, second-order
    one-sided stencils at the ends (needs 4 samples; fewer give zeros for what is undefined)."""
    y = np.asarray(y, dtype=float)
    d1, d2 = np.zeros_like(y), np.zeros_like(y)
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
    ``compiled``: the same equations in the compiled kernels (kernels.rates_frames), for
    systems the kernels take."""
    if compiled:
        return _compiled_rates(system, q, theta_d, theta_dd, base)
    n_body = system.layout.n_body_q
    top = system.masks()["topology"]
    columns = base[0] if base is not None else np.zeros(0, dtype=int)
    select = np.zeros((len(columns), n_body))
    select[np.arange(len(columns)), columns] = 1.0
    qd, qdd = np.full_like(q, np.nan), np.full_like(q, np.nan)
    for f in range(len(q)):
        if not (np.isfinite(q[f]).all() and np.isfinite(theta_d[f]).all()
                and np.isfinite(theta_dd[f]).all()):
            continue
        J = system.jacobian(q[f])[top]
        Jb, Jt = np.vstack([J[:, :n_body], select]), J[:, n_body:]
        base_d, base_dd = (base[1][f], base[2][f]) if base is not None else ((), ())
        qd[f, n_body:], qdd[f, n_body:] = theta_d[f], theta_dd[f]
        qd[f, :n_body] = linear_solve(Jb, np.concatenate([-Jt @ theta_d[f], base_d]))
        gamma = system.gamma(q[f], qd[f], Drive())[top]
        qdd[f, :n_body] = linear_solve(Jb, np.concatenate([gamma - Jt @ theta_dd[f], base_dd]))
    return qd, qdd


def _compiled_rates(system: System, q: np.ndarray, theta_d: np.ndarray, theta_dd: np.ndarray,
                    base: tuple[np.ndarray, np.ndarray, np.ndarray] | None
                    ) -> tuple[np.ndarray, np.ndarray]:
    from fccgrb_cli.solvers.kernels import rates_frames
    from fccgrb_cli.solvers.nrm_compiled import sparse_of

    n = len(q)
    columns = np.asarray(base[0] if base is not None else np.zeros(0), dtype=np.int64)
    base_d = base[1] if base is not None else np.zeros((n, 0))
    base_dd = base[2] if base is not None else np.zeros((n, 0))
    qd, qdd = np.full_like(q, np.nan), np.full_like(q, np.nan)
    rates_frames(sparse_of(system), np.ascontiguousarray(q), np.ascontiguousarray(theta_d),
                 np.ascontiguousarray(theta_dd), columns, np.ascontiguousarray(base_d),
                 np.ascontiguousarray(base_dd), qd, qdd)
    return qd, qdd

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


def consistent_rates(system: System, q: np.ndarray, theta_d: np.ndarray,
                     theta_dd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """q̇, q̈ (frames × nq) of a mixed system given θ̇, θ̈ (frames × n_angles); NaN where the
    frame or its neighbours were left unsolved."""
    n_body = system.layout.n_body_q
    top = system.masks()["topology"]
    qd, qdd = np.full_like(q, np.nan), np.full_like(q, np.nan)
    for f in range(len(q)):
        if not (np.isfinite(q[f]).all() and np.isfinite(theta_d[f]).all()
                and np.isfinite(theta_dd[f]).all()):
            continue
        J = system.jacobian(q[f])[top]
        Jb, Jt = J[:, :n_body], J[:, n_body:]
        qd[f, n_body:], qdd[f, n_body:] = theta_d[f], theta_dd[f]
        qd[f, :n_body] = linear_solve(Jb, -Jt @ theta_d[f])
        gamma = system.gamma(q[f], qd[f], Drive())[top]
        qdd[f, :n_body] = linear_solve(Jb, gamma - Jt @ theta_dd[f])
    return qd, qdd

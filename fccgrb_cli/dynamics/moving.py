"""Inverse dynamics of a model with moving joints (an imported OpenSim model), coordinates in.

The mixed system q = [x, θ] has the bodies' coordinates x (fully-defined, with mass) and the
coordinates θ (massless), tied by the topological rows Φ(x, θ) = 0 (rigid bodies, moving joints,
couplings). Prescribing θ(t) adds the drivers θ − θ*(t) = 0, whose multipliers are the
generalized forces τ the coordinates need (docs/opensim.md §5). Lagrange's equations
M q̈ + Φ_qᵀ λ = g + Q split into

    x rows:   Φ_xᵀ λ = g_x − M ẍ          (Φ_x of full column rank: λ exists; its part in the
                                           null space of Φ_xᵀ — the rotation rows' redundancy —
                                           changes no τ)
    θ rows:   τ = Φ_θᵀ λ                  (no mass on θ: the driver's force is what the rows
                                           take from the coordinate; positive along increasing θ)

with x, ẋ, ẍ from θ, θ̇, θ̈: x by the forward kinematics, Φ_x ẋ = −Φ_θ θ̇ and
Φ_x ẍ = γ − Φ_θ θ̈ (γ of the mixed system at q̇ = [ẋ, θ̇], which holds θ̇ᵀ ∂²h/∂θ² θ̇).
"""

from __future__ import annotations

import numpy as np

from fccgrb_cli.dynamics.mass import gravity_forces, mass_matrix
from fccgrb_cli.system.compiled import Drive, System
from fccgrb_cli.system.moving_pose import pose_from_coordinates

__all__ = ["coordinate_forces", "forces_from_coordinates"]


def coordinate_forces(system: System, theta: np.ndarray, theta_d: np.ndarray,
                      theta_dd: np.ndarray) -> np.ndarray:
    """The generalized forces of the coordinates along a prescribed motion.

    Parameters
    ----------
    system
        The model compiled with mixed coordinates and no tracking
        (``compile_system(model, angles="coordinate")``), with moving joints.
    theta, theta_d, theta_dd
        The coordinates, their rates and accelerations (frames × n_θ; rad, m and per s, s²),
        in the order of ``model.angles``.

    Returns
    -------
    numpy.ndarray
        τ (frames × n_θ): N·m for a rotational coordinate, N for a translational one, positive
        along the coordinate (OpenSim's ``<coordinate>_moment`` / ``_force``).
    """
    from scipy.linalg import lstsq

    M = mass_matrix(system.model)
    g = gravity_forces(system.model)
    nb = system.layout.n_body_q
    out = np.empty_like(np.asarray(theta, dtype=float))
    for f in range(len(theta)):
        q = pose_from_coordinates(system, theta[f])
        J = system.jacobian(q)
        Jx, Jt = J[:, :nb], J[:, nb:]
        xd = lstsq(Jx, -Jt @ theta_d[f])[0]
        qd = np.concatenate([xd, theta_d[f]])
        gamma = system.gamma(q, qd, Drive())
        xdd = lstsq(Jx, gamma - Jt @ theta_dd[f])[0]
        lam = lstsq(Jx.T, g - M @ xdd)[0]
        out[f] = Jt.T @ lam
    return out


def forces_from_coordinates(system: System, time: np.ndarray, theta: np.ndarray,
                            cutoff: float | None = None, order: int = 4
                            ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The inverse dynamics of a coordinates file, as OpenSim's ID tool runs it: the
    coordinates low-passed (zero-lag Butterworth of ``order`` at ``cutoff`` Hz, None: not
    filtered), their rates and accelerations from the natural quintic spline through them
    (f‴ = f⁗ = 0 at the ends; OpenSim's GCVSpline of degree 5 without smoothing), then
    :func:`coordinate_forces`.

    Parameters
    ----------
    system
        As for :func:`coordinate_forces`.
    time
        Sample times (frames,), s, increasing, evenly spaced when ``cutoff`` is given.
    theta
        The coordinates (frames × n_θ; rad, m) in the order of ``model.angles``.
    cutoff, order
        The low-pass filter's cutoff (Hz) and order.

    Returns
    -------
    tuple of numpy.ndarray
        τ (frames × n_θ; N·m, N), and the θ, θ̇, θ̈ it was computed from.
    """
    from scipy.interpolate import make_interp_spline

    from fccgrb_cli.signals.butterworth import lowpass

    time = np.asarray(time, dtype=float)
    theta = np.asarray(theta, dtype=float)
    if cutoff is not None:
        theta = lowpass(theta, 1.0 / float(np.mean(np.diff(time))), cutoff, order)
    natural = [(3, 0.0), (4, 0.0)]
    spline = make_interp_spline(time, theta, k=5, bc_type=(natural, natural))
    smooth, rate, acceleration = spline(time), spline(time, 1), spline(time, 2)
    return coordinate_forces(system, smooth, rate, acceleration), smooth, rate, acceleration

"""Inverse dynamics of a model with moving joints (an imported OpenSim model), coordinates in.

The mixed system q = [x, θ] has the bodies' coordinates x (fully-defined, with mass) and the
coordinates θ (massless), tied by the topological rows Φ(x, θ) = 0 (rigid bodies, moving joints,
couplings). Prescribing θ(t) adds the drivers θ − θ*(t) = 0, whose multipliers are the
generalized forces τ the coordinates need (docs/opensim.md §5). Lagrange's equations
M q̈ + Φ_qᵀ λ = g + Q split into

    x rows:   Φ_xᵀ λ = g_x + Q_x − M ẍ    (Φ_x of full column rank: λ exists; its part in the
                                           null space of Φ_xᵀ — the rotation rows' redundancy —
                                           changes no τ)
    θ rows:   τ = Φ_θᵀ λ                  (no mass on θ: the driver's force is what the rows
                                           take from the coordinate; positive along increasing θ)

with x, ẋ, ẍ from θ, θ̇, θ̈: x by the forward kinematics, Φ_x ẋ = −Φ_θ θ̇ and
Φ_x ẍ = γ − Φ_θ θ̈ (γ of the mixed system at q̇ = [ẋ, θ̇], which holds θ̇ᵀ ∂²h/∂θ² θ̇), and Q_x
the external loads' generalized forces on the bodies they act on (``dynamics.loads``).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from fccgrb_cli.core.blas import lapack
from fccgrb_cli.dynamics.inverse import InverseDynamics
from fccgrb_cli.dynamics.loads import ExternalLoad
from fccgrb_cli.dynamics.mass import gravity_forces, mass_matrix
from fccgrb_cli.system.compiled import Drive, System
from fccgrb_cli.system.moving_pose import pose_from_coordinates

__all__ = ["coordinate_forces", "coordinate_inverse", "forces_from_coordinates", "ready_inverse"]


def coordinate_forces(system: System, theta: np.ndarray, theta_d: np.ndarray,
                      theta_dd: np.ndarray, loads: Sequence[ExternalLoad] = ()) -> np.ndarray:
    """The generalized forces of the coordinates along a prescribed motion.

    Parameters
    ----------
    system
        The model compiled with mixed coordinates and no tracking
        (``compile_system(model, angles="coordinate")``), with moving joints.
    theta, theta_d, theta_dd
        The coordinates, their rates and accelerations (frames × n_θ; rad, m and per s, s²),
        in the order of ``model.angles``.
    loads
        External loads on the model's bodies at the same frames (ground reactions).

    Returns
    -------
    numpy.ndarray
        τ (frames × n_θ): N·m for a rotational coordinate, N for a translational one, positive
        along the coordinate (OpenSim's ``<coordinate>_moment`` / ``_force``).
    """
    return coordinate_inverse(system, theta, theta_d, theta_dd, loads)[1].joint_moments


def coordinate_inverse(system: System, theta: np.ndarray, theta_d: np.ndarray,
                       theta_dd: np.ndarray, loads: Sequence[ExternalLoad] = (), *,
                       kernels: System | None = None
                       ) -> tuple[tuple[np.ndarray, np.ndarray, np.ndarray], InverseDynamics]:
    """:func:`coordinate_forces` with what it passes through: the mixed coordinates q = [x, θ]
    and their rates (frames × nq each; SI), and the inverse dynamics: λ of the topological rows,
    τ, the kinetic (½ ẋᵀMẋ) and potential (−gᵀx) energies (J), the loads' power (W) and the
    residual ‖Φ_xᵀλ − (g + Q − Mẍ)‖ of the least-squares multipliers (N; zero when the rows'
    forces balance the bodies' exactly, as they do for a model whose coordinates move every
    body's six freedoms).

    ``kernels``: the same model compiled with its tracking rows (the solve's system, which the
    compiled kernels take: ``system.sparse.supported``); the rates and the multipliers then run
    in them (``kernels.rates_frames``, ``kernels.coordinate_multipliers_frames``: the same
    equations, all frames in machine code). None: numpy, frame by frame (the reference)."""
    if kernels is not None and _same_rows(system, kernels):
        return _compiled_inverse(system, kernels, theta, theta_d, theta_dd, loads)
    M = mass_matrix(system.model)
    g = gravity_forces(system.model)
    layout = system.layout
    nb = layout.n_body_q
    theta = np.asarray(theta, dtype=float)
    n = len(theta)
    on = [(layout.x_offset(load.body), load) for load in loads]
    q, qd, qdd = (np.empty((n, system.nq)) for _ in range(3))
    lam = np.empty((n, system.n_rows))
    tau = np.empty_like(theta)
    kinetic, potential, power, residual = (np.empty(n) for _ in range(4))
    for f in range(n):
        if system.functions is not None:  # h, ∂h/∂θ and ∂²h/∂θ² once: the pose, Φ_q and γ
            system.functions.terms(theta[f])  # ask for them at this θ in turn (kept: .terms)
        q[f] = pose_from_coordinates(system, theta[f])
        J = system.jacobian(q[f])
        Jx, Jt = J[:, :nb], J[:, nb:]
        factor = _Factor(Jx)
        xd = factor.solve(-Jt @ theta_d[f])
        qd[f] = np.concatenate([xd, theta_d[f]])
        gamma = system.gamma(q[f], qd[f], Drive())
        xdd = factor.solve(gamma - Jt @ theta_dd[f])
        qdd[f] = np.concatenate([xdd, theta_dd[f]])
        applied = g.copy()
        power[f] = 0.0
        for at, load in on:
            block = slice(at, at + 12)
            generalized = load.generalized(q[f, block], f)
            applied[block] += generalized
            power[f] += generalized @ xd[block]
        rhs = applied - M @ xdd
        lam[f] = factor.solve_transposed(rhs)
        residual[f] = float(np.linalg.norm(Jx.T @ lam[f] - rhs))
        tau[f] = Jt.T @ lam[f]
        kinetic[f] = 0.5 * xd @ M @ xd
        potential[f] = -g @ q[f, :nb]
    names = tuple(c.name for c in system.model.angles)
    inverse = InverseDynamics(angle_names=names, row_labels=tuple(system.labels),
                              lam=lam, joint_moments=tau, kinetic=kinetic, potential=potential,
                              external_power=power, residual=residual)
    return (q, qd, qdd), inverse


def _compiled_inverse(system: System, kernels: System, theta: np.ndarray,
                      theta_d: np.ndarray, theta_dd: np.ndarray, loads: Sequence[ExternalLoad]
                      ) -> tuple[tuple[np.ndarray, np.ndarray, np.ndarray], InverseDynamics]:
    """:func:`coordinate_inverse` through the compiled kernels of ``kernels``."""
    from fccgrb_cli.solvers.kernels import coordinate_multipliers_frames
    from fccgrb_cli.solvers.rates import consistent_rates
    from fccgrb_cli.system.sparse import sparse_of

    M = mass_matrix(system.model)
    g = gravity_forces(system.model)
    nb = system.layout.n_body_q
    theta = np.asarray(theta, dtype=float)
    n = len(theta)
    q = pose_from_coordinates(system, theta)
    qd, qdd = consistent_rates(kernels, q, np.asarray(theta_d, dtype=float),
                               np.asarray(theta_dd, dtype=float), compiled=True)
    xd, xdd = qd[:, :nb], qdd[:, :nb]
    frames = np.arange(n)
    rhs = g - xdd @ M.T
    power = np.zeros(n)
    for load in loads:
        at = system.layout.x_offset(load.body)
        generalized = load.generalized(q[:, at:at + 12], frames)
        rhs[:, at:at + 12] += generalized
        power += np.einsum("fi,fi->f", generalized, xd[:, at:at + 12])
    s = sparse_of(kernels)
    lam = np.empty((n, len(s.top_rows)))
    tau = np.empty_like(theta)
    residual = np.empty(n)
    args = (np.ascontiguousarray(q), np.ascontiguousarray(rhs), lam, tau, residual)
    ready_inverse(kernels)
    coordinate_multipliers_frames(s, *args)
    names = tuple(c.name for c in system.model.angles)
    inverse = InverseDynamics(angle_names=names, row_labels=tuple(system.labels),
                              lam=lam, joint_moments=tau,
                              kinetic=0.5 * np.einsum("fi,ij,fj->f", xd, M, xd),
                              potential=-(q[:, :nb] @ g), external_power=power,
                              residual=residual)
    return (q, qd, qdd), inverse


def _same_rows(system: System, kernels: System) -> bool:
    """Whether ``kernels`` (with tracking) has ``system``'s coordinates and, as its topological
    rows in their order, ``system``'s rows: the multipliers the kernels give are then λ of
    ``system``'s rows (else the numpy reference runs)."""
    from fccgrb_cli.system.sparse import sparse_of

    rows = sparse_of(kernels).top_rows
    return (kernels.nq == system.nq and len(rows) == system.n_rows
            and all(kernels.labels[r] == label for r, label in zip(rows, system.labels,
                                                                    strict=True)))


def ready_inverse(kernels: System) -> None:
    """Load (or compile) the compiled inverse's own kernel for the types of ``kernels`` (a mixed
    system with tracking; the types are those of every such system): ``fccgrb compile`` calls
    it, whatever the model it compiles on."""
    from fccgrb_cli.solvers.engine import ready
    from fccgrb_cli.solvers.kernels import coordinate_multipliers_frames
    from fccgrb_cli.system.sparse import sparse_of

    empty = np.zeros((0, 0))
    ready(coordinate_multipliers_frames, sparse_of(kernels), empty, empty, empty, empty,
          np.zeros(0))


class _Factor:
    """The Cholesky factor of Φ_xᵀΦ_x (Φ_x rows ≥ columns, of full column rank): the
    least-squares solution of Φ_x y = b (exact where b is in its range, as the rates'
    right-hand sides are), and the minimum-norm solution of Φ_xᵀ λ = c, λ = Φ_x (Φ_xᵀΦ_x)⁻¹ c
    (the rows' redundancy carries no force). The normal equations square Φ_x's condition
    number, ~20 on OpenSim's gait models (one joint frame's axes and origin per row block), so
    they lose nothing a QR would keep, at a third of its cost (0.7 against 2.3 ms a frame on
    Gait2354's 216 × 144); LAPACK's dpotrf/dpotrs through scipy's compiled module
    (``core.blas.lapack``)."""

    def __init__(self, matrix: np.ndarray) -> None:
        self.matrix = matrix
        self.factor, info = lapack.dpotrf(matrix.T @ matrix, lower=1)
        if info:
            raise np.linalg.LinAlgError(f"Φ_x loses column rank (pivot {info})")

    def _normal(self, rhs: np.ndarray) -> np.ndarray:
        return lapack.dpotrs(self.factor, rhs, lower=1)[0]

    def solve(self, b: np.ndarray) -> np.ndarray:
        return self._normal(self.matrix.T @ b)

    def solve_transposed(self, c: np.ndarray) -> np.ndarray:
        return self.matrix @ self._normal(c)


def coordinate_rates(time: np.ndarray, theta: np.ndarray, cutoff: float | None = None
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A coordinates file's θ, θ̇, θ̈ as OpenSim's ID tool takes them: the rows padded by half
    their number and low-passed at ``cutoff`` Hz (``signals.opensim_lowpass``; None: neither),
    then the natural quintic spline through the (padded) rows (f‴ = f⁗ = 0 at its ends;
    OpenSim's GCVSpline of degree 5 without smoothing) and its derivatives at ``time``.

    Parameters
    ----------
    time
        Sample times (frames,), s, increasing, evenly spaced when ``cutoff`` is given.
    theta
        The coordinates (frames × n_θ; rad, m).
    cutoff
        The low-pass filter's cutoff (Hz).

    Returns
    -------
    tuple of numpy.ndarray
        θ (filtered), θ̇, θ̈ at ``time`` (frames × n_θ each; rad, m and per s, s²).
    """
    from fccgrb_cli.signals.natural_quintic import natural_quintic
    from fccgrb_cli.signals.opensim_lowpass import lowpass_padded

    time = np.asarray(time, dtype=float)
    theta = np.asarray(theta, dtype=float)
    if cutoff is None:
        knots, values, first = time, theta, 0
    else:  # the padded rows hold the trial's own at rows // 2 onwards (signals.opensim_lowpass)
        knots, values = lowpass_padded(time, theta, cutoff)
        first = len(theta) // 2
    rate, acceleration = natural_quintic(knots, values)
    rows = slice(first, first + len(theta))
    return values[rows], rate[rows], acceleration[rows]


def forces_from_coordinates(system: System, time: np.ndarray, theta: np.ndarray,
                            cutoff: float | None = None, loads: Sequence[ExternalLoad] = ()
                            ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The inverse dynamics of a coordinates file, as OpenSim's ID tool runs it:
    :func:`coordinate_rates`, then :func:`coordinate_forces` with ``loads`` (at ``time``'s
    frames, as the tool applies them: not filtered).

    Returns
    -------
    tuple of numpy.ndarray
        τ (frames × n_θ; N·m, N), and the θ, θ̇, θ̈ it was computed from.
    """
    smooth, rate, acceleration = coordinate_rates(time, theta, cutoff)
    return (coordinate_forces(system, smooth, rate, acceleration, loads), smooth, rate,
            acceleration)

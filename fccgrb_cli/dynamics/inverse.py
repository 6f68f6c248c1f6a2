"""Inverse dynamics of the classical (AD-driven) system: M q̈ + Φ_qᵀ λ = g (docs/formulation.md §4).

Written on the fully-defined equivalent x: Φ_qᵀ λ = X_qᵀ (g_x − M_x ẍ), ẍ = X_q q̈ + V̇ q̇, which
also covers reduced bodies (their mass matrix then depends on q). λ by least squares, minimum norm
where constraints are redundant. The moment of driver k, conjugate to θ_k and positive in the
direction that increases it, is τ_k = Φ_θ,k λ_k = −g′(θ_k) λ_k: λ_k sin θ_k for an angle (N·m),
−λ_k for a distance coordinate, whose "moment" is the joint force along it (N). A floating
base's drivers r − r*, u − u*, v − v* (, w − w*) apply the residual wrench F = −λ_r,
M = −(u × λ_u + v × λ_v + w × λ_w) about its origin: their virtual power over a rigid motion
of the base (the rigid-body rows do no work there, so this holds whatever share of λ the
redundant rows take).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from fccgrb_cli.dynamics.loads import ExternalLoad
from fccgrb_cli.dynamics.mass import gravity_forces, mass_blocks, mass_matrix
from fccgrb_cli.solvers.batched import Stacked, blocks, factor
from fccgrb_cli.solvers.newton import linear_solve
from fccgrb_cli.solvers.result import KinematicResult
from fccgrb_cli.system import System


@dataclass(frozen=True)
class InverseDynamics:
    """Per-frame multipliers λ (frames × rows), joint moments τ (frames × coordinates, N·m;
    N for distances),
    kinetic and potential energy (J), the external loads' power (W) and the residual
    ‖Φ_qᵀλ − (g − Mq̈)‖ (a least-squares fit that is not exact flags inconsistent data)."""

    angle_names: tuple[str, ...]
    row_labels: tuple[str, ...]
    lam: np.ndarray
    joint_moments: np.ndarray
    kinetic: np.ndarray
    potential: np.ndarray
    external_power: np.ndarray
    residual: np.ndarray
    base_names: tuple[str, ...] = ()
    residual_force: np.ndarray | None = None
    residual_moment: np.ndarray | None = None


@dataclass(frozen=True)
class KernelInverse:
    """The inverse dynamics as kernels.driven_frames solves it, on the factor it already holds
    at each frame's solution (its ``inverse`` argument): ``arrays`` = the bodies' K_i (bodies ×
    4 × 4, M_x = blockdiag(K_i ⊗ I3)), g_x, each load's body (its offset in x) and its force,
    point and free moment (loads × frames × 3), then what the kernel writes: λ (frames × rows),
    ‖Φ_qᵀλ − rhs‖, the loads' power and which frames it solved."""

    arrays: tuple

    @classmethod
    def prepare(cls, system: System, loads: Sequence[ExternalLoad], n: int) -> KernelInverse:
        """Inputs and empty outputs for ``n`` frames of ``system`` (fully-defined bodies)."""
        layout = system.layout
        stack = [np.ascontiguousarray(np.array([getattr(load, name) for load in loads],
                                               dtype=float).reshape(len(loads), n, 3))
                 for name in ("force", "point", "moment")]
        return cls((mass_blocks(system.model), gravity_forces(system.model),
                    np.array([layout.x_offset(load.body) for load in loads], dtype=np.int64),
                    *stack, np.full((n, system.n_rows), np.nan), np.full(n, np.nan),
                    np.zeros(n), np.zeros(n, dtype=bool)))


def inverse_dynamics(system: System, motion: KinematicResult,
                     loads: Sequence[ExternalLoad] = (), *, batched: bool = True,
                     compiled: bool = False, solved: KernelInverse | None = None
                     ) -> InverseDynamics:
    """λ and τ for every frame of an AD system's ``motion`` (its q, q̇, q̈: frames × nq; θ the
    drivers):
    all frames at once on stacked arrays (``batched``), or frame by frame (the reference);
    ``compiled`` (with ``batched``): the multipliers' solves in the compiled kernels, ``solved``
    holding those the drive's kernel already did (the other frames are solved here)."""
    if system.mixed:
        raise ValueError("inverse_dynamics needs the classical system (angles='driver')")
    model = system.model
    M = mass_matrix(model)
    g = gravity_forces(model)
    theta = motion.theta
    if batched:
        lam, residual, xs, xds, power = _stacked(system, M, g, motion, loads, compiled, solved)
    else:
        lam, residual, xs, xds, power = _frame_by_frame(system, M, g, motion, loads)
    driver_rows = system.n_linear_rows + system.angle_rows
    bases, force, moment = _base_wrenches(system, xs, lam)
    potential = -(xs @ g)
    del xs  # frames × nx: freed before the kinetic energy's frames × nx product (long trials)
    moments = -system.g_terms(theta)[1] * lam[:, driver_rows]
    if len(system.sine_rows):  # a signed angle's sine row: Φ_θ = −cos θ (docs/signed_angles.md)
        k = system.sine_of
        moments[:, k] -= np.cos(theta[:, k]) * lam[:, system.n_linear_rows + system.sine_rows]
    return InverseDynamics(
        angle_names=tuple(a.name for a in model.angles), row_labels=system.labels, lam=lam,
        joint_moments=moments, kinetic=0.5 * np.einsum("fi,fi->f", xds @ M, xds),
        potential=potential, external_power=power, residual=residual, base_names=bases,
        residual_force=force, residual_moment=moment)


Multipliers = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]


def _stacked(system: System, M: np.ndarray, g: np.ndarray, motion: KinematicResult,
             loads: Sequence[ExternalLoad], compiled: bool = False,
             solved: KernelInverse | None = None) -> Multipliers:
    """λ (frames × rows), ‖Φ_qᵀλ − rhs‖, x, ẋ and the loads' power of every frame at once:
    ẍ = X_q q̈ + V̇ q̇, rhs = X_qᵀ (g_x + Σ loads − M_x ẍ), Φ_qᵀ λ = rhs by stacked solves; the
    frames ``solved`` by the drive's kernel are taken from it."""
    q, qd, qdd = motion.q, motion.qd, motion.qdd
    stacked = Stacked(system)
    n = len(q)
    x, xd = stacked.expand(q), stacked.expand_rate(q, qd)
    if solved is not None:
        *_, lam, residual, power, done = solved.arrays
        frames = np.flatnonzero(~done)
    else:
        lam, residual, power = np.empty((n, system.n_rows)), np.empty(n), np.zeros(n)
        frames = np.arange(n)
    if not len(frames):
        return lam, residual, x, xd, power
    q, qd, qdd = q[frames], qd[frames], qdd[frames]
    xq = stacked.expand_jacobian(q)
    xdd = (qdd if xq is None else np.einsum("fxq,fq->fx", xq, qdd)) + stacked.expand_bias(qd)
    forces = np.tile(g, (len(frames), 1))
    power[frames] = 0.0
    for load in loads:
        s = system.layout.x_offset(load.body)
        forces[:, s:s + 12] += load.generalized(x[frames, s:s + 12], frames)
        power[frames] += load.power(x[frames, s:s + 12], xd[frames, s:s + 12], frames)
    rhs_x = forces - xdd @ M.T
    rhs = rhs_x if xq is None else np.einsum("fxq,fx->fq", xq, rhs_x)
    if compiled:
        from fccgrb_cli.solvers.engine import ready
        from fccgrb_cli.solvers.kernels import multipliers_frames
        from fccgrb_cli.system.sparse import sparse_of

        some, misfit = np.empty((len(frames), system.n_rows)), np.empty(len(frames))
        args = (np.ascontiguousarray(q), np.ascontiguousarray(rhs), some, misfit)
        sparse = sparse_of(system)
        ready(multipliers_frames, sparse, *(a[:0] for a in args))
        multipliers_frames(sparse, *args)
        lam[frames], residual[frames] = some, misfit
        return lam, residual, x, xd, power
    for block in blocks(len(frames)):
        J = stacked.jacobian(q[block])
        some = factor(J).solve_transposed(rhs[block])
        lam[frames[block]] = some
        residual[frames[block]] = np.linalg.norm(np.einsum("frq,fr->fq", J, some) - rhs[block],
                                                 axis=1)
    return lam, residual, x, xd, power


def _frame_by_frame(system: System, M: np.ndarray, g: np.ndarray, motion: KinematicResult,
                    loads: Sequence[ExternalLoad]) -> Multipliers:
    """What ``_stacked`` computes, one frame at a time (``linear_solve`` on each Φ_qᵀ)."""
    q, qd, qdd = motion.q, motion.qd, motion.qdd
    layout = system.layout
    n = len(q)
    lam = np.zeros((n, system.n_rows))
    power, residual = np.zeros(n), np.zeros(n)
    xs, xds = np.empty((n, layout.nx)), np.empty((n, layout.nx))
    for f in range(n):
        x = xs[f] = layout.expand(q[f])
        xd = xds[f] = layout.expand_rate(q[f], qd[f])
        xq = layout.expand_jacobian(q[f])
        xdd = (qdd[f] if xq is None else xq @ qdd[f]) + layout.expand_bias(qd[f])
        forces = g.copy()
        for load in loads:
            s = layout.x_offset(load.body)
            forces[s:s + 12] += load.generalized(x[s:s + 12], f)
            power[f] += load.power(x[s:s + 12], xd[s:s + 12], f)
        rhs_x = forces - M @ xdd
        rhs = rhs_x if xq is None else xq.T @ rhs_x
        J = system.jacobian(q[f])
        lam[f] = linear_solve(J.T, rhs)
        residual[f] = np.linalg.norm(J.T @ lam[f] - rhs)
    return lam, residual, xs, xds, power


def _base_wrenches(system: System, xs: np.ndarray, lam: np.ndarray
                   ) -> tuple[tuple[str, ...], np.ndarray | None, np.ndarray | None]:
    """Residual force and moment (frames × bases × 3) of every floating base's drivers."""
    rows: dict[str, dict[str, np.ndarray]] = {}
    for k, label in enumerate(system.labels):
        if label.startswith("base ") and label.endswith(": x"):
            name, what = label[5:-3].split(": ")
            rows.setdefault(name, {})[what] = np.arange(k, k + 3)
    if not rows:
        return (), None, None
    names = tuple(rows)
    n = len(xs)
    force = np.zeros((n, len(names), 3))
    moment = np.zeros((n, len(names), 3))
    for b, name in enumerate(names):
        start = system.layout.x_offset(name)
        x = xs[:, start:start + 12].reshape(n, 4, 3)
        force[:, b] = -lam[:, rows[name]["r"]]
        for axis, column in (("u", 1), ("v", 2), ("w", 3)):
            if axis in rows[name]:
                moment[:, b] -= np.cross(x[:, column], lam[:, rows[name][axis]])
    return names, force, moment

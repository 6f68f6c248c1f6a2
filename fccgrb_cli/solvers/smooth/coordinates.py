"""The smoother's coordinates and its measurement model: the markers as functions of the driver
coordinates d, through the topological equations.

d holds what the classical model of docs/formulation.md §4 is driven by: every angle and distance,
then for each floating base its origin r (3) and the rotation vector φ (3) of its orientation
R = exp([φ]×) R₀ (``rotation.py``; R₀ the base's mean orientation over the trial). Given d, the
classical system Φ(q; d) = 0 fixes the bodies' coordinates q (Newton–Raphson, every frame at
once), so that the topology holds by construction at every d the smoother tries; its
sensitivity S = ∂q/∂d solves Φ_q S = −Φ_d, the right-hand sides being ν for a unit rate of
each coordinate (Eq. 25; a base's features move as ∂r = e_i, ∂u = (J(φ) e_i) × u, …). A tracked
point P of body i is C_P x_i (Eq. 2), so the markers' Jacobian is H = C X_q S.

The linearized measurement of a frame, in the information form the filter takes
(``filter.py``): A = Hᵀ W H / σ², b = Hᵀ W (y − p(d₀) + H d₀) / σ², W picking the markers
present (a marker missing in the frame, or a frame not used, contributes nothing).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fccgrb_cli.core.errors import InputError
from fccgrb_cli.solvers.batched import Drives, Stacked, factor, newton_stacked
from fccgrb_cli.solvers.smooth.arrays import Linearization, Points, SmoothedDrivers
from fccgrb_cli.solvers.smooth.rotation import (
    exp_map,
    jacobian_rate,
    left_jacobian,
    log_map,
    mean_rotation,
    unwrapped,
)
from fccgrb_cli.system import System
from fccgrb_cli.system.sparse import sparse_of

POSITION_TOL = 1e-12  # Newton's tolerance on ‖Δq‖∞ for the positions at d
POSITION_ITER = 20
LARGEST_TURN = 1.8 * np.pi  # rad: the rotation-vector chart's reach from R₀ (singular at 2π)



class AssemblyError(InputError):
    """The model does not assemble at the smoothed coordinates of frame ``frame`` (counted
    from the first frame of the arrays given; ``shifted`` counts it from an earlier one)."""

    def __init__(self, frame: int) -> None:
        super().__init__(f"--smooth auto: frame index {frame}: the model could not be "
                         "assembled at the smoothed coordinates")
        self.frame = frame

    def shifted(self, by: int) -> AssemblyError:
        return AssemblyError(self.frame + by)

@dataclass(frozen=True)
class BaseChart:
    """One floating base: its name, the columns of its r, u, v (, w) in q, the slots of its
    driven features (origin, u, v[, w]) in the classical system's ``Drives.ref``, and R₀."""

    name: str
    columns: np.ndarray  # 4 × 3 (or 3 × 3 for a reduced body), q columns of r, u, v, w
    slots: np.ndarray
    R0: np.ndarray


@dataclass(frozen=True)
class Linearized:
    """The measurement model at d₀ for every frame: q (frames × nq of the classical system,
    topology exact), S = ∂q/∂d, the model's marker positions (frames × markers × 3) and the
    markers' Jacobian H (frames × 3 markers × n)."""

    q: np.ndarray
    S: np.ndarray
    points: np.ndarray
    H: np.ndarray


@dataclass(frozen=True)
class Coordinates:
    """The driver coordinates of a classical system (angles='driver'): the angles' and
    distances' names, the floating bases' charts, and the tracked points' C_P (markers × 3 ×
    12) with their bodies' offsets in x."""

    system: System
    bases: tuple[BaseChart, ...]
    point_local: np.ndarray
    point_offset: np.ndarray

    @classmethod
    def build(cls, system: System, mixed_q: np.ndarray, frames: np.ndarray) -> Coordinates:
        """The coordinates of ``system`` (the classical one) for a trial whose mixed-coordinate
        solution is ``mixed_q``; each base's R₀ is its mean orientation over ``frames``."""
        if system.mixed:
            raise ValueError("Coordinates needs the classical system (angles='driver')")
        model, layout = system.model, system.layout
        if model.tracked_vectors:
            raise InputError(f"{model.source}: --smooth auto takes tracked points only, and the "
                             "model tracks vectors; use --smooth none")
        charts = []
        slot = 0
        for name in model.floating_bases:
            body = model.body(name)
            sl = layout.q_slice(name)
            count = 4 if body.form == "full" else 3
            columns = (sl.start + np.arange(3 * count)).reshape(count, 3)
            R = _orientations(mixed_q[frames], columns)
            charts.append(BaseChart(name, columns, np.arange(slot, slot + count),
                                    mean_rotation(R)))
            slot += count
        locals_, offsets = [], []
        for tp in model.tracked_points:
            locals_.append(model.body(tp.body).points[tp.point].local)
            offsets.append(layout.x_offset(tp.body))
        return cls(system, tuple(charts), np.array(locals_, dtype=float).reshape(-1, 3),
                   np.array(offsets, dtype=int))

    # --- sizes and names -----------------------------------------------------------------
    @property
    def n_angles(self) -> int:
        return len(self.system.angle_rows)

    @property
    def n(self) -> int:
        return self.n_angles + 6 * len(self.bases)

    @property
    def names(self) -> tuple[str, ...]:
        out = [a.name for a in self.system.model.angles]
        for chart in self.bases:
            out += [f"{chart.name}.r.{axis}" for axis in "xyz"]
            out += [f"{chart.name}.phi.{axis}" for axis in "xyz"]
        return tuple(out)

    @property
    def units(self) -> tuple[str, ...]:
        """Each coordinate's unit: rad for angles and rotation vectors, m for distances and
        a base's origin."""
        out = ["m" if d else "rad" for d in self.system.distance_rows]
        for _ in self.bases:
            out += ["m"] * 3 + ["rad"] * 3
        return tuple(out)

    # --- d from a mixed solution, drives from d --------------------------------------------
    def from_mixed(self, mixed_q: np.ndarray) -> np.ndarray:
        """d of every frame of a mixed-coordinate solution (frames × n): its angles, each
        base's origin and the unwrapped rotation vector of its orientation about R₀ (the
        orientation made orthonormal first: NRM-WLS keeps rigidity only to its weight)."""
        n_body = self.system.layout.n_body_q
        parts = [mixed_q[:, n_body:]]
        for chart in self.bases:
            R = _orientations(mixed_q, chart.columns)
            phi = unwrapped(log_map(R @ chart.R0.T))
            turn = np.linalg.norm(phi, axis=1)
            if np.nanmax(turn, initial=0.0) > LARGEST_TURN:
                f = int(np.nanargmax(turn))
                raise InputError(f"--smooth auto: frame index {f}: the floating base "
                                 f"{chart.name} has turned {np.degrees(turn[f]):.0f} deg from "
                                 "its mean orientation, beyond the smoother's reach of "
                                 f"{np.degrees(LARGEST_TURN):.0f} deg; use --smooth none")
            parts += [mixed_q[:, chart.columns[0]], phi]
        return np.concatenate(parts, axis=1)

    def drives(self, d: np.ndarray, d_d: np.ndarray | None = None,
               d_dd: np.ndarray | None = None) -> Drives:
        """The classical system's drives at d (frames × n) and, when given, its rates: θ*,
        θ̇*, θ̈*, and each base's features r, u, v (, w) with their rates (ṙ; u̇ = ω × u;
        ü = α × u + ω × (ω × u), ω = J(φ) φ̇, α = J(φ) φ̈ + J̇ φ̇)."""
        n, na = len(d), self.n_angles
        zeros = np.zeros_like(d)
        d_d = zeros if d_d is None else d_d
        d_dd = zeros if d_dd is None else d_dd
        slots = self.system.n_base_slots
        ref, ref_d, ref_dd = (np.zeros((n, slots, 3)) for _ in range(3))
        for b, chart in enumerate(self.bases):
            k = na + 6 * b
            phi, phi_d, phi_dd = d[:, k + 3:k + 6], d_d[:, k + 3:k + 6], d_dd[:, k + 3:k + 6]
            R = exp_map(phi) @ chart.R0
            J = left_jacobian(phi)
            omega = np.einsum("fij,fj->fi", J, phi_d)
            alpha = np.einsum("fij,fj->fi", J, phi_dd) + jacobian_rate(phi, phi_d)
            ref[:, chart.slots[0]] = d[:, k:k + 3]
            ref_d[:, chart.slots[0]] = d_d[:, k:k + 3]
            ref_dd[:, chart.slots[0]] = d_dd[:, k:k + 3]
            for axis, slot in enumerate(chart.slots[1:]):
                e = R[:, :, axis]
                ref[:, slot] = e
                ref_d[:, slot] = np.cross(omega, e)
                ref_dd[:, slot] = np.cross(alpha, e) + np.cross(omega, np.cross(omega, e))
        return Drives(d[:, :na], d_d[:, :na], d_dd[:, :na], ref, ref_d, ref_dd)

    # --- the measurement model ---------------------------------------------------------------
    def positions(self, d: np.ndarray, guesses: np.ndarray) -> np.ndarray:
        """q (frames × nq) with Φ(q; d) = 0 to ``POSITION_TOL``, from ``guesses``; a frame
        that does not converge is an error naming it (its guess was too far: the smoother's
        steps are small, so this means a branch the data left)."""
        it = newton_stacked(Stacked(self.system), guesses, self.drives(d), POSITION_TOL,
                            POSITION_ITER)
        if not it.converged.all():
            raise AssemblyError(int(np.flatnonzero(~it.converged)[0]))
        return it.q

    def sensitivity(self, q: np.ndarray, d: np.ndarray) -> np.ndarray:
        """S = ∂q/∂d (frames × nq × n): Φ_q S = ν of a unit rate of each coordinate."""
        system = self.system
        stacked = Stacked(system)
        n_frames, n = len(d), self.n
        rhs = np.zeros((n_frames, system.n_rows, n))
        unit = np.zeros((n, n_frames, n))
        unit[np.arange(n), :, np.arange(n)] = 1.0
        nu = stacked.nu(self.drives(np.tile(d, (n, 1)), unit.reshape(n * n_frames, n)))
        rhs[:] = nu.reshape(n, n_frames, -1).transpose(1, 2, 0)
        J = stacked.jacobian(q)
        return solve_many(J, rhs)

    def markers(self, q: np.ndarray) -> np.ndarray:
        """The tracked points' positions (frames × markers × 3): r + a u + b v + c w."""
        x = Stacked(self.system).expand(q)
        out = np.empty((len(q), len(self.point_offset), 3))
        for k, (start, local) in enumerate(zip(self.point_offset, self.point_local,
                                               strict=True)):
            r, u, v, w = x[:, start:start + 12].reshape(-1, 4, 3).transpose(1, 0, 2)
            out[:, k] = r + local[0] * u + local[1] * v + local[2] * w
        return out

    def marker_jacobian(self, q: np.ndarray, S: np.ndarray) -> np.ndarray:
        """H = C X_q S (frames × 3 markers × n)."""
        stacked = Stacked(self.system)
        xq = stacked.expand_jacobian(q)
        Sx = S if xq is None else np.matmul(xq, S)
        rows = []
        for start, local in zip(self.point_offset, self.point_local, strict=True):
            block = Sx[:, start:start + 12].reshape(len(q), 4, 3, -1)
            rows.append(block[:, 0] + local[0] * block[:, 1] + local[1] * block[:, 2]
                        + local[2] * block[:, 3])
        return np.concatenate(rows, axis=1)

    def base_units(self, d: np.ndarray) -> np.ndarray:
        """The floating bases' features' rates for a unit rate of each base coordinate
        (frames × 6 bases × slots × 3)."""
        n_frames, na = len(d), self.n_angles
        m = 6 * len(self.bases)
        slots = self.system.n_base_slots
        if not m:
            return np.zeros((n_frames, 0, slots, 3))
        unit = np.zeros((m, n_frames, self.n))
        unit[np.arange(m), :, na + np.arange(m)] = 1.0
        rates = self.drives(np.tile(d, (m, 1)), unit.reshape(m * n_frames, self.n)).ref_d
        return np.ascontiguousarray(rates.reshape(m, n_frames, slots, 3).transpose(1, 0, 2, 3))

    def linearize(self, d: np.ndarray, guesses: np.ndarray, compiled: bool = False
                  ) -> Linearized:
        """The measurement model at d (see the module's docstring); ``compiled``: by
        model_kernels.linearize_frames (fully-defined bodies)."""
        if compiled:
            return self._compiled(d, guesses)
        q = self.positions(d, guesses)
        S = self.sensitivity(q, d)
        return Linearized(q, S, self.markers(q), self.marker_jacobian(q, S))

    def _compiled(self, d: np.ndarray, guesses: np.ndarray) -> Linearized:
        from fccgrb_cli.solvers.smooth.model_kernels import linearize_frames

        n_frames, nq, n = len(d), self.system.nq, self.n
        k = len(self.point_offset)
        drives = self.drives(d)
        q, S = np.full((n_frames, nq), np.nan), np.zeros((n_frames, nq, n))
        points, H = np.empty((n_frames, k, 3)), np.empty((n_frames, 3 * k, n))
        converged = np.zeros(n_frames, dtype=bool)
        linearize_frames(sparse_of(self.system),
                         SmoothedDrivers(np.ascontiguousarray(guesses),
                                 np.ascontiguousarray(drives.theta),
                                 np.ascontiguousarray(drives.ref), self.base_units(d)),
                         Points(self.point_offset.astype(np.int64), self.point_local),
                         POSITION_ITER, Linearization(q, S, points, H, converged))
        if not converged.all():  # the numpy path's continuation decides, and names a failure
            redo = np.flatnonzero(~converged)
            again = self.linearize(d[redo], guesses[redo])
            q[redo], S[redo], points[redo], H[redo] = again.q, again.S, again.points, again.H
        return Linearized(q, S, points, H)


def solve_many(J: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """X with J_f X_f = B_f for every frame (J: frames × m × n, B: frames × m × k): LU of a
    square J, least squares (QR) of a taller one of full column rank, as batched.factor."""
    n_frames, m, n = J.shape
    if m == n:
        return np.linalg.solve(J, rhs)
    f = factor(J)
    out = np.empty((n_frames, n, rhs.shape[2]))
    if f.q is not None and len(f.batched):
        assert f.r is not None  # factored with q
        qtb = np.matmul(f.q.transpose(0, 2, 1), rhs[f.batched])
        out[f.batched] = np.linalg.solve(f.r, qtb)
    for k in f.fallback:
        out[k] = np.linalg.lstsq(J[k], rhs[k], rcond=None)[0]
    return out


def _orientations(q: np.ndarray, columns: np.ndarray) -> np.ndarray:
    """The nearest rotation [u v w] of each frame's base vectors (frames × 3 × 3)."""
    u, v = q[:, columns[1]], q[:, columns[2]]
    w = q[:, columns[3]] if len(columns) > 3 else np.cross(u, v)
    M = np.stack([u, v, w], axis=2)
    U, _, Vt = np.linalg.svd(M)
    D = np.ones((len(q), 3))
    D[:, 2] = np.sign(np.linalg.det(U @ Vt))
    return (U * D[:, None, :]) @ Vt

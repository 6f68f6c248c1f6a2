"""The model compiled once into constant arrays: Φ, Φ_q, ν and γ in a few array operations.

Rows are ordered [linear vector equations | tracking equations | dot equations]. With
F = A x + f0 the features and x the fully-defined equivalent coordinates (Eq. 5):

* linear rows  Φ = F_a − F_b          Φ_x = A_a − A_b (constant)
* tracking     Φ = F_a − y(t)         ν = ẏ, γ = ÿ − Φ_x V̇q̇ (Eq. 31–32, 35–36)
* dot rows     Φ = F_a·F_b − c        Φ_x = F_bᵀA_a + F_aᵀA_b, γ = −2Ḟ_a·Ḟ_b − Φ_x V̇q̇
* coordinate rows also carry −g(θ), g = cos for an angle (s1·s2 = cos θ) and g(d) = d for a
  distance ((r_Q − r_P)·s = d): MCR (θ a coordinate, Φ_θ = −g′(θ), γ += g″(θ) θ̇², Eq. 13–22)
  or AR (θ*(t) prescribed, ν = g′(θ*) θ̇*, γ += g″(θ*) θ̇*² + g′(θ*) θ̈*, Eq. 23–26); for an
  angle these are Φ_θ = sin θ, ν = −θ̇* sin θ*, γ −= θ̇*² cos θ* + θ̈* sin θ*.
* a signed angle (``range: full``) adds a sine row, (s1 × s2)·n − sin θ written as a dot row
  F_a·F_b − sin θ (docs/signed_angles.md): Φ_θ = −cos θ, ν = cos θ* θ̇*, γ += −sin θ θ̇² (MCR)
  or −sin θ* θ̇*² + cos θ* θ̈* (AR), Hessian += c sin θ.
* moving joints and couplings (an imported OpenSim model) have rows F_a·F_b − h_r(θ) with h_r any
  smooth function of several coordinates (system/moving.py, docs/opensim.md): Φ_θ = −∂h/∂θ,
  γ += θ̇ᵀ ∂²h/∂θ² θ̇ (+ ∂h/∂θ θ̈* as drivers, ν = ∂h/∂θ θ̇*), Hessian −= Σ c_r ∂²h_r/∂θ².

Then Φ_q = Φ_x X_q with X_q = V (Eq. 7) for reduced bodies.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from fccgrb_cli.model import Model
from fccgrb_cli.system.constraints import AXES, collect
from fccgrb_cli.system.features import FeatureTable
from fccgrb_cli.system.layout import Layout, build_layout, skew
from fccgrb_cli.system.moving import FunctionRows, collect_function_rows
from fccgrb_cli.system.rank import rank_of

TOPOLOGY, DRIVER, TRACKING = 0, 1, 2
_EMPTY = np.zeros(0)
_EMPTY3 = np.zeros((0, 3))


def coordinate_terms(theta: np.ndarray, distance: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """g, g′ and g″ of every coordinate (last axis of θ): cos θ, −sin θ, −cos θ for an angle,
    d, 1, 0 where ``distance`` is True (a row's Φ = F_a·F_b − g(θ), docs/formulation.md §2)."""
    cos = np.cos(theta)
    return (np.where(distance, theta, cos), np.where(distance, 1.0, -np.sin(theta)),
            np.where(distance, 0.0, -cos))


@dataclass(frozen=True)
class Drive:
    """The time-dependent data of one frame: prescribed coordinates θ*, θ̇*, θ̈* (rad, rad/s,
    rad/s² for angles; m, m/s, m/s² for distances) for AR drivers and tracking targets y, ẏ, ÿ
    (n_targets × 3, SI) for TC/TOC."""

    theta: np.ndarray = field(default_factory=lambda: _EMPTY)
    theta_d: np.ndarray = field(default_factory=lambda: _EMPTY)
    theta_dd: np.ndarray = field(default_factory=lambda: _EMPTY)
    ref: np.ndarray = field(default_factory=lambda: _EMPTY3)
    ref_d: np.ndarray | None = None
    ref_dd: np.ndarray | None = None


@dataclass(frozen=True, eq=False)
class System:
    """Constant arrays of a compiled model (build with :func:`compile_system`)."""

    model: Model
    layout: Layout
    angle_mode: str
    A_flat: np.ndarray
    f0: np.ndarray
    lin_a: np.ndarray
    lin_b: np.ndarray
    trk_a: np.ndarray
    trk_slot: np.ndarray
    trk_weight: tuple[float | None, ...]
    J_const: np.ndarray
    c_const: np.ndarray
    J_base: np.ndarray
    scatter_index: np.ndarray
    scatter_coef: np.ndarray
    scatter_gather: np.ndarray
    hess_index: np.ndarray
    hess_coef: np.ndarray
    hess_row: np.ndarray
    dot_a: np.ndarray
    dot_b: np.ndarray
    dot_a3: np.ndarray
    dot_b3: np.ndarray
    dot_c: np.ndarray
    angle_rows: np.ndarray
    distance_rows: np.ndarray
    sine_rows: np.ndarray
    sine_of: np.ndarray
    labels: tuple[str, ...]
    kinds: np.ndarray
    n_base_slots: int = 0
    functions: FunctionRows | None = None

    # --- sizes -------------------------------------------------------------------------------
    @property
    def nq(self) -> int:
        return self.layout.nq

    @property
    def n_rows(self) -> int:
        return len(self.labels)

    @property
    def n_linear_rows(self) -> int:
        return len(self.J_const)

    @property
    def n_targets(self) -> int:
        return len(self.trk_slot)

    @property
    def mixed(self) -> bool:
        return self.angle_mode == "coordinate"

    # --- evaluation ----------------------------------------------------------------------------
    def features(self, x: np.ndarray) -> np.ndarray:
        """F = A x + f0, one row per feature point or vector (n_features × 3)."""
        return (self.A_flat @ x).reshape(-1, 3) + self.f0

    def _theta(self, q: np.ndarray, drive: Drive) -> np.ndarray:
        return q[self.layout.n_body_q:] if self.mixed else drive.theta

    def residual(self, q: np.ndarray, drive: Drive) -> np.ndarray:
        """Φ(q, t)."""
        x = self.layout.expand(q)
        return self._residual(self.features(x), q, drive, x)

    def _residual(self, F: np.ndarray, q: np.ndarray, drive: Drive, x: np.ndarray) -> np.ndarray:
        lin = self.J_const @ x + self.c_const
        if self.n_targets:
            start = 3 * len(self.lin_a)
            lin[start:] -= drive.ref[self.trk_slot].ravel()
        flat = F.ravel()
        products = flat[self.dot_a3] * flat[self.dot_b3]
        dot = products[0::3] + products[1::3] + products[2::3] - self.dot_c
        if len(self.angle_rows):
            theta = self._theta(q, drive)
            dot[self.angle_rows] -= self.g_terms(theta)[0]
            if len(self.sine_rows):
                dot[self.sine_rows] -= np.sin(theta[self.sine_of])
        if self.functions is not None:
            dot[self.functions.rows] -= self.functions.terms(self._theta(q, drive), False)[0]
        return np.concatenate([lin, dot])

    def g_terms(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """g, g′, g″ of the coordinates θ (… × n_coordinates), see :func:`coordinate_terms`."""
        return coordinate_terms(theta, self.distance_rows)

    def _jacobian(self, F: np.ndarray) -> np.ndarray:
        """Constant rows plus the dot rows F_bᵀ C_a + F_aᵀ C_b, scattered block by block: each
        feature is Σ [c0 I, c1 I, c2 I, c3 I] over its body blocks (Eq. 2–3), so its product with
        F_other is the 12 numbers c ⊗ F_other. Columns are q's when no body is reduced, else x's."""
        values = self.scatter_coef * F.ravel()[self.scatter_gather]
        flat = np.bincount(self.scatter_index, values, minlength=self.J_base.size)
        return self.J_base + flat.reshape(self.J_base.shape)

    def _jacobian_q(self, J: np.ndarray, q: np.ndarray) -> np.ndarray:
        xq = self.layout.expand_jacobian(q)
        if xq is not None:
            J = J @ xq
            if self.mixed:
                J = np.hstack([J, np.zeros((len(J), len(self.layout.angle_names)))])
        if self.mixed and self.functions is not None:
            n = self.layout.n_body_q
            J[self.n_linear_rows + self.functions.rows, n:] = -self.functions.terms(q[n:], False)[1]
        elif self.mixed:
            n = self.layout.n_body_q
            J[self.n_linear_rows + self.angle_rows, n + np.arange(len(self.angle_rows))] = \
                -self.g_terms(q[n:])[1]
            J[self.n_linear_rows + self.sine_rows, n + self.sine_of] = \
                -np.cos(q[n:][self.sine_of])
        return J

    def _jacobian_x(self, F: np.ndarray) -> np.ndarray:
        """Φ_x (n_rows × nx)."""
        return self._jacobian(F)[:, : self.layout.nx]

    def evaluate(self, q: np.ndarray, drive: Drive) -> tuple[np.ndarray, np.ndarray]:
        """Φ and Φ_q together (they share the features)."""
        x = self.layout.expand(q)
        F = self.features(x)
        return self._residual(F, q, drive, x), self._jacobian_q(self._jacobian(F), q)

    def jacobian(self, q: np.ndarray) -> np.ndarray:
        """Φ_q (n_rows × nq)."""
        return self._jacobian_q(self._jacobian(self.features(self.layout.expand(q))), q)

    def nu(self, q: np.ndarray, drive: Drive) -> np.ndarray:
        """ν = −Φ_t, so that Φ_q q̇ = ν."""
        nu = np.zeros(self.n_rows)
        if self.n_targets and drive.ref_d is not None:
            start = 3 * len(self.lin_a)
            nu[start:start + 3 * self.n_targets] = drive.ref_d[self.trk_slot].ravel()
        if len(self.angle_rows) and not self.mixed:
            nu[self.n_linear_rows + self.angle_rows] = \
                self.g_terms(drive.theta)[1] * drive.theta_d
            k = self.sine_of
            nu[self.n_linear_rows + self.sine_rows] = np.cos(drive.theta[k]) * drive.theta_d[k]
        if self.functions is not None and not self.mixed:
            nu[self.n_linear_rows + self.functions.rows] = \
                self.functions.terms(drive.theta, False)[1] @ drive.theta_d
        return nu

    def gamma(self, q: np.ndarray, qd: np.ndarray, drive: Drive) -> np.ndarray:
        """γ = −(Φ_q q̇)_q q̇ − 2Φ_qt q̇ − Φ_tt, so that Φ_q q̈ = γ."""
        layout = self.layout
        x = layout.expand(q)
        F = self.features(x)
        Fd = (self.A_flat @ layout.expand_rate(q, qd)).reshape(-1, 3)
        gamma = -(self._jacobian_x(F) @ layout.expand_bias(qd))
        start = self.n_linear_rows
        gamma[start:] -= 2.0 * np.einsum("ij,ij->i", Fd[self.dot_a], Fd[self.dot_b])
        if self.n_targets and drive.ref_dd is not None:
            t0 = 3 * len(self.lin_a)
            gamma[t0:t0 + 3 * self.n_targets] += drive.ref_dd[self.trk_slot].ravel()
        if len(self.angle_rows):
            rows = start + self.angle_rows
            sines, k = start + self.sine_rows, self.sine_of
            if self.mixed:
                theta, theta_d = q[layout.n_body_q:], qd[layout.n_body_q:]
                gamma[rows] += self.g_terms(theta)[2] * theta_d**2
                gamma[sines] -= np.sin(theta[k]) * theta_d[k] ** 2
            else:
                _, g1, g2 = self.g_terms(drive.theta)
                gamma[rows] += g2 * drive.theta_d**2 + g1 * drive.theta_dd
                th, thd, thdd = drive.theta[k], drive.theta_d[k], drive.theta_dd[k]
                gamma[sines] += -np.sin(th) * thd**2 + np.cos(th) * thdd
        if self.functions is not None:
            rows = start + self.functions.rows
            if self.mixed:
                theta, theta_d = q[layout.n_body_q:], qd[layout.n_body_q:]
                gamma[rows] += np.einsum("rij,i,j->r", self.functions.terms(theta)[2],
                                         theta_d, theta_d)
            else:
                _, h1, h2 = self.functions.terms(drive.theta)
                gamma[rows] += (np.einsum("rij,i,j->r", h2, drive.theta_d, drive.theta_d)
                                + h1 @ drive.theta_dd)
        return gamma

    def residual_hessian(self, q: np.ndarray, c: np.ndarray) -> np.ndarray:
        """Σ_i c_i ∇²_q Φ_i (nq × nq): the second-order term of Newton's method on ½ΦᵀWΦ
        (c = WΦ). Dot rows have the constant x-Hessian C_aᵀC_b + C_bᵀC_a, assembled as
        kron(K, I3) from the 4×4 coefficient blocks; reduced bodies add the curvature of
        w = u × v; MCR rows add −c_k g″(θ_k) on the diagonal (c_k cos θ_k for an angle, nothing
        for a distance)."""
        layout = self.layout
        dots = c[self.n_linear_rows:]
        index, coef, row = self._hessian_scatter
        nx = layout.nx
        Sx = np.bincount(index, coef * dots[row], minlength=nx * nx).reshape(nx, nx)
        xq = layout.expand_jacobian(q)
        H = np.zeros((self.nq, self.nq))
        nb = layout.n_body_q
        if xq is None:
            H[:nb, :nb] = Sx
        else:
            H[:nb, :nb] = xq.T @ Sx @ xq
            F = self.features(layout.expand(q))
            g = self._jacobian(F)[:, : layout.nx].T @ c
            for u, v, w in zip(layout.reduced_u, layout.reduced_v, layout.reduced_w, strict=True):
                block = skew(g[w])
                H[np.ix_(u, v)] -= block
                H[np.ix_(v, u)] += block
        if self.mixed and self.functions is not None:
            H[nb:, nb:] -= np.einsum("r,rij->ij", dots[self.functions.rows],
                                     self.functions.terms(q[nb:])[2])
        elif self.mixed:
            rows = self.angle_rows
            H[nb + np.arange(len(rows)), nb + np.arange(len(rows))] -= \
                dots[rows] * self.g_terms(q[nb:])[2]
            k = nb + self.sine_of
            H[k, k] += dots[self.sine_rows] * np.sin(q[k])
        return H

    @cached_property
    def _hessian_scatter(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """kron(K, I3) of residual_hessian as flat indices into the nx × nx x-Hessian: each
        term of K at (a, b) lands on (3a + d, 3b + d), d = 0, 1, 2."""
        side = 4 * len(self.layout.body_names)
        ka, kb = np.divmod(self.hess_index, side)
        d = np.arange(3)
        index = ((3 * ka[:, None] + d) * self.layout.nx + 3 * kb[:, None] + d).ravel()
        return index, np.repeat(self.hess_coef, 3), np.repeat(self.hess_row, 3)

    # --- reading the solution ------------------------------------------------------------------
    def point_positions(self, q: np.ndarray, which: list[tuple[str, str]]) -> np.ndarray:
        """Global positions (k × 3) of the named (body, point) pairs at q."""
        x = self.layout.expand(q)
        out = np.empty((len(which), 3))
        for k, (body, point) in enumerate(which):
            local = self.model.body(body).points[point].local
            start = self.layout.x_offset(body)
            r, u, v, w = x[start:start + 12].reshape(4, 3)
            out[k] = r + local[0] * u + local[1] * v + local[2] * w
        return out

    def angles_at(self, q: np.ndarray) -> np.ndarray:
        """Every coordinate's value at q, whatever the mode: acos(s1·s2) for an angle (rad),
        atan2((s1 × s2)·n, s1·s2) in (−π, π] for a signed one, (r_Q − r_P)·s for a distance
        (m). A moving joint's coordinates are not functions of the bodies' coordinates alone:
        q's own θ when they are mixed coordinates, NaN (unknown) when they are driven."""
        if self.functions is not None:
            n = self.layout.n_body_q
            return q[n:].copy() if self.mixed else np.full(self.functions.n_coordinates, np.nan)
        F = self.features(self.layout.expand(q))
        dot = np.einsum("ij,ij->i", F[self.dot_a[self.angle_rows]], F[self.dot_b[self.angle_rows]])
        out = np.where(self.distance_rows, dot, np.arccos(np.clip(dot, -1.0, 1.0)))
        if len(self.sine_rows):
            sine = np.einsum("ij,ij->i", F[self.dot_a[self.sine_rows]],
                             F[self.dot_b[self.sine_rows]])
            out[self.sine_of] = np.arctan2(sine, dot[self.sine_of])
        return out

    def pose(self) -> np.ndarray:
        """q at the model's pose, mixed coordinates set to the angles the pose has."""
        q = self.layout.pose_q(self.model)
        if self.mixed and self.functions is not None:
            q[self.layout.n_body_q:] = self.functions.defaults
        elif self.mixed:
            q[self.layout.n_body_q:] = self.angles_at(q)
        return q

    @property
    def full_angles(self) -> np.ndarray:
        """Per coordinate: a signed angle that may take any value (``range: full``)."""
        out = np.zeros(len(self.distance_rows), dtype=bool)
        out[self.sine_of] = True
        if self.functions is not None:  # a moving joint's coordinate may take any value
            out[:] = True
        return out

    def base_reference(self, q: np.ndarray) -> np.ndarray:
        """The floating bases' driven features at q (n_base_slots × 3: origin, u, v[, w])."""
        if not self.n_base_slots:
            return np.zeros((0, 3))
        F = self.features(self.layout.expand(q))
        return F[self.trk_a[-self.n_base_slots:]]

    @cached_property
    def topology_rank(self) -> int:
        """The rank of the topological rows at the model's pose (assembled), below their count
        where they are dependent: a closed planar loop written in 3D, a signed angle's cosine
        and sine rows. Optimizers that cannot take dependent equality constraints keep this
        many rows (see FrameProblem.keep_independent)."""
        return rank_of(self.jacobian(self.pose())[self.kinds == TOPOLOGY])

    @property
    def redundant_topology(self) -> bool:
        return self.topology_rank < int((self.kinds == TOPOLOGY).sum())

    def masks(self) -> dict[str, np.ndarray]:
        """Boolean row masks by kind."""
        return {"topology": self.kinds == TOPOLOGY, "driver": self.kinds == DRIVER,
                "tracking": self.kinds == TRACKING}


def compile_system(model: Model, *, angles: str = "driver", track: bool = False) -> System:
    """Compile the model once: angles as AR drivers ('driver', kinematic analysis with AD) or as
    mixed coordinates ('coordinate', MCR); ``track`` adds TC/TOC for the tracked points/vectors.
    With drivers, floating bases get base drivers too (targets after the markers' in
    ``Drive.ref``); with mixed coordinates the markers determine them."""
    if angles not in ("driver", "coordinate"):
        raise ValueError(f"angles must be 'driver' or 'coordinate', got {angles!r}")
    names = tuple(a.name for a in model.angles) if angles == "coordinate" else ()
    layout = build_layout(model, names)
    table = FeatureTable(model, layout)
    cl = collect(model, table, angles=angles, track=track, base=angles == "driver")
    functions = collect_function_rows(table, cl, model, tuple(a.name for a in model.angles))
    A, f0 = table.arrays()
    nx = layout.nx

    def idx(values: list) -> np.ndarray:
        return np.array(values, dtype=int)

    lin_a, lin_b = idx([a for a, _, _ in cl.linear]), idx([b for _, b, _ in cl.linear])
    no_reduced = not len(layout.reduced_w)
    trk_a, trk_slot = idx([a for a, _, _, _ in cl.tracking]), idx([s for _, s, _, _ in cl.tracking])
    dot_a, dot_b = idx([a for a, _, _, _ in cl.dots]), idx([b for _, b, _, _ in cl.dots])
    j_lin = (A[lin_a] - A[lin_b]).reshape(-1, nx)
    j_trk = A[trk_a].reshape(-1, nx)

    labels: list[str] = []
    kinds: list[int] = []
    for _, _, label in cl.linear:
        labels += [f"{label}: {ax}" for ax in AXES]
        kinds += [TOPOLOGY] * 3
    first_base = len(cl.tracking) - cl.n_base
    for k, (_, _, label, _) in enumerate(cl.tracking):
        labels += [f"{label}: {ax}" for ax in AXES]
        kinds += [DRIVER if k >= first_base else TRACKING] * 3
    angle_set = set(cl.angle_dots) | set(cl.sine_dots)
    for k, (_, _, _, label) in enumerate(cl.dots):
        labels.append(label)
        kinds.append(DRIVER if (k in angle_set and angles == "driver") else TOPOLOGY)

    j_const = np.vstack([j_lin, j_trk]) if len(j_lin) + len(j_trk) else np.zeros((0, nx))
    width = layout.nq if no_reduced else nx
    j_base = np.zeros((len(labels), width))
    j_base[: len(j_const), :nx] = j_const
    scatter = _dot_scatter(table, cl, len(j_const), width)
    hessian = _dot_hessian(table, cl, len(model.bodies))
    return System(
        model=model,
        layout=layout,
        angle_mode=angles,
        A_flat=A.reshape(-1, nx),
        f0=f0,
        lin_a=lin_a,
        lin_b=lin_b,
        trk_a=trk_a,
        trk_slot=trk_slot,
        trk_weight=tuple(w for _, _, _, w in cl.tracking),
        J_const=j_const,
        c_const=np.concatenate([(f0[lin_a] - f0[lin_b]).ravel(), f0[trk_a].ravel()]),
        J_base=j_base,
        scatter_index=scatter[0],
        scatter_coef=np.repeat(scatter[1][:, :, None], 3, axis=2).ravel(),
        hess_index=hessian[0],
        hess_coef=hessian[1],
        hess_row=hessian[2],
        scatter_gather=(3 * scatter[2][:, None, None] + np.zeros((1, 4, 1), dtype=int)
                        + np.arange(3)[None, None, :]).ravel(),
        dot_a=dot_a,
        dot_b=dot_b,
        dot_a3=(3 * dot_a[:, None] + np.arange(3)).ravel(),
        dot_b3=(3 * dot_b[:, None] + np.arange(3)).ravel(),
        dot_c=np.array([c for _, _, c, _ in cl.dots], dtype=float),
        angle_rows=idx(cl.angle_dots),
        distance_rows=(functions.translational if functions is not None
                       else np.array(cl.distance_dots, dtype=bool)),
        sine_rows=idx(cl.sine_dots),
        sine_of=idx(cl.sine_of),
        labels=tuple(labels),
        kinds=np.array(kinds, dtype=int),
        n_base_slots=cl.n_base,
        functions=functions,
    )


def _dot_scatter(table: FeatureTable, cl, first_row: int, width: int
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Flat indices into Φ_q, block coefficients (n_blocks × 4) and the partner feature of every
    body block of every dot row: ∂(F_a·F_b)/∂x_body = c ⊗ F_b over each block (start, c) of a."""
    index, coef, other = [], [], []
    offsets = np.arange(12)
    for d, (a, b, _, _) in enumerate(cl.dots):
        row = first_row + d
        for mine, partner in ((a, b), (b, a)):
            for start, c in table.blocks[mine]:
                index.append(row * width + start + offsets)
                coef.append(c)
                other.append(partner)
    if not index:
        return np.zeros(0, dtype=int), np.zeros((0, 4)), np.zeros(0, dtype=int)
    return np.concatenate(index), np.array(coef), np.array(other, dtype=int)


def _dot_hessian(table: FeatureTable, cl, n_bodies: int
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Flat indices into the 4n_b × 4n_b coefficient matrix K, the coefficients and the dot row
    of every term of ∇²(F_a·F_b) = C_aᵀC_b + C_bᵀC_a, block pair by block pair."""
    index, coef, row = [], [], []
    side = 4 * n_bodies
    m = np.arange(4)
    for d, (a, b, _, _) in enumerate(cl.dots):
        for sa, ca in table.blocks[a]:
            for sb, cb in table.blocks[b]:
                ra, rb = 4 * (sa // 12) + m, 4 * (sb // 12) + m
                outer = np.outer(ca, cb)
                for rows, cols, values in ((ra, rb, outer), (rb, ra, outer.T)):
                    index.append((rows[:, None] * side + cols[None, :]).ravel())
                    coef.append(values.ravel())
                    row.append(np.full(16, d))
    if not index:
        return np.zeros(0, dtype=int), np.zeros(0), np.zeros(0, dtype=int)
    return np.concatenate(index), np.concatenate(coef), np.concatenate(row)

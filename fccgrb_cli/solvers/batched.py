"""Many frames at once: the compiled System's Φ, Φ_q, ν and γ on stacks of frames, and the
linear solves the kinematic analysis with angular drivers and the inverse dynamics need
(docs/formulation.md §2–4), as arrays of n_frames × rows × columns instead of a Python loop per
frame.

Where frames are independent (the classical model driven by θ*(t) known for every frame, the
consistent rates Φ_q q̇ = ν and Φ_q q̈ = γ, the multipliers Φ_qᵀ λ = Q − M q̈) every frame is
evaluated with the System's constant arrays (``A_flat``, ``f0``, ``J_const``, ``dot_a/b``, ...)
in one operation over the stack: F = A x + f0 (Eq. 2–3), the linear rows' constant Φ_x, the dot
rows' Φ_x = F_bᵀ A_a + F_aᵀ A_b, and Φ_q = Φ_x X_q (Eq. 7) for reduced bodies.

The stacked solves mirror ``newton.linear_solve`` (LU for a square matrix, the least-squares /
minimum-norm solution otherwise): square stacks by LU, taller ones of full column rank by QR;
any frame they cannot take (singular, rank-deficient, wider than tall) goes through
``linear_solve`` itself, so a batch never answers differently from the frame-by-frame path.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from fccgrb_cli.solvers.newton import linear_solve
from fccgrb_cli.system import Drive, System
from fccgrb_cli.system.layout import skew

# A column of R below this fraction of the largest (QR without pivoting) may hide a rank
# deficiency: such a frame is left to linear_solve's rank-revealing least squares.
RANK_GUARD = 1e-8
BLOCK = 1024  # frames per stack: stacks of Φ_q and their factors cost ~60 kB a frame


def blocks(n: int) -> list[slice]:
    """Consecutive slices of at most ``BLOCK`` frames covering ``n``: stacked work is done block
    by block, so a long trial's memory stays that of one block (frames are independent)."""
    return [slice(start, min(n, start + BLOCK)) for start in range(0, n, BLOCK)]


@dataclass(frozen=True)
class Drives:
    """The time-dependent data of many frames, stacked (frames first): prescribed coordinates
    θ*, θ̇*, θ̈* (frames × n_coordinates) and the floating bases' driven features and rates
    (frames × slots × 3); the stacked form of ``Drive``."""

    theta: np.ndarray
    theta_d: np.ndarray
    theta_dd: np.ndarray
    ref: np.ndarray
    ref_d: np.ndarray
    ref_dd: np.ndarray

    def take(self, frames: np.ndarray) -> Drives:
        """The drives of the given frames."""
        return Drives(*(a[frames] for a in (self.theta, self.theta_d, self.theta_dd,
                                            self.ref, self.ref_d, self.ref_dd)))

    def frame(self, f: int | np.integer) -> Drive:
        """One frame's ``Drive``."""
        return Drive(self.theta[f], self.theta_d[f], self.theta_dd[f], self.ref[f],
                     self.ref_d[f], self.ref_dd[f])


@dataclass(frozen=True, eq=False)
class Stacked:
    """A compiled classical ``System`` (angles='driver') evaluated on stacks of frames: q
    (frames × nq) → Φ (frames × rows), Φ_q (frames × rows × nq), ν, γ. Same rows, columns and
    conventions as the System's one-frame methods (see compiled.py's module docstring for the
    formulas).

    A mixed system is evaluated with its angles held as drivers (``drives.theta`` the solved
    θ): Φ_q is then its body columns, and ν, γ with the drives' θ̇, θ̈ are the right-hand sides
    Φ_q,body q̇_b = −Φ_θ θ̇ and Φ_q,body q̈_b = γ − Φ_θ θ̈ of its consistent rates (rates.py; an
    angle's row gives g′(θ) θ̇ and g″(θ) θ̇² + g′(θ) θ̈ either way); its tracking rows take
    the drives' ``ref`` as the classical base rows do."""

    system: System

    @cached_property
    def _dot_blocks(self) -> np.ndarray:
        """[A_a; A_b] of every dot row (dots × 6 × nx): its Φ_x is [F_b, F_a] · [A_a; A_b]."""
        s = self.system
        A3 = s.A_flat.reshape(-1, 3, s.layout.nx)
        return np.concatenate([A3[s.dot_a], A3[s.dot_b]], axis=1)

    # --- coordinates ------------------------------------------------------------------------
    def expand(self, q: np.ndarray) -> np.ndarray:
        """x = S V q (Eq. 5) of every frame (frames × nx), a block at a time (the columns'
        copies of a long trial's every frame would be as large as x)."""
        lay = self.system.layout
        x = np.empty((len(q), lay.nx))
        for b in blocks(len(q)):
            x[b, lay.copy_x] = q[b, lay.copy_q]
            if len(lay.reduced_w):
                x[b, lay.reduced_w] = np.cross(q[b, lay.reduced_u], q[b, lay.reduced_v])
        return x

    def expand_rate(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """ẋ = X_q q̇ of every frame, a block at a time."""
        lay = self.system.layout
        xd = np.empty((len(q), lay.nx))
        for b in blocks(len(q)):
            xd[b, lay.copy_x] = qd[b, lay.copy_q]
            if len(lay.reduced_w):
                u, v = q[b, lay.reduced_u], q[b, lay.reduced_v]
                ud, vd = qd[b, lay.reduced_u], qd[b, lay.reduced_v]
                xd[b, lay.reduced_w] = np.cross(ud, v) + np.cross(u, vd)
        return xd

    def expand_jacobian(self, q: np.ndarray) -> np.ndarray | None:
        """X_q (frames × nx × n_body_q), None when it is the identity (no reduced body)."""
        lay = self.system.layout
        if not len(lay.reduced_w) and lay.n_body_q == lay.nx:
            return None
        xq = np.zeros((len(q), lay.nx, lay.n_body_q))
        xq[:, lay.copy_x, lay.copy_q] = 1.0
        if len(lay.reduced_w):
            rows = lay.reduced_w[:, :, None]
            xq[:, rows, lay.reduced_u[:, None, :]] = -skew(q[:, lay.reduced_v])
            xq[:, rows, lay.reduced_v[:, None, :]] = skew(q[:, lay.reduced_u])
        return xq

    def expand_bias(self, qd: np.ndarray) -> np.ndarray:
        """V̇ q̇ of every frame: 2 u̇ × v̇ in the w block of each reduced body (Eq. 36)."""
        lay = self.system.layout
        bias = np.zeros((len(qd), lay.nx))
        if len(lay.reduced_w):
            bias[:, lay.reduced_w] = 2.0 * np.cross(qd[:, lay.reduced_u], qd[:, lay.reduced_v])
        return bias

    def features(self, x: np.ndarray) -> np.ndarray:
        """F = A x + f0 (frames × n_features × 3)."""
        s = self.system
        return (x @ s.A_flat.T).reshape(len(x), -1, 3) + s.f0

    def base_reference(self, q: np.ndarray) -> np.ndarray:
        """The floating bases' driven features of every frame (frames × slots × 3), as
        ``System.base_reference``."""
        s = self.system
        if not s.n_base_slots:
            return np.zeros((len(q), 0, 3))
        return self.features(self.expand(q))[:, s.trk_a[-s.n_base_slots:]]

    # --- Φ, Φ_q, ν, γ ---------------------------------------------------------------------
    def residual(self, q: np.ndarray, drives: Drives) -> np.ndarray:
        """Φ of every frame (frames × rows)."""
        s = self.system
        x = self.expand(q)
        F = self.features(x)
        lin = x @ s.J_const.T + s.c_const
        if s.n_targets:
            lin[:, 3 * len(s.lin_a):] -= drives.ref[:, s.trk_slot].reshape(len(q), -1)
        dot = np.einsum("fdk,fdk->fd", F[:, s.dot_a], F[:, s.dot_b]) - s.dot_c
        if len(s.angle_rows):
            theta = drives.theta
            dot[:, s.angle_rows] -= s.g_terms(theta)[0]
            dot[:, s.sine_rows] -= np.sin(theta[:, s.sine_of])
        if s.functions is not None:
            for f, theta_f in enumerate(drives.theta):
                dot[f, s.functions.rows] -= s.functions.terms(theta_f, False)[0]
        return np.concatenate([lin, dot], axis=1)

    def jacobian_x(self, F: np.ndarray) -> np.ndarray:
        """Φ_x (frames × rows × nx): the constant linear rows, then F_bᵀ A_a + F_aᵀ A_b."""
        s = self.system
        n = len(F)
        J = np.empty((n, s.n_rows, s.layout.nx))
        J[:, : s.n_linear_rows] = s.J_const
        partners = np.concatenate([F[:, s.dot_b], F[:, s.dot_a]], axis=2)  # frames × dots × 6
        J[:, s.n_linear_rows:] = np.matmul(partners.transpose(1, 0, 2),
                                           self._dot_blocks).transpose(1, 0, 2)
        return J

    def jacobian_q(self, Jx: np.ndarray, q: np.ndarray) -> np.ndarray:
        """Φ_q = Φ_x X_q (Eq. 7)."""
        xq = self.expand_jacobian(q)
        return Jx if xq is None else Jx @ xq

    def evaluate(self, q: np.ndarray, drives: Drives) -> tuple[np.ndarray, np.ndarray]:
        """Φ and Φ_q of every frame."""
        F = self.features(self.expand(q))
        return self.residual(q, drives), self.jacobian_q(self.jacobian_x(F), q)

    def jacobian(self, q: np.ndarray) -> np.ndarray:
        """Φ_q of every frame (frames × rows × nq)."""
        return self.jacobian_q(self.jacobian_x(self.features(self.expand(q))), q)

    def nu(self, drives: Drives) -> np.ndarray:
        """ν = −Φ_t of every frame of a driven system: ṙ* on the base rows, g′(θ*) θ̇* on the
        driver rows (Eq. 25: −θ̇* sin θ* for an angle), cos θ* θ̇* on the sine rows,
        ∂h/∂θ θ̇* on a moving joint's or coupling's rows (one frame at a time)."""
        s = self.system
        n = len(drives.theta)
        nu = np.zeros((n, s.n_rows))
        if s.n_targets:
            start = 3 * len(s.lin_a)
            nu[:, start:start + 3 * s.n_targets] = drives.ref_d[:, s.trk_slot].reshape(n, -1)
        if len(s.angle_rows):
            nu[:, s.n_linear_rows + s.angle_rows] = s.g_terms(drives.theta)[1] * drives.theta_d
            k = s.sine_of
            nu[:, s.n_linear_rows + s.sine_rows] = (np.cos(drives.theta[:, k])
                                                    * drives.theta_d[:, k])
        if s.functions is not None:
            rows = s.n_linear_rows + s.functions.rows
            for f, (theta, theta_d) in enumerate(zip(drives.theta, drives.theta_d, strict=True)):
                nu[f, rows] = s.functions.terms(theta, False)[1] @ theta_d
        return nu

    def gamma(self, q: np.ndarray, qd: np.ndarray, drives: Drives) -> np.ndarray:
        """γ = −(Φ_q q̇)_q q̇ − 2Φ_qt q̇ − Φ_tt of every frame (docs/formulation.md §2): −Φ_x V̇q̇,
        −2 Ḟ_a·Ḟ_b on the dot rows, r̈* on the base rows, g″(θ*) θ̇*² + g′(θ*) θ̈* on the
        driver rows (Eq. 26: −θ̇*² cos θ* − θ̈* sin θ* for an angle), −sin θ* θ̇*² + cos θ* θ̈*
        on the sine rows, θ̇*ᵀ ∂²h/∂θ² θ̇* + ∂h/∂θ θ̈* on a moving joint's or coupling's rows
        (one frame at a time)."""
        s, lay = self.system, self.system.layout
        n, start = len(q), self.system.n_linear_rows
        Fd = (self.expand_rate(q, qd) @ s.A_flat.T).reshape(n, -1, 3)
        gamma = np.zeros((n, s.n_rows))
        if len(lay.reduced_w):
            Jx = self.jacobian_x(self.features(self.expand(q)))
            gamma -= np.einsum("frj,fj->fr", Jx, self.expand_bias(qd))
        gamma[:, start:] -= 2.0 * np.einsum("fdk,fdk->fd", Fd[:, s.dot_a], Fd[:, s.dot_b])
        if s.n_targets:
            t0 = 3 * len(s.lin_a)
            gamma[:, t0:t0 + 3 * s.n_targets] += drives.ref_dd[:, s.trk_slot].reshape(n, -1)
        if len(s.angle_rows):
            _, g1, g2 = s.g_terms(drives.theta)
            gamma[:, start + s.angle_rows] += g2 * drives.theta_d**2 + g1 * drives.theta_dd
            k = s.sine_of
            th, thd, thdd = drives.theta[:, k], drives.theta_d[:, k], drives.theta_dd[:, k]
            gamma[:, start + s.sine_rows] += -np.sin(th) * thd**2 + np.cos(th) * thdd
        if s.functions is not None:
            rows = start + s.functions.rows
            for f in range(n):
                _, h1, h2 = s.functions.terms(drives.theta[f])
                theta_d = drives.theta_d[f]
                gamma[f, rows] += (np.einsum("rij,i,j->r", h2, theta_d, theta_d)
                                   + h1 @ drives.theta_dd[f])
        return gamma


# --- stacked linear solves -------------------------------------------------------------------
@dataclass(frozen=True)
class Factored:
    """A stack of matrices J (frames × m × n) prepared for several right-hand sides: J x = b
    (``solve``) and Jᵀ y = c (``solve_transposed``), with ``newton.linear_solve``'s answers:
    the exact solution of a square J (LU, LAPACK's gesv on each matrix as numpy.linalg.solve
    does frame by frame), the least-squares one of a taller J of full column rank and the
    minimum-norm one of Jᵀ (one QR per frame, kept). Frames the stack cannot take
    (``fallback``: singular, rank-deficient, not finite, wider than tall) are solved one by one
    by ``linear_solve``."""

    J: np.ndarray
    q: np.ndarray | None  # taller stacks: J = Q R of the batched frames
    r: np.ndarray | None
    batched: np.ndarray  # frame indices handled in the stack
    fallback: np.ndarray  # frame indices left to linear_solve

    def solve(self, b: np.ndarray) -> np.ndarray:
        """x with J x = b, frame by frame (frames × n)."""
        out = np.empty((len(self.J), self.J.shape[2]))
        if self.q is not None:
            assert self.r is not None  # factored with q
            qtb = _matvec(self.q.transpose(0, 2, 1), b[self.batched])
            out[self.batched] = _solve(self.r, qtb)
        elif len(self.batched):
            out[self.batched] = _solve(self.J[self.batched], b[self.batched])
        for f in self.fallback:
            out[f] = linear_solve(self.J[f], b[f])
        return out

    def solve_transposed(self, c: np.ndarray) -> np.ndarray:
        """y with Jᵀ y = c (minimum norm where J has more rows than columns)."""
        out = np.empty((len(self.J), self.J.shape[1]))
        if self.q is not None:
            assert self.r is not None  # factored with q
            z = _solve(self.r.transpose(0, 2, 1), c[self.batched])
            out[self.batched] = _matvec(self.q, z)
        elif len(self.batched):
            out[self.batched] = _solve(self.J[self.batched].transpose(0, 2, 1),
                                       c[self.batched])
        for f in self.fallback:
            out[f] = linear_solve(self.J[f].T, c[f])
        return out


def _matvec(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """A_f b_f for every frame f."""
    return np.matmul(A, b[..., None])[..., 0]


def _solve(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """A_f x_f = b_f for every frame f of a stack of square matrices (LU); a stack holding an
    exactly singular matrix, which numpy refuses as a whole, frame by frame through
    ``linear_solve`` (least squares, minimum norm)."""
    try:
        return np.linalg.solve(A, b[..., None])[..., 0]
    except np.linalg.LinAlgError:
        return np.array([linear_solve(a, v) for a, v in zip(A, b, strict=True)])


def factor(J: np.ndarray) -> Factored:
    """Prepare every frame of J (frames × m × n): a square stack as it is (solved by LU), the
    QR of a taller one; a frame that is not finite, or taller and rank-deficient (|R_ii| ≤
    RANK_GUARD max |R_jj|: QR without pivoting cannot give the minimum-norm answer), is left to
    ``linear_solve``."""
    n_frames, m, n = J.shape
    good = np.isfinite(J).all(axis=(1, 2))
    if m < n or not good.any():
        return Factored(J, None, None, np.zeros(0, int), np.arange(n_frames))
    frames = np.flatnonzero(good)
    if m == n:
        return Factored(J, None, None, frames, np.flatnonzero(~good))
    q, r = np.linalg.qr(J[frames])
    diag = np.abs(np.diagonal(r, axis1=1, axis2=2))
    ok = diag.min(axis=1) > RANK_GUARD * diag.max(axis=1)
    return Factored(J, q[ok], r[ok], frames[ok],
                    np.sort(np.concatenate([np.flatnonzero(~good), frames[~ok]])))


# --- Newton–Raphson on all frames ------------------------------------------------------------
@dataclass(frozen=True)
class StackedIterate:
    """Newton–Raphson's outcome on every frame: q (frames × nq), iterations, converged."""

    q: np.ndarray
    iterations: np.ndarray
    converged: np.ndarray


def newton_stacked(stacked: Stacked, q0: np.ndarray, drives: Drives, tol: float,
                   max_iter: int) -> StackedIterate:
    """``newton.newton_raphson`` on every frame at once (docs/formulation.md §3, KA with AD):
    Φ_q Δq = −Φ until ‖Δq‖∞ < tol, iterating only the frames not yet converged. A frame whose
    step is not finite goes back to its guess, unconverged, as in the one-frame iteration."""
    q = q0.copy()
    n = len(q)
    iterations = np.full(n, max_iter)
    converged = np.zeros(n, dtype=bool)
    active = np.arange(n)
    for k in range(1, max_iter + 1):
        phi, J = stacked.evaluate(q[active], drives.take(active))
        step = factor(J).solve(-phi)
        q[active] += step
        size = np.abs(step).max(axis=1)
        broken = ~np.isfinite(size)
        q[active[broken]] = q0[active[broken]]
        done = broken | (size < tol)
        converged[active[done & ~broken]] = True
        iterations[active[done]] = k
        active = active[~done]
        if not len(active):
            break
    return StackedIterate(q, iterations, converged)

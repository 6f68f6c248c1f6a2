"""One frame as an optimization problem (docs/formulation.md §3, CNO and MO): the topological
equations Φ_top(q) = 0 as equality constraints, the tracking residuals as objectives, and bounds.

Every value, gradient and Jacobian comes from the compiled constraint engine (no finite
differences); one evaluation of Φ and Φ_q is cached per q, since the optimizers ask for the
objective, its gradient and the constraints separately.
"""

from __future__ import annotations

import numpy as np

from fccgrb_cli.system import Drive, System

ED_SMOOTHING = 1e-6
ANGLE_MARGIN = np.radians(2.0)


class FrameProblem:
    """Objectives and constraints of one frame with marker targets (n_targets × 3, NaN gaps)."""

    def __init__(self, system: System, targets: np.ndarray):
        self.system = system
        masks = system.masks()
        self.top = np.flatnonzero(masks["topology"])
        self.equalities = self.top  # the rows the optimizers constrain (see keep_independent)
        self.trk = np.flatnonzero(masks["tracking"])
        missing = ~np.all(np.isfinite(targets), axis=1)
        self.missing = missing
        self.active = np.repeat(~missing, 3)
        weights = np.array([1.0 if w is None else w for w in system.trk_weight])
        self.point_weights = np.where(missing, 0.0, weights)
        self.drive = Drive(ref=np.where(missing[:, None], 0.0, targets))
        self._q: np.ndarray | None = None
        self._phi: np.ndarray | None = None
        self._J: np.ndarray | None = None

    def keep_independent(self, q: np.ndarray) -> None:
        """Keep as many topological rows as they have rank (``System.topology_rank``), the best
        conditioned at q first (QR with column pivoting of Φ_topᵀ), for optimizers that cannot
        take dependent equality constraints (trust-constr). Redundancy is a model's (a closed
        planar loop in 3D, a signed angle's cosine and sine rows), so the count is the model's,
        not the numerical rank at q, which a guess off the constraints overstates; of a signed
        angle's pair the pivoting keeps the row whose derivative does not vanish at this
        angle."""
        import scipy.linalg

        J = self._eval(q)[1][self.top]
        _, _, pivots = scipy.linalg.qr(J.T, pivoting=True, mode="economic")
        self.equalities = np.sort(self.top[pivots[: self.system.topology_rank]])

    # --- cached engine evaluation ------------------------------------------------------------
    def _eval(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if self._q is None or not np.array_equal(q, self._q):
            self._phi, self._J = self.system.evaluate(q, self.drive)
            self._q = q.copy()
        assert self._phi is not None and self._J is not None  # evaluated with self._q
        return self._phi, self._J

    def residuals(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Tracking residuals (n_targets × 3) and their Jacobian (n_targets × 3 × nq)."""
        phi, J = self._eval(q)
        n = len(self.point_weights)
        return phi[self.trk].reshape(n, 3), J[self.trk].reshape(n, 3, -1)

    # --- equality constraints ------------------------------------------------------------------
    def constraints(self, q: np.ndarray) -> np.ndarray:
        return self._eval(q)[0][self.equalities]

    def constraints_jacobian(self, q: np.ndarray) -> np.ndarray:
        return self._eval(q)[1][self.equalities]

    def constraints_hessian(self, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Σ v_i ∇²Φ_top,i."""
        c = np.zeros(self.system.n_rows)
        c[self.equalities] = v
        return self.system.residual_hessian(q, c)

    # --- objectives ----------------------------------------------------------------------------
    def tc(self, q: np.ndarray) -> tuple[float, np.ndarray]:
        """F = Σ w_n ‖C_P q − r*‖² and its gradient."""
        d, Jd = self.residuals(q)
        wd = self.point_weights[:, None] * d
        return float((wd * d).sum()), 2.0 * np.einsum("pk,pkq->q", wd, Jd)

    def tc_hessian(self, q: np.ndarray) -> np.ndarray:
        """∇²F of the TC objective: 2 Σ w (J_dᵀJ_d + d·∇²d)."""
        d, Jd = self.residuals(q)
        w = self.point_weights
        H = 2.0 * np.einsum("p,pkq,pkr->qr", w, Jd, Jd)
        c = np.zeros(self.system.n_rows)
        c[self.trk] = 2.0 * (w[:, None] * d).ravel()
        return H + self.system.residual_hessian(q, c)

    def distances(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Euclidean distance of each tracked point to its marker, smoothed at zero:
        √(‖d‖² + ε²) − ε with ε = 1 µm (differentiable where a point sits on its marker, as in
        unperturbed data), and its gradient (n × nq). Above a millimetre it is ‖d‖ − ε to within
        ε²/2‖d‖ < 1e-9 m: a uniform 1 µm shift, which moves neither the minimax's nor the sum's
        minimizer by more than that. Reported distances (ED) come from the points, unshifted."""
        d, Jd = self.residuals(q)
        smooth = np.sqrt((d * d).sum(axis=1) + ED_SMOOTHING**2)
        return smooth - ED_SMOOTHING, np.einsum("pk,pkq->pq", d / smooth[:, None], Jd)

    def ed(self, q: np.ndarray) -> tuple[float, np.ndarray]:
        """F = Σ w_n ‖C_P q − r*‖ and its gradient (zero where a point sits on its marker)."""
        dist, grad = self.distances(q)
        return float(self.point_weights @ dist), self.point_weights @ grad

    # --- statistics ----------------------------------------------------------------------------
    def statistics(self, q: np.ndarray) -> tuple[float, float]:
        """‖Φ‖ over the active equations and max |Φ_top| at q."""
        phi = self.system.residual(q, self.drive)
        keep = np.ones(len(phi), dtype=bool)
        keep[self.trk] = self.active
        return float(np.linalg.norm(phi[keep])), float(np.abs(phi[self.top]).max())

    def bound_arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`bounds` as lower and upper arrays (±inf where free)."""
        bounds = self.bounds()
        return (np.array([-np.inf if lo is None else lo for lo, _ in bounds]),
                np.array([np.inf if hi is None else hi for _, hi in bounds]))

    def bounds(self) -> list[tuple[float | None, float | None]]:
        """Unit-vector components in [−1.1, 1.1], angles in [2°, 178°], positions, distance
        coordinates and signed angles (``range: full``) free. The 0.1
        margin keeps a frame aligned with the axes (a component of exactly ±1) off the bound,
        where SLSQP would treat it as active and take several times more iterations; the angles
        stay where s1·s2 = cos θ is invertible (at 0 and π the MCR rows are singular, and
        goal attainment, whose optimum is flat, wandered there on noisy frames)."""
        layout = self.system.layout
        out: list[tuple[float | None, float | None]] = []
        for form in layout.forms:
            out += [(None, None)] * 3 + [(-1.1, 1.1)] * (9 if form == "full" else 6)
        free = self.system.distance_rows | self.system.full_angles
        out += [(None, None) if unbounded else (ANGLE_MARGIN, np.pi - ANGLE_MARGIN)
                for unbounded in free]
        return out

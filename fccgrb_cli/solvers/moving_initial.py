"""The first frame's guess for a model with moving joints (an imported OpenSim model).

Its bodies follow from its coordinates, so the guess is found in the coordinates alone: from the
default pose, the θ whose bodies (forward kinematics) put the tracked points nearest their
markers, in the least-squares sense (Levenberg–Marquardt projected on the clamped ranges), then q
of those bodies. The mixed solve refines it; the guess itself is never a result.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from fccgrb_cli.model import GROUND
from fccgrb_cli.solvers.newton import linear_solve
from fccgrb_cli.system import System
from fccgrb_cli.system.moving_pose import pose_from_coordinates

__all__ = ["bounded_least_squares", "moving_initial_guess"]

# Levenberg–Marquardt's damping: first value, its factors after a kept and a refused step, and
# the value at which a point no step improves is given up on (it is a guess's fit only).
DAMPING, SOFTER, HARDER, STIFF = 1e-3, 1.0 / 3.0, 4.0, 1e12


def bounded_least_squares(residual: Callable[[np.ndarray], np.ndarray],
                          jacobian: Callable[[np.ndarray], np.ndarray], start: np.ndarray,
                          low: np.ndarray, high: np.ndarray, evaluations: int) -> np.ndarray:
    """x in [low, high] (±inf: unbounded) near min ½‖r(x)‖², from ``start``.

    Levenberg–Marquardt steps (JᵀJ + μ diag(JᵀJ)) δ = −Jᵀr in the entries not held on a bound
    by the gradient, projected on the box; a step is kept only when it lowers the cost (μ
    shrinks), refused otherwise (μ grows). Ends when a kept
    step changes the cost by less than 1e-12 of it or x by less than 1e-10 in every entry, when
    μ passes 1e12, when every entry is held, or after ``evaluations`` residuals. An initial guess,
    which the solve refines (scipy's trust-region reflective method would cost its 0.3 s import
    on every command)."""
    x = np.clip(np.asarray(start, dtype=float), low, high)
    r = residual(x)
    cost, used, mu = float(r @ r), 1, DAMPING
    J = jacobian(x)
    while used < evaluations and mu <= STIFF:
        A, g = J.T @ J, J.T @ r
        # entries on a bound the gradient pushes against stay there (Bertsekas' projected
        # Newton): the step is taken in the others alone
        free = ~(((x <= low) & (g > 0.0)) | ((x >= high) & (g < 0.0)))
        if not free.any():
            break
        A = A[np.ix_(free, free)]
        scale = np.where(np.diag(A) > 0.0, np.diag(A), 1.0)
        step = np.zeros_like(x)
        try:
            step[free] = np.linalg.solve(A + mu * np.diag(scale), -g[free])
        except np.linalg.LinAlgError:
            mu *= HARDER
            continue
        trial = np.clip(x + step, low, high)
        r_trial = residual(trial)
        used += 1
        trial_cost = float(r_trial @ r_trial)
        if not trial_cost < cost:  # NaN included
            mu *= HARDER
            continue
        settled = cost - trial_cost <= 1e-12 * cost or np.max(np.abs(trial - x)) <= 1e-10
        x, r, cost, mu = trial, r_trial, trial_cost, mu * SOFTER
        if settled:
            break
        J = jacobian(x)
    return x


def moving_initial_guess(system: System, targets: np.ndarray) -> np.ndarray:
    """q near the markers ``targets`` (n_targets × 3, m, NaN in gaps) for a system with moving
    joints: the coordinates no coupling sets fitted from the model's defaults, the coupled and
    held ones following them, the bodies placed by all of them."""
    model, functions = system.model, system.functions
    assert functions is not None  # a system with moving joints has their function rows
    n_points = len(model.tracked_points)
    seen = np.all(np.isfinite(targets[:n_points]), axis=1)
    which = [(tp.body, tp.point) for tp, ok in zip(model.tracked_points, seen, strict=True) if ok]
    wanted = targets[:n_points][seen]
    dependent = {row[1] for row in functions.couplings}
    free = np.array([k for k in range(functions.n_coordinates) if k not in dependent], dtype=int)
    # held values first (a held coordinate may be a coupler's independent), then the couplers,
    # which the importer orders down their chains
    held = [c for c in functions.couplings if c[2] < 0]
    coupled = [c for c in functions.couplings if c[2] >= 0]

    def coordinates(values: np.ndarray) -> np.ndarray:
        theta = functions.defaults.copy()
        theta[free] = values
        for _, k, independent, function in held + coupled:
            theta[k] = function.terms(float(theta[independent]) if independent >= 0 else 0.0)[0]
        return theta

    def misfit(values: np.ndarray) -> np.ndarray:
        q = pose_from_coordinates(system, coordinates(values))
        return (system.point_positions(q, which) - wanted).ravel()

    nb = system.layout.n_body_q
    top = np.flatnonzero(system.kinds == 0)
    first = 3 * len(system.lin_a)
    tracked = (3 * np.flatnonzero(seen)[:, None] + (first + np.arange(3))).ravel()
    others = np.concatenate([np.arange(nb), nb + np.array(sorted(dependent), dtype=int)])

    def jacobian(values: np.ndarray) -> np.ndarray:
        # along the joints: Φ_top,others d(others) = −Φ_top,free d(free), so the points move by
        # their rows' Jacobian on the others times that solution (x and the coupled θ follow)
        J = system.jacobian(pose_from_coordinates(system, coordinates(values)))
        follow = linear_solve(J[np.ix_(top, others)], -J[np.ix_(top, nb + free)])
        return J[np.ix_(tracked, others)] @ follow

    low, high = _bounds(model, free)
    start = np.clip(functions.defaults[free], low, high)
    if not which or not len(free):
        return pose_from_coordinates(system, coordinates(start))
    root = _root_coordinates(model, free)
    if 0 < len(root) < len(free):  # the base first: the limbs then start near their markers
        def misfit_root(values: np.ndarray) -> np.ndarray:
            full = start.copy()
            full[root] = values
            return misfit(full)

        def jacobian_root(values: np.ndarray) -> np.ndarray:
            full = start.copy()
            full[root] = values
            return jacobian(full)[:, root]

        placed = bounded_least_squares(misfit_root, jacobian_root, start[root], low[root],
                                       high[root], 100 * len(root))
        start = start.copy()
        start[root] = placed
    fit = bounded_least_squares(misfit, jacobian, start, low, high, 100 * len(start))
    return pose_from_coordinates(system, coordinates(fit))


def _bounds(model, free: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each free coordinate's range where OpenSim clamps it (its IK keeps it inside, which
    also keeps a limb off its mirrored branch: an arm turned over, an elbow bent backwards),
    else unbounded."""
    angles = [model.angles[k] for k in free]
    low = np.array([a.range[0] if getattr(a, "clamped", False) else -np.inf for a in angles])
    high = np.array([a.range[1] if getattr(a, "clamped", False) else np.inf for a in angles])
    return low, high


def _root_coordinates(model, free: np.ndarray) -> np.ndarray:
    """Positions in ``free`` of the coordinates of the joints on the ground (the base)."""
    names = {c for joint in model.moving_joints if joint.parent == GROUND
             for c in joint.transform.coordinates}
    return np.array([i for i, k in enumerate(free) if model.angles[k].name in names], dtype=int)

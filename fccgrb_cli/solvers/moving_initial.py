"""The first frame's guess for a model with moving joints (an imported OpenSim model).

Its bodies follow from its coordinates, so the guess is found in the coordinates alone: from the
default pose, the θ whose bodies (forward kinematics) put the tracked points nearest their
markers, in the least-squares sense (Levenberg–Marquardt with a trust region), then q of those
bodies. The mixed solve refines it; the guess itself is never a result.
"""

from __future__ import annotations

import numpy as np

from fccgrb_cli.model import GROUND
from fccgrb_cli.solvers.newton import linear_solve
from fccgrb_cli.system import System
from fccgrb_cli.system.moving_pose import pose_from_coordinates

__all__ = ["moving_initial_guess"]


def moving_initial_guess(system: System, targets: np.ndarray) -> np.ndarray:
    """q near the markers ``targets`` (n_targets × 3, m, NaN in gaps) for a system with moving
    joints: the coordinates no coupling sets fitted from the model's defaults, the coupled and
    held ones following them, the bodies placed by all of them."""
    from scipy.optimize import least_squares

    model, functions = system.model, system.functions
    assert functions is not None  # a system with moving joints has their function rows
    n_points = len(model.tracked_points)
    seen = np.all(np.isfinite(targets[:n_points]), axis=1)
    which = [(tp.body, tp.point) for tp, ok in zip(model.tracked_points, seen, strict=True) if ok]
    wanted = targets[:n_points][seen]
    dependent = {row[1] for row in functions.couplings}
    free = np.array([k for k in range(functions.n_coordinates) if k not in dependent], dtype=int)

    def coordinates(values: np.ndarray) -> np.ndarray:
        theta = functions.defaults.copy()
        theta[free] = values
        for _, k, independent, function in functions.couplings:
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

        placed = least_squares(misfit_root, start[root], jac=jacobian_root, method="trf",
                               bounds=(low[root], high[root]), max_nfev=100 * len(root))
        start = start.copy()
        start[root] = placed.x
    fit = least_squares(misfit, start, jac=jacobian, method="trf", bounds=(low, high),
                        max_nfev=100 * len(start))
    return pose_from_coordinates(system, coordinates(fit.x))


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

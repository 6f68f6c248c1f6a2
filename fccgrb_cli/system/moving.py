"""Rows whose right-hand side is a general function of the coordinates (docs/opensim.md).

A moving joint (:class:`fccgrb_cli.model.spatial.MovingJoint`) gives 12 dot rows

    e_i^P · e_j^C − R_ij(θ) = 0   (i, j = 1…3),      (r_C − r_P) · e_k^P − p_k(θ) = 0   (k = 1…3),

with e^P, r_P the parent's joint frame axes and origin, e^C, r_C the child's, all features of the
bodies (linear in q); a coupling θ_d − f(θ_i) = 0 is one row of two zero features. Every row is
``F_a · F_b − c − h_r(θ)``: the existing dot rows with ``g(θ_k)`` generalized to any smooth
``h_r`` of several coordinates. :class:`FunctionRows` evaluates h, ∂h/∂θ and ∂²h/∂θ² for all of
them at once; the compiled system adds

    Φ_r −= h_r,   Φ_θ = −∂h/∂θ,   ν_r = ∂h/∂θ θ̇* (drivers),
    γ_r += θ̇ᵀ ∂²h/∂θ² θ̇ (+ ∂h/∂θ θ̈* for drivers),   ∇²_θθ(Σ c_r Φ_r) −= Σ c_r ∂²h_r/∂θ².

The rotation rows are nine for three degrees of freedom: dependent by design (rank 3 at every
pose, where any three of them would lose rank at some rotations), which the solvers take.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from fccgrb_cli.model import GROUND, Model
from fccgrb_cli.model.spatial import JointCoordinate
from fccgrb_cli.system.features import FeatureTable
from fccgrb_cli.system.moving_batch import StackedTransforms

__all__ = ["FunctionRows", "collect_function_rows"]


@dataclass(frozen=True, eq=False)
class FunctionRows:
    """The general-function rows of a compiled model: ``rows`` index the dot rows; ``joints``
    hold, per moving joint, its first row, its transform and the indices of its coordinates
    in θ; ``couplings`` per coupling its row, dependent index, independent index (−1: none)
    and function; ``defaults`` θ at the model's initial pose; ``translational`` which θ are
    metres."""

    rows: np.ndarray
    joints: tuple
    couplings: tuple
    n_coordinates: int
    defaults: np.ndarray
    translational: np.ndarray
    _last: list = field(default_factory=list)

    def terms(self, theta: np.ndarray, second: bool = True
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """h (n_rows,), ∂h/∂θ (n_rows × n_θ) and ∂²h/∂θ² (n_rows × n_θ × n_θ; zeros unless
        ``second``) at θ, rows in the order of :attr:`rows`. The last evaluation is kept: an
        iteration asks for the same θ's residual, Jacobian and curvature in turn."""
        key = np.asarray(theta, dtype=float).tobytes()
        if self._last and self._last[0] == key and (self._last[1] or not second):
            return self._last[2]
        out = self._terms(theta, second)
        self._last[:] = [key, second, out]
        return out

    def transforms(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Every moving joint's R_PC and p_PC at every frame of θ (frames × n_θ):
        frames × joints × 3 × 3 and frames × joints × 3, joints in the order of
        :attr:`joints`. At one θ (n_θ,), one frame of them from the rows' h (:meth:`terms`,
        which that pose's Φ_q and γ then reuse)."""
        stacked = self._stacked
        if np.ndim(theta) == 1:
            h = self.terms(theta, second=False)[0]
            return h[stacked.rot_rows].reshape(1, -1, 3, 3), h[stacked.tr_rows][None]
        return stacked.transforms(theta)

    @cached_property
    def _stacked(self) -> StackedTransforms:
        """The joints' transforms evaluated together (system/moving_batch.py)."""
        return StackedTransforms(self.joints, self.n_coordinates)

    def _terms(self, theta: np.ndarray, second: bool
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        n, nt = len(self.rows), self.n_coordinates
        h, h1, h2 = np.zeros(n), np.zeros((n, nt)), np.zeros((n, nt, nt))
        if self.joints:
            self._stacked.add(np.asarray(theta, dtype=float), second, h, h1, h2)
        for row, dependent, independent, function in self.couplings:
            # θ_d − f(θ_i) = −h  →  h = f(θ_i) − θ_d
            f, d1, d2 = function.terms(float(theta[independent]) if independent >= 0 else 0.0)
            h[row] = f - theta[dependent]
            h1[row, dependent] -= 1.0
            if independent >= 0:
                h1[row, independent] += d1
                h2[row, independent, independent] += d2
        return h, h1, h2


def collect_function_rows(features: FeatureTable, out, model: Model,
                          names: tuple[str, ...]) -> FunctionRows | None:
    """Append the rows of the model's moving joints and couplings to ``out`` (a
    ConstraintList) as dot rows with c = 0; ``names`` are the coordinates in θ's order.
    None when the model has neither."""
    if not model.moving_joints and not model.couplings:
        return None
    position = {name: k for k, name in enumerate(names)}
    rows: list[int] = []
    joints = []
    for joint in model.moving_joints:
        label = f"joint {joint.name} (moving)"
        parent_axes = [features.vector(joint.parent, a) for a in joint.parent_axes]
        child_axes = [features.vector(joint.child, a) for a in joint.child_axes]
        first = len(rows)
        for i, e_parent in enumerate(parent_axes):
            for j, e_child in enumerate(child_axes):
                rows.append(out.dot(e_parent, e_child, 0.0, f"{label}: R{i + 1}{j + 1}"))
        offset = features.difference(features.point(joint.child, joint.child_origin),
                                     features.point(joint.parent, joint.parent_origin))
        for k, e_parent in enumerate(parent_axes):
            rows.append(out.dot(offset, e_parent, 0.0, f"{label}: p{k + 1}"))
        index = np.array([position[c] for c in joint.transform.coordinates], dtype=int)
        joints.append((first, joint.transform, index))
    couplings = []
    zero = features.body_vector(GROUND, np.zeros(3))
    for coupling in model.couplings:
        couplings.append((len(rows), position[coupling.dependent],
                          position[coupling.independent] if coupling.independent else -1,
                          coupling.function))
        rows.append(out.dot(zero, zero, 0.0, f"coupling {coupling.name}"))
    # the coordinates of the moving joints, every one a JointCoordinate
    coordinates = [c for c in model.angles if isinstance(c, JointCoordinate) and c.name in position]
    return FunctionRows(
        rows=np.array(rows, dtype=int),
        joints=tuple(joints),
        couplings=tuple(couplings),
        n_coordinates=len(names),
        defaults=np.array([c.default for c in coordinates], dtype=float),
        translational=np.array([c.translational for c in coordinates], dtype=bool),
    )

"""Joints whose child frame moves in the parent frame as a function of coordinates.

A spatial transform (OpenSim's CustomJoint and every joint OpenSim defines through one) places
the child's joint frame C in the parent's joint frame P by

    R_PC(θ) = R(a_1, n_1) R(a_2, n_2) R(a_3, n_3),      p_PC(θ) = Σ_m b_m t_m,

three rotations by a_k = f_k(θ) about unit axes n_k of the turning frame (body-fixed), and a
translation along unit axes t_m of P by b_m = g_m(θ), every amount a function of one coordinate
(or a constant). The joint's rows (docs/opensim.md) need R_PC and p_PC with their first and
second derivatives in the coordinates; :meth:`SpatialTransform.terms` gives them as 12 values in
the order of the rows: R_PC row by row (R_ij = e_i^P · e_j^C), then p_PC's components in P.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Protocol

import numpy as np

__all__ = ["Coupling", "JointCoordinate", "MovingJoint", "Pieces", "ScalarFunction",
           "SpatialAxis", "SpatialTransform", "axis_rotation"]

Vec3 = tuple[float, float, float]


@dataclass(frozen=True)
class Pieces:
    """A function as polynomials piece by piece. With no ``knots`` one piece for every x; with
    m ≥ 2 increasing knots m + 1 pieces: x < knots[0], then [knots[k], knots[k+1]) for
    k = 0 … m − 2 (the last one closed: x = knots[−1] is in it), then x > knots[−1]. Piece p is
    Σ_j coefficients[p][j] (x − origins[p])^j: the same function as the class's ``terms``, its
    first and second derivatives included, to rounding."""

    knots: np.ndarray
    origins: np.ndarray
    coefficients: tuple[np.ndarray, ...]

    @classmethod
    def polynomial(cls, coefficients: list[float]) -> Pieces:
        """Σ c_j x^j for every x (coefficients from the constant term up)."""
        return cls(np.zeros(0), np.zeros(1), (np.asarray(coefficients, dtype=float),))

    def scaled(self, scale: float) -> Pieces:
        """The pieces of scale · f."""
        return Pieces(self.knots, self.origins, tuple(scale * c for c in self.coefficients))

    def values(self, x: np.ndarray) -> np.ndarray:
        """f at every x (any shape): each x's piece, then Horner's rule."""
        x = np.asarray(x, dtype=float)
        m = len(self.knots)
        if m == 0:
            piece = np.zeros(x.shape, dtype=int)
        else:  # the knots at or below x; x on the last knot is in the last closed interval
            piece = np.where(x == self.knots[-1], m - 1,
                             np.searchsorted(self.knots, x, side="right"))
        degree = max(len(c) for c in self.coefficients)
        table = np.zeros((len(self.coefficients), degree))
        for p, c in enumerate(self.coefficients):
            table[p, :len(c)] = c
        dx = x - self.origins[piece]
        out = np.zeros(x.shape)
        for j in range(degree - 1, -1, -1):
            out = out * dx + table[piece, j]
        return out


class ScalarFunction(Protocol):
    """f(x) with f′ and f″ (OpenSim's functions, ``fccgrb_cli.model.osim.functions``), and
    where it has that form, its polynomial pieces (None: it has not)."""

    def terms(self, x: float) -> tuple[float, float, float]: ...

    def pieces(self) -> Pieces | None: ...


def skew3(n: np.ndarray) -> np.ndarray:
    """ñ (3 × 3) with ñ b = n × b."""
    return np.array([[0.0, -n[2], n[1]], [n[2], 0.0, -n[0]], [-n[1], n[0], 0.0]])


def axis_rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rotation by ``angle`` (rad) about the unit ``axis``: I + sin a ñ + (1 − cos a) ñ²."""
    K = skew3(np.asarray(axis, dtype=float))
    return np.eye(3) + np.sin(angle) * K + (1.0 - np.cos(angle)) * K @ K


@dataclass(frozen=True)
class SpatialAxis:
    """One axis of a spatial transform: a rotation about or a translation along the unit
    ``axis`` by ``function(coordinate)`` (rad or m); ``coordinate`` None: a constant."""

    kind: str  # "rotation" or "translation"
    axis: Vec3
    coordinate: str | None
    function: ScalarFunction


@dataclass(frozen=True)
class SpatialTransform:
    """Three rotation axes, then three translation axes (see the module)."""

    axes: tuple[SpatialAxis, ...]

    @cached_property
    def _index(self) -> dict[str, int]:
        return {name: i for i, name in enumerate(self.coordinates)}

    @cached_property
    def _rotations(self) -> tuple:
        """Per rotation axis: the axis, ñ and ñ² (constant)."""
        out = []
        for a in self.axes:
            if a.kind == "rotation":
                K = skew3(np.asarray(a.axis, dtype=float))
                out.append((a, K, K @ K))
        return tuple(out)

    @cached_property
    def coordinates(self) -> tuple[str, ...]:
        """The distinct coordinates the transform depends on, in the order of first use."""
        out: list[str] = []
        for a in self.axes:
            if a.coordinate is not None and a.coordinate not in out:
                out.append(a.coordinate)
        return tuple(out)

    def terms(self, values: np.ndarray, second: bool = True
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """h (12,), ∂h/∂θ (12 × k) and ∂²h/∂θ² (12 × k × k; zeros unless ``second``) at the
        values (k,) of :attr:`coordinates`: h = [R_PC row by row, p_PC] (rad-free numbers
        and m). One joint at a time: the forward kinematics' form, and the reference that a
        solve's evaluation of all joints together (system/moving_batch.py) is tested against."""
        k = len(self.coordinates)
        index = self._index
        h, h1, h2 = np.zeros(12), np.zeros((12, k)), np.zeros((12, k, k))
        # rotations: G[o] = dᵒR_j/da_jᵒ (o = 0, 1, 2) = ñ_jᵒ R_j; products through prefixes
        # P_j = G0_1 … G0_(j−1) and suffixes S_j = G0_j … G0_m
        factors, slots, d1s, d2s = [], [], [], []
        for a, K, KK in self._rotations:
            x = values[index[a.coordinate]] if a.coordinate is not None else 0.0
            f, d1, d2 = a.function.terms(float(x))
            R = np.eye(3) + np.sin(f) * K + (1.0 - np.cos(f)) * KK
            factors.append((R, K @ R, KK @ R))
            slots.append(index[a.coordinate] if a.coordinate is not None else -1)
            d1s.append(d1)
            d2s.append(d2)
        m = len(factors)
        prefix = [np.eye(3)]
        for g in factors:
            prefix.append(prefix[-1] @ g[0])
        suffix = [np.eye(3)] * (m + 1)
        for j in range(m - 1, -1, -1):
            suffix[j] = factors[j][0] @ suffix[j + 1]
        h[:9] = prefix[m].ravel()
        for a_ in range(m):
            if slots[a_] < 0:
                continue
            left = prefix[a_] @ factors[a_][1]
            h1[:9, slots[a_]] += d1s[a_] * (left @ suffix[a_ + 1]).ravel()
            if not second:
                continue
            h2[:9, slots[a_], slots[a_]] += (
                d2s[a_] * (left @ suffix[a_ + 1])
                + d1s[a_] ** 2 * (prefix[a_] @ factors[a_][2] @ suffix[a_ + 1])).ravel()
            middle = left
            for b_ in range(a_ + 1, m):
                if slots[b_] >= 0:
                    both = (d1s[a_] * d1s[b_]
                            * (middle @ factors[b_][1] @ suffix[b_ + 1])).ravel()
                    h2[:9, slots[a_], slots[b_]] += both
                    h2[:9, slots[b_], slots[a_]] += both
                middle = middle @ factors[b_][0]
        for a in self.axes:
            if a.kind != "translation":
                continue
            t = np.asarray(a.axis, dtype=float)
            x = values[index[a.coordinate]] if a.coordinate is not None else 0.0
            f, d1, d2 = a.function.terms(float(x))
            h[9:] += f * t
            if a.coordinate is not None:
                j = index[a.coordinate]
                h1[9:, j] += d1 * t
                h2[9:, j, j] += d2 * t
        return h, h1, h2


@dataclass(frozen=True)
class MovingJoint:
    """A joint between ``parent`` and ``child`` (bodies; ``parent`` may be the ground): the
    child's joint frame (origin point ``child_origin`` and axes ``child_axes``, names of the
    child's point and three vectors) moves in the parent's joint frame (``parent_origin``,
    ``parent_axes`` of the parent) by ``transform``."""

    name: str
    parent: str
    child: str
    parent_origin: str
    parent_axes: tuple[str, str, str]
    child_origin: str
    child_axes: tuple[str, str, str]
    transform: SpatialTransform


@dataclass(frozen=True)
class Coupling:
    """θ_dependent = function(θ_independent): a coupler constraint (OpenSim's
    CoordinateCouplerConstraint), or with ``independent`` None and a constant function, a
    locked coordinate."""

    name: str
    dependent: str
    independent: str | None
    function: ScalarFunction


@dataclass(frozen=True)
class JointCoordinate:
    """A coordinate of a moving joint, solved as a mixed coordinate: rad, or m when
    ``translational``; ``default`` its value in the model's initial pose."""

    name: str
    translational: bool
    default: float
    range: tuple[float, float]
    clamped: bool = False  # OpenSim keeps its IK inside ``range``; fccgrb flags frames outside
    motion: None = None
    clinical_sign: None = None
    clinical_range: None = None

    @property
    def kind(self) -> str:
        """"joint": the coordinate has no row of its own; its joint's rows hold it."""
        return "joint"

    @property
    def full(self) -> bool:
        """Any value is allowed (no 0–π cosine ambiguity: the rows hold R(θ) itself)."""
        return True

    def clinical(self, theta: np.ndarray) -> None:
        """No clinical angle is declared for an imported coordinate."""
        return None

"""OpenSim's functions of one coordinate: value, first and second derivative.

A CustomJoint's transform axes and a CoordinateCouplerConstraint move by a function ``f(x)`` of a
coordinate; the constraint rows need f, f′ and f″ (docs/opensim.md). Each class below is the
mathematics OpenSim documents for the element of the same name:

* ``Constant``: f = c.
* ``LinearFunction``: ``coefficients = [slope, intercept]``.
* ``Polynomial`` (``PolynomialFunction``): ``coefficients`` from the highest power down.
* ``PiecewiseLinearFunction``: straight segments between the points, the end segments
  continued outside them.
* ``SimmSpline``: the cubic interpolating spline of Forsythe, Malcolm and Moler, whose third
  derivative on the first and last interval equals that of the cubic through the four points at
  that end (three points: a parabola; two: a line); outside the points, the tangent at the end
  point (f″ = 0).
* ``NaturalCubicSpline`` and ``natCubicSpline`` (2.x/3.x names): read as a ``SimmSpline``, as
  OpenSim reads them (it renames both on reading: that old spline was not a natural one).
* ``GCVSpline`` of odd degree 2m − 1 (m its ``half_order``) with no smoothing: the natural
  interpolating spline of that degree, which is ``Σ c_i |x − x_i|^(2m−1) + p(x)`` with p of
  degree m − 1 and ``Σ c_i x_i^k = 0`` for k < m; outside the points it is the polynomial of
  degree m − 1 its end piece continues into (derivatives m … 2m − 2 vanish at the ends).
* ``MultiplierFunction``: ``scale · f(x)``.

Every one of them is a polynomial piece by piece, inside and outside its points: ``pieces()``
gives that exact form (:class:`Pieces`), which the compiled kernels evaluate.
"""

from __future__ import annotations

from dataclasses import dataclass
from fractions import Fraction
from functools import cached_property
from math import comb

import numpy as np

from fccgrb_cli.model.spatial import Pieces

__all__ = [
    "Constant",
    "Function",
    "LinearFunction",
    "Multiplier",
    "NaturalSpline",
    "PiecewiseLinear",
    "Polynomial",
    "SimmSpline",
]


class Function:
    """A smooth-enough function of one coordinate, as OpenSim defines it."""

    def terms(self, x: float) -> tuple[float, float, float]:
        """f(x), f′(x) and f″(x) (units of the output per unit of x, and per unit²)."""
        raise NotImplementedError

    def pieces(self) -> Pieces | None:
        """f as :class:`Pieces`; None for a function without that form (it stays with the
        numpy reference engine)."""
        return None

    @property
    def constant(self) -> bool:
        """Whether f does not depend on x (a transform axis without a coordinate needs one)."""
        return False


@dataclass(frozen=True)
class Constant(Function):
    """f(x) = value."""

    value: float

    def terms(self, x: float) -> tuple[float, float, float]:
        return self.value, 0.0, 0.0

    def pieces(self) -> Pieces:
        return Pieces.polynomial([self.value])

    @property
    def constant(self) -> bool:
        return True


@dataclass(frozen=True)
class LinearFunction(Function):
    """f(x) = slope · x + intercept."""

    slope: float
    intercept: float

    def terms(self, x: float) -> tuple[float, float, float]:
        return self.slope * x + self.intercept, self.slope, 0.0

    def pieces(self) -> Pieces:
        return Pieces.polynomial([self.intercept, self.slope])


@dataclass(frozen=True)
class Polynomial(Function):
    """f(x) = Σ c_k x^(n−1−k), coefficients from the highest power down (OpenSim's order)."""

    coefficients: tuple[float, ...]

    def terms(self, x: float) -> tuple[float, float, float]:
        c = np.asarray(self.coefficients, dtype=float)
        d1 = np.polyder(c) if len(c) > 1 else np.zeros(1)
        d2 = np.polyder(d1) if len(d1) > 1 else np.zeros(1)
        return float(np.polyval(c, x)), float(np.polyval(d1, x)), float(np.polyval(d2, x))

    def pieces(self) -> Pieces:
        return Pieces.polynomial(list(self.coefficients)[::-1])


@dataclass(frozen=True)
class Multiplier(Function):
    """f(x) = scale · inner(x) (OpenSim's MultiplierFunction)."""

    inner: Function
    scale: float

    def terms(self, x: float) -> tuple[float, float, float]:
        f, d1, d2 = self.inner.terms(x)
        return self.scale * f, self.scale * d1, self.scale * d2

    def pieces(self) -> Pieces | None:
        inner = self.inner.pieces()
        return None if inner is None else inner.scaled(self.scale)

    @property
    def constant(self) -> bool:
        return self.inner.constant


def _interval(knots: np.ndarray, x: float) -> int:
    """The index k of the interval [x_k, x_k+1] holding x (the end intervals outside)."""
    return int(np.clip(np.searchsorted(knots, x, side="right") - 1, 0, len(knots) - 2))


@dataclass(frozen=True)
class PiecewiseLinear(Function):
    """Straight segments through the points; the end segments continue outside them."""

    x: tuple[float, ...]
    y: tuple[float, ...]

    def terms(self, x: float) -> tuple[float, float, float]:
        xs, ys = np.asarray(self.x), np.asarray(self.y)
        k = _interval(xs, x)
        slope = (ys[k + 1] - ys[k]) / (xs[k + 1] - xs[k])
        return float(ys[k] + slope * (x - xs[k])), float(slope), 0.0

    def pieces(self) -> Pieces:
        xs, ys = np.asarray(self.x, dtype=float), np.asarray(self.y, dtype=float)
        slopes = np.diff(ys) / np.diff(xs)
        # outside, the end segments themselves (origins x_0 and x_(m−2), as ``terms`` has them)
        k = np.concatenate([[0], np.arange(len(xs) - 1), [len(xs) - 2]])
        return Pieces(xs, xs[k], tuple(np.array([ys[i], slopes[i]]) for i in k))


class _Cubic(Function):
    """A cubic spline through (x_i, y_i) given by its second derivatives M_i at the knots;
    outside the knots the tangent line at the end knot."""

    x: tuple[float, ...]
    y: tuple[float, ...]

    @property
    def moments(self) -> np.ndarray:
        """M_i, the second derivatives at the knots."""
        raise NotImplementedError

    def terms(self, x: float) -> tuple[float, float, float]:
        xs, ys = np.asarray(self.x), np.asarray(self.y)
        M = self.moments
        if x < xs[0] or x > xs[-1]:
            end = 0 if x < xs[0] else len(xs) - 1
            k = min(end, len(xs) - 2)
            slope = self._slope(xs, ys, M, k, xs[end])
            return float(ys[end] + slope * (x - xs[end])), float(slope), 0.0
        k = _interval(xs, x)
        h = xs[k + 1] - xs[k]
        a, b = (xs[k + 1] - x) / h, (x - xs[k]) / h
        value = a * ys[k] + b * ys[k + 1] + ((a**3 - a) * M[k] + (b**3 - b) * M[k + 1]) * h**2 / 6
        return float(value), float(self._slope(xs, ys, M, k, x)), float(a * M[k] + b * M[k + 1])

    @staticmethod
    def _slope(xs: np.ndarray, ys: np.ndarray, M: np.ndarray, k: int, x: float) -> float:
        h = xs[k + 1] - xs[k]
        a, b = (xs[k + 1] - x) / h, (x - xs[k]) / h
        return (ys[k + 1] - ys[k]) / h + ((1 - 3 * a**2) * M[k] + (3 * b**2 - 1) * M[k + 1]) * h / 6

    def pieces(self) -> Pieces:
        """Inside, the Taylor form at each interval's left knot (y_k, f′, M_k/2,
        (M_k+1 − M_k)/6h); outside, the tangent line at the end knot."""
        xs, ys = np.asarray(self.x, dtype=float), np.asarray(self.y, dtype=float)
        M, n = self.moments, len(xs)
        inside = []
        for k in range(n - 1):
            h = xs[k + 1] - xs[k]
            inside.append(np.array([ys[k], self._slope(xs, ys, M, k, xs[k]), M[k] / 2,
                                    (M[k + 1] - M[k]) / (6 * h)]))
        left = np.array([ys[0], self._slope(xs, ys, M, 0, xs[0])])
        right = np.array([ys[-1], self._slope(xs, ys, M, n - 2, xs[-1])])
        origins = np.concatenate([[xs[0]], xs[:-1], [xs[-1]]])
        return Pieces(xs, origins, (left, *inside, right))

    def _interior(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The continuity rows h_{i−1} M_{i−1} + 2(h_{i−1} + h_i) M_i + h_i M_{i+1} = 6 Δ²."""
        xs, ys = np.asarray(self.x), np.asarray(self.y)
        n = len(xs)
        h = np.diff(xs)
        slope = np.diff(ys) / h
        A, rhs = np.zeros((n, n)), np.zeros(n)
        for i in range(1, n - 1):
            A[i, i - 1:i + 2] = h[i - 1], 2 * (h[i - 1] + h[i]), h[i]
            rhs[i] = 6 * (slope[i] - slope[i - 1])
        return A, rhs, h


def _third_difference(x: np.ndarray, y: np.ndarray) -> float:
    """6 f[x0, x1, x2, x3]: the third derivative of the cubic through four points."""
    d = y.astype(float).copy()
    for level in range(1, 4):
        d[level:] = (d[level:] - d[level - 1:-1]) / (x[level:] - x[:-level])
    return 6.0 * d[3]


@dataclass(frozen=True)
class SimmSpline(_Cubic):
    """OpenSim's SimmSpline: end third derivatives from the four end points (see module)."""

    x: tuple[float, ...]
    y: tuple[float, ...]

    @cached_property
    def moments(self) -> np.ndarray:
        """M_i from the interior continuity rows and the end conditions."""
        xs, ys = np.asarray(self.x), np.asarray(self.y)
        if len(xs) == 2:
            return np.zeros(2)
        A, rhs, h = self._interior()
        n = len(xs)
        left = _third_difference(xs[:4], ys[:4]) if n > 3 else 0.0
        right = _third_difference(xs[-4:], ys[-4:]) if n > 3 else 0.0
        A[0, :2] = -1.0, 1.0          # (M1 − M0) / h0 = f‴ on the first interval
        rhs[0] = left * h[0]
        A[-1, -2:] = -1.0, 1.0        # (M_n−1 − M_n−2) / h_n−2 = f‴ on the last one
        rhs[-1] = right * h[-1]
        return np.linalg.solve(A, rhs)


@dataclass(frozen=True)
class NaturalSpline(Function):
    """The natural interpolating spline of odd degree 2m − 1 through the points (OpenSim's
    GCVSpline of degree 2m − 1 without smoothing), written as
    ``Σ c_i |x − x_i|^(2m−1) + Σ_k<m p_k x^k`` with ``Σ c_i x_i^k = 0`` for k < m."""

    x: tuple[float, ...]
    y: tuple[float, ...]
    degree: int = 3

    @cached_property
    def coefficients(self) -> tuple[np.ndarray, np.ndarray]:
        xs, ys = np.asarray(self.x), np.asarray(self.y)
        n, m = len(xs), (self.degree + 1) // 2
        shift = 0.5 * (xs[0] + xs[-1])
        scale = max(0.5 * (xs[-1] - xs[0]), 1e-300)
        t = (xs - shift) / scale
        P = np.vander(t, m, increasing=True)
        A = np.zeros((n + m, n + m))
        A[:n, :n] = np.abs(t[:, None] - t[None, :]) ** self.degree
        A[:n, n:] = P
        A[n:, :n] = P.T
        solution = np.linalg.lstsq(A, np.concatenate([ys, np.zeros(m)]), rcond=None)[0]
        return solution[:n], solution[n:]

    def terms(self, x: float) -> tuple[float, float, float]:
        xs = np.asarray(self.x)
        c, p = self.coefficients
        shift = 0.5 * (xs[0] + xs[-1])
        scale = max(0.5 * (xs[-1] - xs[0]), 1e-300)
        t = (x - shift) / scale
        r = t - (xs - shift) / scale
        k, a = self.degree, np.abs(r)
        value = c @ a**k + np.polyval(p[::-1], t)
        d1 = k * c @ (a ** (k - 1) * np.sign(r)) + np.polyval(np.polyder(p[::-1]), t)
        poly2 = np.polyder(p[::-1], 2) if len(p) > 2 else np.zeros(1)
        d2 = (k * (k - 1) * c @ a ** (k - 2) if k > 1 else 0.0) + np.polyval(poly2, t)
        return float(value), float(d1 / scale), float(d2 / scale**2)

    def pieces(self) -> Pieces:
        """On each piece |t − t_i|^k is ±(t − t_i)^k (k odd: − where t < t_i): the sum and
        the polynomial expanded about the piece's origin (the nearest knot on its left, the
        first knot for the piece before it), then t − t_o = (x − x_o) / scale. The expansion
        is exact (rational arithmetic on the float coefficients, rounded once at the end):
        where the c_i are large its terms cancel, and rounding them one by one would add to
        the error ``terms`` already has. At a knot of a degree-1 spline (a kink) f′ is the
        right-hand one, where ``terms`` gives the mean of the two sides."""
        xs = np.asarray(self.x, dtype=float)
        c, p = self.coefficients
        shift = 0.5 * (xs[0] + xs[-1])
        scale = max(0.5 * (xs[-1] - xs[0]), 1e-300)
        t = [(Fraction(v) - Fraction(shift)) / Fraction(scale) for v in xs]
        cs, ps, k, n = [Fraction(v) for v in c], [Fraction(v) for v in p], self.degree, len(xs)
        out, origins = [], []
        for piece in range(n + 1):
            o = max(piece - 1, 0)
            # Σ_i σ_i c_i (t − t_i)^k = Σ_j C(k, j) (t − t_o)^j Σ_i σ_i c_i (t_o − t_i)^(k−j)
            a = [comb(k, j) * sum(((ci if i < piece else -ci) * (t[o] - t[i]) ** (k - j)
                                   for i, ci in enumerate(cs)), Fraction(0))
                 for j in range(k + 1)]
            for power, coefficient in enumerate(ps):  # p_l t^l about t_o
                for j in range(power + 1):
                    a[j] += coefficient * comb(power, j) * t[o] ** (power - j)
            out.append(np.array([float(a_j / Fraction(scale) ** j) for j, a_j in enumerate(a)]))
            origins.append(xs[o])
        return Pieces(xs, np.array(origins), tuple(out))

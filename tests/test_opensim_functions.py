"""OpenSim's functions: values against closed forms and an independent spline code (scipy),
derivatives against finite differences, on generated knots."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.interpolate import CubicSpline, make_interp_spline

from fccgrb_cli.model.osim.functions import (
    Constant,
    LinearFunction,
    Multiplier,
    NaturalSpline,
    PiecewiseLinear,
    Polynomial,
    SimmSpline,
)


def knots(seed: int, n: int = 9) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    x = np.sort(rng.uniform(-2.0, 2.0, n))
    while np.min(np.diff(x)) < 0.05:
        x = np.sort(rng.uniform(-2.0, 2.0, n))
    return x, rng.normal(size=n)


def inside(x: np.ndarray, count: int = 23) -> np.ndarray:
    """Points strictly inside the knots' span and away from the knots themselves."""
    t = np.linspace(x[0], x[-1], count)[1:-1]
    return t[np.min(np.abs(t[:, None] - x[None, :]), axis=1) > 1e-3]


def all_functions(seed: int) -> list:
    x, y = knots(seed)
    return [Constant(0.7), LinearFunction(-1.3, 0.4), Polynomial((0.3, -1.0, 2.0, 0.5)),
            PiecewiseLinear(tuple(x), tuple(y)), SimmSpline(tuple(x), tuple(y)),
            NaturalSpline(tuple(x), tuple(y), 3), NaturalSpline(tuple(x), tuple(y), 5),
            Multiplier(SimmSpline(tuple(x), tuple(y)), -1.7)]


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_derivatives_match_finite_differences(seed):
    h = 1e-5  # central differences: truncation ~h²·f‴, round-off ~1e-11/h
    x, _ = knots(seed)
    for f in all_functions(seed):
        for t in [*inside(x), x[0] - 0.3, x[-1] + 0.4]:
            _, d1, d2 = f.terms(t)
            fd1 = (f.terms(t + h)[0] - f.terms(t - h)[0]) / (2 * h)
            fd2 = (f.terms(t + h)[1] - f.terms(t - h)[1]) / (2 * h)
            scale = 1.0 + abs(d1)
            assert abs(d1 - fd1) < 1e-5 * scale, (f, t)
            assert abs(d2 - fd2) < 1e-4 * (1.0 + abs(d2)), (f, t)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_splines_interpolate_their_points(seed):
    x, y = knots(seed)
    for f in all_functions(seed)[3:7]:
        assert np.allclose([f.terms(v)[0] for v in x], y, atol=1e-9)


def test_simm_spline_reproduces_a_cubic_everywhere_between_its_points():
    # FMM end conditions take the end third derivatives from the cubic through the last four
    # points: a cubic's samples give back that cubic exactly, end intervals included
    c = np.array([0.3, -1.0, 2.0, 0.5])
    for seed in range(3):
        x, _ = knots(seed)
        f = SimmSpline(tuple(x), tuple(np.polyval(c, x)))
        for t in inside(x, 41):
            value, d1, d2 = f.terms(t)
            assert value == pytest.approx(np.polyval(c, t), abs=1e-10)
            assert d1 == pytest.approx(np.polyval(np.polyder(c), t), abs=1e-9)
            assert d2 == pytest.approx(np.polyval(np.polyder(c, 2), t), abs=1e-8)


def test_simm_spline_of_three_points_is_their_parabola_and_of_two_their_line():
    x = (-1.0, 0.5, 2.0)
    c = np.array([0.7, -0.2, 1.1])
    f = SimmSpline(x, tuple(np.polyval(c, x)))
    assert f.terms(1.3)[0] == pytest.approx(np.polyval(c, 1.3), abs=1e-12)
    line = SimmSpline((0.0, 2.0), (1.0, 2.0))
    assert line.terms(0.5) == pytest.approx((1.25, 0.5, 0.0))


def test_simm_spline_continues_along_its_end_tangents():
    x, y = knots(4)
    f = SimmSpline(tuple(x), tuple(y))
    end, slope, _ = f.terms(x[-1])
    assert f.terms(x[-1] + 0.5) == pytest.approx((end + 0.5 * slope, slope, 0.0))
    start, slope0, _ = f.terms(x[0])
    assert f.terms(x[0] - 0.25) == pytest.approx((start - 0.25 * slope0, slope0, 0.0))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_natural_cubic_spline_equals_scipy_natural_spline(seed):
    x, y = knots(seed)
    f = NaturalSpline(tuple(x), tuple(y), 3)
    reference = CubicSpline(x, y, bc_type="natural")
    for t in inside(x):
        assert f.terms(t) == pytest.approx([float(reference(t, k)) for k in range(3)],
                                           abs=1e-8)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_quintic_gcv_spline_is_the_natural_quintic_interpolant(seed):
    # the natural quintic: f‴ = f⁗ = 0 at both ends, built by scipy's B-splines
    x, y = knots(seed)
    f = NaturalSpline(tuple(x), tuple(y), 5)
    natural = [(3, 0.0), (4, 0.0)]
    reference = make_interp_spline(x, y, k=5, bc_type=(natural, natural))
    for t in inside(x):
        assert f.terms(t) == pytest.approx([float(reference(t, k)) for k in range(3)],
                                           abs=1e-7)


def test_quintic_spline_reproduces_quadratics_and_extrapolates_them():
    x, _ = knots(5)
    c = np.array([1.0, 2.0, 3.0])
    f = NaturalSpline(tuple(x), tuple(np.polyval(c, x)), 5)
    for t in (x[0] - 1.0, 0.1, x[-1] + 1.0):
        assert f.terms(t) == pytest.approx((np.polyval(c, t), np.polyval(np.polyder(c), t),
                                            2.0), abs=1e-8)


def test_closed_forms_of_the_simple_functions():
    assert Polynomial((2.0, -3.0, 1.0)).terms(2.0) == pytest.approx((3.0, 5.0, 4.0))
    assert LinearFunction(2.0, -1.0).terms(3.0) == (5.0, 2.0, 0.0)
    assert Multiplier(LinearFunction(2.0, -1.0), 3.0).terms(3.0) == (15.0, 6.0, 0.0)
    pl = PiecewiseLinear((0.0, 1.0, 3.0), (0.0, 2.0, 1.0))
    assert pl.terms(2.0) == pytest.approx((1.5, -0.5, 0.0))
    assert pl.terms(4.0) == pytest.approx((0.5, -0.5, 0.0))
    assert pl.terms(-1.0) == pytest.approx((-2.0, 2.0, 0.0))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_pieces_give_every_functions_values_at_many_points(seed):
    """``Pieces.values`` (a pose of many frames at once) equals each function's own ``terms``
    inside, on and outside its knots, whatever the shape of the points given (to 1e-10 of
    its largest value: a natural spline's pieces are expanded exactly from its |x − x_i|^k
    form, which loses more to rounding)."""
    x, _ = knots(seed)
    points = np.concatenate([inside(x), x, [x[0] - 0.7, x[-1] + 0.9, x[-1]]])
    for f in all_functions(seed):
        values = f.pieces().values(points)
        expected = np.array([f.terms(float(t))[0] for t in points])
        scale = 1e-10 * max(1.0, float(np.abs(expected).max()))
        assert np.allclose(values, expected, rtol=0, atol=scale), f
        assert f.pieces().values(points.reshape(-1, 1)).shape == (len(points), 1)
        assert f.pieces().values(np.float64(x[-1])) == pytest.approx(f.terms(x[-1])[0],
                                                                      rel=0, abs=scale)

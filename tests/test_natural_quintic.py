"""``signals.natural_quintic``: the natural quintic interpolating spline's f′, f″ at its samples.

Independent checks: scipy's B-spline construction of the same spline (``make_interp_spline``,
k = 5, f‴ = f⁗ = 0 at both ends) on generated uneven grids; its exactness on quadratics (the
natural spline reproduces the polynomials of degree < 3); and the Hermite end-derivative
formulas of the module's docstring against the quintic they describe."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.interpolate import make_interp_spline

from fccgrb_cli.signals.natural_quintic import natural_quintic


@pytest.mark.parametrize("seed", range(10))
def test_equals_scipy_b_spline_construction(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = int(rng.choice([3, 4, 5, 7, 12, 60, 400]))
    x = rng.uniform(-5.0, 5.0) + np.cumsum(rng.uniform(0.05, 3.0, n)) * 10.0 ** rng.uniform(-3, 1)
    y = rng.normal(size=(n, 3)).cumsum(axis=0) * 10.0 ** rng.uniform(-2, 2)
    natural = [(3, np.zeros(3)), (4, np.zeros(3))]
    spline = make_interp_spline(x, y, k=5, bc_type=(natural, natural))
    first, second = natural_quintic(x, y)
    for mine, order in ((first, 1), (second, 2)):
        expected = spline(x, order)
        assert np.abs(mine - expected).max() <= 1e-9 * np.abs(expected).max()


def test_one_signal_keeps_its_shape() -> None:
    x = np.linspace(0.0, 1.0, 9)
    first, second = natural_quintic(x, np.sin(x))
    assert first.shape == second.shape == (9,)


@pytest.mark.parametrize("seed", range(4))
def test_reproduces_quadratics(seed: int) -> None:
    rng = np.random.default_rng(seed)
    x = np.cumsum(rng.uniform(0.1, 1.0, 25))
    c = rng.normal(size=3)
    first, second = natural_quintic(x, np.polyval(c, x))
    assert first == pytest.approx(np.polyval(np.polyder(c), x), rel=1e-9, abs=1e-9)
    assert second == pytest.approx(np.full_like(x, 2.0 * c[0]), rel=1e-9, abs=1e-9)


def test_end_derivative_formulas_of_the_quintic() -> None:
    # the quintic with f, f', f'' given at 0 and h: its f''' and f'''' at both ends
    rng = np.random.default_rng(3)
    h = 0.37
    f0, f1, d0, d1, e0, e1 = rng.normal(size=6)
    A = np.array([[h**3, h**4, h**5], [3 * h**2, 4 * h**3, 5 * h**4],
                  [6 * h, 12 * h**2, 20 * h**3]])
    a3, a4, a5 = np.linalg.solve(A, [f1 - f0 - d0 * h - e0 * h**2 / 2, d1 - d0 - e0 * h, e1 - e0])
    delta = (f1 - f0) / h
    assert 6 * a3 == pytest.approx((60 * delta - 36 * d0 - 24 * d1) / h**2 + (-9 * e0 + 3 * e1) / h)
    assert 24 * a4 == pytest.approx((-360 * delta + 192 * d0 + 168 * d1) / h**3
                                    + (36 * e0 - 24 * e1) / h**2)
    assert 6 * a3 + 24 * a4 * h + 60 * a5 * h**2 == pytest.approx(
        (60 * delta - 24 * d0 - 36 * d1) / h**2 + (-3 * e0 + 9 * e1) / h)
    assert 24 * a4 + 120 * a5 * h == pytest.approx(
        (360 * delta - 168 * d0 - 192 * d1) / h**3 + (-24 * e0 + 36 * e1) / h**2)


@pytest.mark.parametrize("bad", [np.array([0.0, 1.0]), np.array([0.0, 1.0, 1.0, 2.0])])
def test_too_few_or_repeated_points_refused(bad: np.ndarray) -> None:
    with pytest.raises(ValueError, match="strictly increasing"):
        natural_quintic(bad, np.zeros(len(bad)))

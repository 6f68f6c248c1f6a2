"""The first frame's guess of an imported model: the bounded least squares it is fitted by,
against scipy's trust-region reflective method on generated problems."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import least_squares

from fccgrb_cli.solvers.moving_initial import bounded_least_squares


def _problem(seed: int):
    """Markers of a random planar chain of n links (lengths known), angles to fit: r(x) the
    joint positions' misfit. Returns residual, Jacobian, the true angles."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(2, 6))
    lengths = rng.uniform(0.2, 0.6, n)
    truth = rng.uniform(-1.2, 1.2, n)

    def points(x):
        turn = np.cumsum(x)
        return np.cumsum(lengths[:, None] * np.column_stack([np.cos(turn), np.sin(turn)]), 0)

    observed = points(truth) + rng.normal(0.0, 0.01, (n, 2))

    def residual(x):
        return (points(x) - observed).ravel()

    def jacobian(x):
        turn = np.cumsum(x)
        d = lengths[:, None] * np.column_stack([-np.sin(turn), np.cos(turn)])  # ∂p_i/∂turn_i
        J = np.zeros((n, 2, n))
        for i in range(n):  # point i moves with every angle k ≤ i through the links k..i
            for k in range(i + 1):
                J[i, :, k] = d[k:i + 1].sum(0)
        return J.reshape(2 * n, n)

    return residual, jacobian, truth, rng


@pytest.mark.parametrize("seed", range(12))
def test_unbounded_fit_reaches_scipys_optimum(seed):
    residual, jacobian, truth, rng = _problem(seed)
    start = truth + rng.uniform(-0.3, 0.3, len(truth))
    inf = np.full(len(truth), np.inf)
    ours = bounded_least_squares(residual, jacobian, start, -inf, inf, 100 * len(truth))
    theirs = least_squares(residual, start, jac=jacobian, method="trf", xtol=1e-14,
                           ftol=1e-14, gtol=1e-14).x
    cost = residual(ours) @ residual(ours)
    assert cost <= residual(theirs) @ residual(theirs) * (1 + 1e-8) + 1e-20
    np.testing.assert_allclose(ours, theirs, atol=1e-6)


@pytest.mark.parametrize("seed", range(12))
def test_bounded_fit_stays_inside_and_matches_scipy_where_a_bound_binds(seed):
    residual, jacobian, truth, rng = _problem(seed)
    # the first angle's range ends short of its true value: the bound binds at the optimum
    low, high = np.full(len(truth), -np.inf), np.full(len(truth), np.inf)
    high[0] = truth[0] - 0.2
    start = np.clip(truth + rng.uniform(-0.2, 0.2, len(truth)), low, high)
    ours = bounded_least_squares(residual, jacobian, start, low, high, 200 * len(truth))
    theirs = least_squares(residual, start, jac=jacobian, method="trf", bounds=(low, high),
                           xtol=1e-14, ftol=1e-14, gtol=1e-14).x
    assert np.all(ours <= high) and np.all(ours >= low)
    assert residual(ours) @ residual(ours) <= residual(theirs) @ residual(theirs) * 1.001
    np.testing.assert_allclose(ours, theirs, atol=1e-3)


def test_a_residual_that_turns_nan_is_stepped_back_from():
    """A step into a region where the model is undefined is refused, not taken."""
    def residual(x):
        return np.array([np.sqrt(x[0]) - 0.5]) if x[0] >= 0 else np.array([np.nan])

    def jacobian(x):
        return np.array([[0.5 / np.sqrt(max(x[0], 1e-12))]])

    fit = bounded_least_squares(residual, jacobian, np.array([4.0]), np.array([-np.inf]),
                                np.array([np.inf]), 100)
    assert fit[0] == pytest.approx(0.25, abs=1e-6)

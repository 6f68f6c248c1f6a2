"""``newton.minimum_norm_solve`` (LAPACK's gelsy through scipy's compiled module) against numpy's
SVD least squares: the minimum-norm solution on generated tall, wide and rank-deficient
systems, vector and matrix right-hand sides."""

from __future__ import annotations

import numpy as np
import pytest

from fccgrb_cli.solvers.newton import linear_solve, minimum_norm_solve


@pytest.mark.parametrize("seed", range(12))
def test_minimum_norm_solution_as_numpy_svd(seed: int) -> None:
    rng = np.random.default_rng(seed)
    m, n = (int(v) for v in rng.integers(2, 40, size=2))
    rank = int(rng.integers(1, min(m, n) + 1))
    A = rng.normal(size=(m, rank)) @ rng.normal(size=(rank, n)) * 10.0 ** rng.uniform(-3, 3)
    b = rng.normal(size=(m,) if seed % 2 else (m, int(rng.integers(1, 5))))
    expected = np.linalg.lstsq(A, b, rcond=np.finfo(float).eps * max(m, n))[0]
    x = minimum_norm_solve(A, b)
    assert x.shape == expected.shape
    scale = np.abs(expected).max()
    assert np.abs(x - expected).max() <= 1e-8 * scale
    assert np.abs(linear_solve(A, b) - expected).max() <= 1e-8 * scale or m == n


def test_inputs_left_alone() -> None:
    rng = np.random.default_rng(0)
    A, b = rng.normal(size=(6, 4)), rng.normal(size=6)
    A0, b0 = A.copy(), b.copy()
    minimum_norm_solve(A, b)
    assert np.array_equal(A, A0) and np.array_equal(b, b0)

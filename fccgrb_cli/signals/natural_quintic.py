"""The natural quintic interpolating spline of sampled signals and its first two derivatives at the
samples (OpenSim's GCVSpline of degree 5 without smoothing, as its inverse dynamics tool fits
the coordinates; docs/opensim.md).

Written in Hermite form: on each interval [x_i, x_i + h] the quintic is fixed by f, f′, f″ at
its two ends, so with the samples f_i known, the unknowns are d_i = f′(x_i) and e_i = f″(x_i).
With δ = (f_{i+1} − f_i)/h, the third and fourth derivatives at the interval's ends are

    f‴(x_i⁺)     = ( 60δ − 36 d_i − 24 d_{i+1}) / h² + (−9 e_i + 3 e_{i+1}) / h
    f⁗(x_i⁺)     = (−360δ + 192 d_i + 168 d_{i+1}) / h³ + (36 e_i − 24 e_{i+1}) / h²
    f‴(x_{i+1}⁻) = ( 60δ − 24 d_i − 36 d_{i+1}) / h² + (−3 e_i + 9 e_{i+1}) / h
    f⁗(x_{i+1}⁻) = ( 360δ − 168 d_i − 192 d_{i+1}) / h³ + (−24 e_i + 36 e_{i+1}) / h²

(sympy; a test checks them against the polynomial). The spline is C⁴: f‴ and f⁗ agree on
both sides of every inner sample; natural: f‴ = f⁗ = 0 at both ends. That is 2n equations in
the 2n unknowns, banded (three entries either side of the diagonal, unknowns interleaved
d_0, e_0, d_1, ...), solved by LAPACK's banded Gaussian elimination with partial pivoting
(dgbsv), every signal a right-hand side of the same matrix. scipy's ``make_interp_spline(k=5)``
builds the same spline from B-splines; importing it costs ~0.3 s of every inverse dynamics
command.
"""

from __future__ import annotations

import numpy as np

from fccgrb_cli.core.blas import lapack

__all__ = ["natural_quintic"]

KL = KU = 3  # the equations' band: entries up to three columns either side of the diagonal


def natural_quintic(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """f′ and f″ at the samples of the natural quintic spline through (x, y).

    Parameters
    ----------
    x
        The sample points (n ≥ 3: through two, a quadratic of any curvature is as natural),
        strictly increasing.
    y
        The samples (n, or n × signals).

    Returns
    -------
    tuple of numpy.ndarray
        f′ and f″ at ``x`` (shaped as ``y``; per unit of x and its square).
    """
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    n = len(x)
    h = np.diff(x)
    if n < 3 or y.shape[0] != n or not np.all(h > 0.0):
        raise ValueError("natural_quintic: expected n ≥ 3 strictly increasing points and n "
                         "samples")
    scale = float(np.mean(h))  # unknowns d_i and u_i = e_i · scale; equations made unitless
    r = h / scale
    columns = y.reshape(n, -1)
    slope = np.diff(columns, axis=0) / h[:, None]  # δ per interval, (n − 1) × signals
    # each interval's four end conditions in the unknowns (d_k, u_k, d_{k+1}, u_{k+1}) with
    # u = e · scale, rows multiplied by scale² (f‴) and scale³ (f⁗), and the multiple of δ_k:
    # (coefficients, δ's) for f‴ and f⁗ at the interval's left end, then at its right end
    left = ((np.stack([-36 / r**2, -9 / r, -24 / r**2, 3 / r], axis=1), 60 / r**2),
            (np.stack([192 / r**3, 36 / r**2, 168 / r**3, -24 / r**2], axis=1), -360 / r**3))
    right = ((np.stack([-24 / r**2, -3 / r, -36 / r**2, 9 / r], axis=1), 60 / r**2),
             (np.stack([-168 / r**3, -24 / r**2, -192 / r**3, 36 / r**2], axis=1), 360 / r**3))
    N = 2 * n
    # LAPACK's band storage: ab[KL + KU + r − c, c] = A[r, c], KL more rows for the fill-in
    ab = np.zeros((2 * KL + KU + 1, N))
    rhs = np.zeros((N, columns.shape[1]))
    k = np.arange(n - 1)
    # rows 2i (f‴) and 2i + 1 (f⁗) at sample i: (interval i − 1 at its right end) − (interval
    # i at its left end) = 0, the ends' missing side being the natural condition's zero
    for sign, at_sample, ends in ((1.0, k + 1, right), (-1.0, k, left)):
        for row, (block, delta) in enumerate(ends):
            at = 2 * at_sample + row
            for j in range(4):
                ab[KL + KU + at - (2 * k + j), 2 * k + j] += sign * block[:, j]
            rhs[at] -= sign * delta[:, None] * slope
    solution = _banded_solve(ab, rhs)
    first = solution[0::2].reshape(y.shape)
    second = (solution[1::2] / scale).reshape(y.shape)
    return first, second


def _banded_solve(ab: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """A x = rhs for A of band KL below, KU above, in LAPACK's band storage ``ab``: LAPACK's
    dgbsv (Gaussian elimination with partial pivoting on the band) through scipy's compiled
    module (``core.blas.lapack``, without the ``scipy.linalg`` package's import).
    ``numpy.linalg.LinAlgError`` for a singular A."""
    x, info = lapack.dgbsv(KL, KU, ab, rhs)[2:]
    if info:
        raise np.linalg.LinAlgError("natural_quintic: singular equations" if info > 0 else
                                    f"dgbsv: illegal argument {-info}")
    return x

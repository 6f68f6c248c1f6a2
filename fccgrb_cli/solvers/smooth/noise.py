"""The smoothing strength from the data: the markers' noise from the fit's residuals, then each
coordinate's prior by maximum likelihood.

* Marker noise σ: the residuals e = y − p(d̂) of each frame's own least-squares fit are the
  noise projected off the model, e = (I − P_H) ε, and a low-frequency artefact the model cannot
  follow. Their third difference along frames removes the artefact (a 3 Hz component at 200 Hz
  keeps (2π 3/200)³ ≈ 10⁻³ of itself) and keeps white noise with variance σ² Σ_j c_j² (1 − h),
  c = (1, −3, 3, −1), h the row's leverage (diagonal of H A⁻¹ Hᵀ). σ is the median absolute
  third difference over 0.6745 (a marker's spike or swap moves it little), scaled by that
  variance: an estimate of the white noise only. A low-frequency soft-tissue artefact is not
  noise to a smoother — it moves with the motion, in its band, and no smoother can tell it from
  motion — so it stays in the motion, as it does with any filter.
* Each coordinate's cutoff f_c: its frames' own estimates z_k = (A⁻¹ b)_k with variance
  (A⁻¹)_kk, and the prior of order p whose equivalent cutoff is f_c (``prior.density``); the
  likelihood of z_k by the Kalman filter's prediction errors is maximized over f_c on a
  log-spaced grid between ``LOWEST`` Hz and 0.45 × the frame rate, then refined by golden
  section (to ``PRECISION``). The coordinates are taken one at a time (their frames' estimates
  are correlated, which the smoother itself then takes into account): a coupled likelihood
  would cost a coupled filter per trial point.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from fccgrb_cli.solvers.smooth.prior import ORDER, density, noise_shape, transition
from fccgrb_cli.solvers.smooth.start import initial_state

LOWEST = 0.2  # Hz
HIGHEST = 0.45  # of the frame rate
GRID = 16
PRECISION = 0.005  # relative, on the cutoff
THIRD = np.array([1.0, -3.0, 3.0, -1.0])
MAD = 0.6744897501960817  # the median of |N(0, 1)|
FLOOR = 1e-6  # m: the noise level below which the markers are taken as exact (1 µm)


@dataclass(frozen=True)
class FrameEstimates:
    """Each frame's own estimate of the coordinates, z = A⁻¹ b (frames × n; NaN where A is
    singular or zero), and the variances of its parts (A⁻¹)_kk (inf there)."""

    z: np.ndarray
    variance: np.ndarray

    @classmethod
    def of(cls, A: np.ndarray, b: np.ndarray) -> FrameEstimates:
        n_frames, n = b.shape
        z = np.full((n_frames, n), np.nan)
        variance = np.full((n_frames, n), np.inf)
        full = np.linalg.matrix_rank(A) == n if n_frames else np.zeros(0, bool)
        if full.any():
            inverse = np.linalg.inv(A[full])
            z[full] = np.einsum("fij,fj->fi", inverse, b[full])
            variance[full] = np.diagonal(inverse, axis1=1, axis2=2)
        return cls(z, variance)


def marker_noise(residuals: np.ndarray, leverage: np.ndarray) -> float:
    """σ (m) from the residuals of every frame's own fit (frames × rows; NaN where a marker
    is missing or the frame not used) and the rows' leverages (the same shape)."""
    d3 = sum(c * residuals[j:len(residuals) - 3 + j] for j, c in enumerate(THIRD))
    weight = sum(c * c * (1.0 - leverage[j:len(leverage) - 3 + j]) for j, c in enumerate(THIRD))
    ok = np.isfinite(d3) & np.isfinite(weight) & (weight > 0)
    if not ok.any():
        return float("nan")
    scaled = np.abs(d3[ok]) / np.sqrt(weight[ok])
    return max(float(np.median(scaled)) / MAD, FLOOR)


def cutoff(time: np.ndarray, z: np.ndarray, variance: np.ndarray,
           likelihood: Callable, order: int = ORDER) -> float:
    """The maximum-likelihood equivalent cutoff (Hz) of one coordinate's frame estimates
    (``likelihood``: filter.log_likelihood or its compiled twin)."""
    dt = float(time[1] - time[0])
    seen = np.isfinite(variance) & np.isfinite(z)
    r = float(np.median(variance[seen]))
    var = np.where(seen, variance, np.inf)
    values = np.where(seen, z, 0.0)

    def log_l(log_fc: float) -> float:
        omega = 2.0 * np.pi * np.exp(log_fc)
        F = transition(order, dt, omega)
        Q = density(np.exp(log_fc), r, dt, order) * noise_shape(order, dt, omega)
        mean0, cov0 = initial_state(time, values, var, order, omega)
        value = likelihood(values, var, F, Q, mean0, cov0, order)
        return value if np.isfinite(value) else -np.inf

    low, high = np.log(LOWEST), np.log(HIGHEST / dt)
    grid = np.linspace(low, high, GRID)
    scores = np.array([log_l(g) for g in grid])
    k = int(np.argmax(scores))
    a, b = grid[max(k - 1, 0)], grid[min(k + 1, GRID - 1)]
    golden = (np.sqrt(5.0) - 1.0) / 2.0
    c, d = b - golden * (b - a), a + golden * (b - a)
    fc, fd = log_l(c), log_l(d)
    while b - a > PRECISION:
        if fc >= fd:
            b, d, fd = d, c, fc
            c = b - golden * (b - a)
            fc = log_l(c)
        else:
            a, c, fc = c, d, fd
            d = a + golden * (b - a)
            fd = log_l(d)
    return float(np.exp((a + b) / 2.0))

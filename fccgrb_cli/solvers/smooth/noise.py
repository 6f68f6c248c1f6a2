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
* Each coordinate's strength: its frames' own estimates z_k = (A⁻¹ b)_k carry the markers'
  noise, variance (A⁻¹)_kk σ², and possibly noise the residuals cannot see — a marker cluster
  that moves as a whole on the skin, or noise correlated between markers, moves the estimate
  without leaving a residual — modelled as white noise of variance τ_k² on the coordinate.
  The likelihood of z_k under the prior of order p whose equivalent cutoff is f_c
  (``prior.density``) with noise (A⁻¹)_kk σ² + τ_k², by the Kalman filter's prediction
  errors, is maximized over f_c (between ``LOWEST`` Hz and 0.45 × the frame rate) and τ_k
  (coordinate ascent, ``strength``). On the five-bar with white marker noise τ comes out ~0;
  on the Qualisys walking trial the estimates' own noise is 3–4 times the markers' (τ² 7–20
  times (A⁻¹)_kk σ²) and the cutoffs 13–28 Hz. The coordinates are taken one at a time
  (their frames' estimates are correlated, which the smoother itself then takes into account):
  a coupled likelihood would cost a coupled filter per trial point.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from fccgrb_cli.solvers.smooth.prior import ORDER, density, noise_shape, transition
from fccgrb_cli.solvers.smooth.start import initial_state

LOWEST = 0.2  # Hz
HIGHEST = 0.45  # of the frame rate
COARSE = 10
PRECISION = 0.01  # relative, on the cutoff
ESTIMATE_FRAMES = 2000
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


@dataclass(frozen=True)
class Strength:
    """One coordinate's smoothing strength: the equivalent cutoff (Hz) of its prior, the
    variance of the noise its frames' estimates carry beyond the markers' white noise (its
    unit², 0 where there is none), and the median variance of its frames' estimates from the
    markers' noise, at which the cutoff holds (the prior's spectral density is
    ``prior.density(cutoff, variance + extra)``, fixed for the trial)."""

    cutoff: float
    extra: float
    variance: float

    @property
    def total_variance(self) -> float:
        """The variance the cutoff holds at: the markers' part and the coordinate's own."""
        return self.variance + self.extra


class _Likelihood:
    """log L(f_c, τ²) of one coordinate's frame estimates (see the module's docstring)."""

    def __init__(self, time: np.ndarray, z: np.ndarray, variance: np.ndarray,
                 likelihood: Callable, order: int) -> None:
        seen = np.isfinite(variance) & np.isfinite(z)
        window = _window(seen)
        self.time, self.order, self.likelihood = time[window], order, likelihood
        self.dt = float(time[1] - time[0])
        self.z = np.where(seen, z, 0.0)[window]
        self.variance = np.where(seen, variance, np.inf)[window]
        self.r = float(np.median(variance[seen]))

    def __call__(self, log_fc: float, extra: float) -> float:
        fc = float(np.exp(log_fc))
        omega = 2.0 * np.pi * fc
        var = self.variance + extra
        F = transition(self.order, self.dt, omega)
        Q = density(fc, self.r + extra, self.dt, self.order) * noise_shape(self.order,
                                                                          self.dt, omega)
        mean0, cov0 = initial_state(self.time, self.z, var, self.order, omega)
        value = self.likelihood(self.z, var, F, Q, mean0, cov0, self.order)
        return value if np.isfinite(value) else -np.inf


def _window(seen: np.ndarray) -> slice:
    """The frames the estimate reads: every one, or the ``ESTIMATE_FRAMES`` around the middle
    of the measured ones in a longer trial (the strength is the trial's, and a filter pass per
    trial point over every frame of a long trial would cost more than the smoothing)."""
    idx = np.flatnonzero(seen)
    if len(seen) <= ESTIMATE_FRAMES:
        return slice(0, len(seen))
    middle = int(idx[len(idx) // 2])
    start = min(max(0, middle - ESTIMATE_FRAMES // 2), len(seen) - ESTIMATE_FRAMES)
    return slice(start, start + ESTIMATE_FRAMES)


def _golden(f: Callable[[float], float], a: float, b: float, tol: float) -> tuple[float, float]:
    """The maximum of a unimodal f on [a, b] (golden section): (x, f(x))."""
    ratio = (np.sqrt(5.0) - 1.0) / 2.0
    c, d = b - ratio * (b - a), a + ratio * (b - a)
    fc, fd = f(c), f(d)
    while b - a > tol:
        if fc >= fd:
            b, d, fd = d, c, fc
            c = b - ratio * (b - a)
            fc = f(c)
        else:
            a, c, fc = c, d, fd
            d = a + ratio * (b - a)
            fd = f(d)
    x = (a + b) / 2.0
    return x, f(x)


def strength(time: np.ndarray, z: np.ndarray, variance: np.ndarray, likelihood: Callable,
             cutoff_hz: float | None = None, order: int = ORDER) -> Strength:
    """The maximum-likelihood strength of one coordinate's frame estimates (``likelihood``:
    filter.log_likelihood or its compiled twin); ``cutoff_hz``: the cutoff given, only the
    extra noise estimated. A coarse grid over both (the cutoff log-spaced between ``LOWEST``
    Hz and 0.45 × the frame rate; the extra noise none, or e^−3 … e^5 times the frames' median
    variance), then coordinate ascent from its best point by golden sections: the cutoff, the
    noise's log-ratio, the cutoff again. (Ascent from the best cutoff without extra noise alone
    stops on a ridge: on the Qualisys trial at 23–47 Hz, where the joint optimum lies at
    13–28 Hz with noise 7–20 times the markers'.) The extra noise is kept where it raises the
    log-likelihood over the best without it by more than ½ log(frames) (Schwarz's criterion
    for one more parameter): on the five-bar with white noise alone, plain maximum likelihood
    found some in 29 % of the coordinates, which kept their errors from cancelling in the
    moments' predicted spread (27 % too wide)."""
    log_l = _Likelihood(time, z, variance, likelihood, order)
    low, high = np.log(LOWEST), np.log(HIGHEST / log_l.dt)
    fixed = cutoff_hz is not None
    cutoffs = np.array([np.log(cutoff_hz)]) if cutoff_hz is not None else \
        np.linspace(low, high, COARSE)
    ratios = np.arange(-3.0, 6.0, 2.0)  # log(τ²/r)
    step = (high - low) / (COARSE - 1)

    def extra_of(x: float | None) -> float:
        return 0.0 if x is None else log_l.r * float(np.exp(x))

    def refine_cutoff(f: float, x: float | None) -> tuple[float, float]:
        if fixed:
            return f, log_l(f, extra_of(x))
        return _golden(lambda v: log_l(v, extra_of(x)), max(low, f - step),
                       min(high, f + step), PRECISION)

    plain = [log_l(f, 0.0) for f in cutoffs]
    f0, l0 = refine_cutoff(cutoffs[int(np.argmax(plain))], None)
    scores = np.array([[log_l(f, extra_of(x)) for x in ratios] for f in cutoffs])
    i, j = np.unravel_index(int(np.argmax(scores)), scores.shape)
    f1, _ = refine_cutoff(cutoffs[i], ratios[j])
    x1, _ = _golden(lambda v: log_l(f1, extra_of(v)), ratios[j] - 2.0, ratios[j] + 2.0, 0.05)
    f1, l1 = refine_cutoff(f1, x1)
    if l1 - l0 > 0.5 * np.log(np.isfinite(log_l.variance).sum()):
        return Strength(float(np.exp(f1)), extra_of(x1), log_l.r)
    return Strength(float(np.exp(f0)), 0.0, log_l.r)

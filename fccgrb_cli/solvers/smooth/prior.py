"""The motion prior of the whole-trial smoother: each driver coordinate d(t) (a joint angle, a
distance, a floating base's translation or rotation vector) is an integrated Wiener process of
order p — its p-th derivative is white noise of spectral density q — observed once a frame.

The state of a coordinate at a frame holds d and its first p − 1 derivatives, each divided by
ω^j (ω a frequency of the coordinate's own motion, ``scale``): s_j = d^(j) / ω^j. In these units
the state's parts are of one size (a motion whose content lies below ω has |d^(j)| ≲ ω^j |d|),
which keeps the filter's covariances well conditioned at any frame rate.

Over one frame interval dt the state moves by s⁺ = F s + w, w ~ N(0, q C):

    F_ij = (ω dt)^(j−i) / (j − i)!                     (j ≥ i; a Taylor step)
    C_ij = dt^(2p−1−i−j) / ((2p−1−i−j) (p−1−i)! (p−1−j)! ω^(i+j))

(the integral over the interval of e^(A τ) L Lᵀ e^(Aᵀ τ), A the shift and L the last unit vector,
in scaled units). With noise of variance r per sample on d, the steady smoother is the zero-lag
filter |H(f)| = 1 / (1 + (f/f_c)^(2p)) (the smoothing spline of degree 2p − 1, Wecker & Ansley
1983), whose equivalent cutoff f_c relates the spectral density to the noise:
q = r dt (2π f_c)^(2p). The smoother reports f_c, and takes it as the override.
"""

from __future__ import annotations

from math import factorial

import numpy as np

ORDER = 5
"""p: the order of the prior (state d, ḋ, …, d⁗). Chosen by the benchmark (benchmarks/
smoothing.py --orders; here the median over 8 noise seeds): on the five-bar at 200 Hz with 1 mm
marker noise the joint moments' error over every frame falls from 0.20 (p = 3, a white-jerk
prior: the quintic smoothing spline) to 0.059 (p = 4) and 0.039 N·m RMS (p = 5); p = 6 is worse
(0.055: its larger errors at the trial's ends) and each order costs more state."""

DERIVATIVES = 3
"""The outputs per coordinate: d, ḋ and d̈ (what the classical model's drivers take)."""


def transition(order: int, dt: float, scale: float) -> np.ndarray:
    """F (order × order) of one coordinate with scaling frequency ``scale`` (rad/s)."""
    F = np.zeros((order, order))
    for i in range(order):
        for j in range(i, order):
            F[i, j] = (scale * dt) ** (j - i) / factorial(j - i)
    return F


def noise_shape(order: int, dt: float, scale: float) -> np.ndarray:
    """C (order × order): the covariance of one interval's process noise per unit spectral
    density, in scaled units."""
    C = np.empty((order, order))
    for i in range(order):
        for j in range(order):
            e = 2 * order - 1 - i - j
            C[i, j] = dt**e / (e * factorial(order - 1 - i) * factorial(order - 1 - j)
                              * scale ** (i + j))
    return C


def density(cutoff_hz: float | np.ndarray, noise_variance: float | np.ndarray, dt: float,
            order: int = ORDER) -> float | np.ndarray:
    """q of the prior whose steady smoother has equivalent cutoff ``cutoff_hz`` at sample noise
    ``noise_variance``: q = r dt (2π f_c)^(2p)."""
    return noise_variance * dt * (2.0 * np.pi * np.asarray(cutoff_hz)) ** (2 * order)


def response(frequency_hz: np.ndarray, cutoff_hz: float, order: int = ORDER) -> np.ndarray:
    """The steady smoother's gain 1 / (1 + (f/f_c)^(2p)) (zero phase)."""
    return 1.0 / (1.0 + (np.asarray(frequency_hz) / cutoff_hz) ** (2 * order))

"""The first frame's prior of each coordinate's state: nearly diffuse, from the data.

A Kalman filter needs a proper prior for the state at the first frame, and a "vague" one of
arbitrary size costs the covariance passes their accuracy: the state's later precision is 10⁸–10¹³
times finer than a variance of the coordinate's range, and the noise-part recursions cancel terms
of that size (they lost every digit at the trial's ends in the tests). So the prior is taken from
the data themselves: a weighted least-squares polynomial of degree p − 1 through the first
``WINDOW`` measured frames gives the state at frame 0 and its covariance, and that covariance
inflated ``INFLATION`` times is the prior. It is then 10⁴ times vaguer than what those frames
say, so that it moves the smoothed answer by ~10⁻⁴ of its own uncertainty, while the passes keep
~10 digits.
"""

from __future__ import annotations

from math import factorial

import numpy as np

WINDOW = 4  # times the order: measured frames in the initial fit
INFLATION = 1e4


def initial_state(time: np.ndarray, z: np.ndarray, variance: np.ndarray, order: int,
                  scale: float) -> tuple[np.ndarray, np.ndarray]:
    """Mean (order) and covariance (order × order; scaled units s_j = d^(j)/ω^j at
    ``time[0]``) of one coordinate's prior, from its measurements z with ``variance`` (inf
    where none). Needs at least ``order`` measured frames (the caller checks)."""
    seen = np.flatnonzero(np.isfinite(variance) & np.isfinite(z))[: WINDOW * order]
    tau = scale * (time[seen] - time[0])
    X = np.column_stack([tau**j / factorial(j) for j in range(order)])
    w = 1.0 / variance[seen]
    normal = X.T @ (X * w[:, None])
    cov = np.linalg.inv(normal)
    mean = cov @ (X.T @ (w * z[seen]))
    return mean, INFLATION * cov

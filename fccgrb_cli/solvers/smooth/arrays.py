"""The named tuples of arrays the smoother's compiled kernels take (numba types a named tuple
like its fields), apart from the kernels so that Python code builds them without loading
numba."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class ChainArrays(NamedTuple):
    """The prior (filter.Chains): F and Q (n × p × p), the first frame's mean (np) and
    covariance blocks (n × p × p)."""

    F: np.ndarray
    Q: np.ndarray
    mean0: np.ndarray
    cov0: np.ndarray


class SmoothedDrivers(NamedTuple):
    """Every frame's guess (frames × nq), driven angles (frames × angles), floating bases'
    features (frames × slots × 3) and those features' rates for a unit rate of each base
    coordinate (frames × base coordinates × slots × 3)."""

    guesses: np.ndarray
    theta: np.ndarray
    ref: np.ndarray
    base_units: np.ndarray


class Points(NamedTuple):
    """The tracked points: each one's body's first column in q and its local a, b, c."""

    offsets: np.ndarray
    local: np.ndarray


class Linearization(NamedTuple):
    """What linearize_frames writes: q, S = ∂q/∂d, the points, H, and which frames
    converged."""

    q: np.ndarray
    S: np.ndarray
    points: np.ndarray
    H: np.ndarray
    converged: np.ndarray

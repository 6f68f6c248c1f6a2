"""The named tuples of arrays (and scalars) the compiled kernels take: numba types a named
tuple like its fields, so related arguments travel as one, at no cost in the loops. Here, apart
from the kernels, so that Python code builds them without loading numba."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class Limits(NamedTuple):
    """One frame's iteration: the tolerance on the step (m and rad) and the iteration cap."""

    tol: float
    max_iter: int


class WarmStart(NamedTuple):
    """What carries from frame to frame of a loop over frames: Python's ``guess`` (taken at the
    call's first frame when ``use_guess``), up to len(history) solutions (newest last),
    ``state`` ([number in history, last frame's iterations]), and whether a frame starts from
    their polynomial extrapolation (else from the last solution)."""

    guess: np.ndarray
    use_guess: bool
    history: np.ndarray
    state: np.ndarray
    extrapolate: bool


class FrameOutputs(NamedTuple):
    """Per frame, what a loop over frames writes: q, iterations, ‖Φ‖ over the rows kept,
    max |Φ_top|, converged, and left unsolved (markers that cannot determine the model)."""

    q: np.ndarray
    iterations: np.ndarray
    phi_norm: np.ndarray
    phi_top: np.ndarray
    converged: np.ndarray
    unsolved: np.ndarray


class Bounds(NamedTuple):
    """The interior point's lower ≤ q ≤ upper (``interior`` False: the plain SQP, bounds
    unused) and its bound multipliers z_l, z_u with their steps (4 × nq)."""

    lower: np.ndarray
    upper: np.ndarray
    interior: bool
    z: np.ndarray


class NrmTrial(NamedTuple):
    """A trial as NRM's loop reads it: targets (frames × targets × 3, m), the gaps
    (frames × targets), each frame's set of gaps by number, what the rank test said of each
    set (UNKNOWN until asked) and the rows' weights W."""

    targets: np.ndarray
    missing: np.ndarray
    pattern_of: np.ndarray
    solvable: np.ndarray
    base_w: np.ndarray


class Drivers(NamedTuple):
    """The driven values of a classical model per frame: θ*, θ̇*, θ̈* and a floating base's
    features with their rates (frames × slots × 3)."""

    theta: np.ndarray
    theta_d: np.ndarray
    theta_dd: np.ndarray
    ref: np.ndarray
    ref_d: np.ndarray
    ref_dd: np.ndarray


class DrivenMotion(NamedTuple):
    """What driven_frames writes per frame: q, q̇, q̈, Φ at the solution, iterations and
    converged."""

    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    phi: np.ndarray
    iterations: np.ndarray
    converged: np.ndarray


class BaseRates(NamedTuple):
    """A floating base's coordinate columns and their differenced rates (frames × columns)."""

    columns: np.ndarray
    d: np.ndarray
    dd: np.ndarray

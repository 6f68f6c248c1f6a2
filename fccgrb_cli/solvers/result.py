"""One result type for every kinematic method (as scipy.optimize gives one OptimizeResult)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class KinematicResult:
    """Per-frame coordinates and statistics of a kinematic solution.

    q, qd, qdd: (frames × nq) system coordinates and their rates (SI); theta, theta_d, theta_dd:
    (frames × n_angles) the angular coordinates (solved MC coordinates, or the AR drivers);
    iterations, time_s, phi_norm (‖Φ‖), phi_top_max (max |topological Φ|), converged: per frame;
    wall_s: the whole solve's wall-clock time when frames ran in parallel (else NaN);
    status: the optimizer's own message for every frame (optimization methods only);
    flags: per frame, why it is not to be trusted (a bit mask of solvers/quality.py; None until
    the run is assessed, 0 for a trusted frame).
    """

    method: str
    tol: float
    time: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    theta: np.ndarray
    theta_d: np.ndarray
    theta_dd: np.ndarray
    angle_names: tuple[str, ...]
    iterations: np.ndarray
    time_s: np.ndarray
    phi_norm: np.ndarray
    phi_top_max: np.ndarray
    converged: np.ndarray
    messages: tuple[str, ...] = field(default=())
    wall_s: float = float("nan")
    status: tuple[str, ...] = field(default=())
    flags: np.ndarray | None = None

    @property
    def n_frames(self) -> int:
        return len(self.time)

    @property
    def failed_frames(self) -> np.ndarray:
        """Frames the solver did not converge on (or left unsolved)."""
        return np.flatnonzero(~self.converged)

    @property
    def trusted(self) -> np.ndarray:
        """Per frame: converged and not flagged by the quality checks."""
        return self.converged if self.flags is None else self.converged & (self.flags == 0)


@dataclass(frozen=True)
class FrameStats:
    """What a solver records of each frame (arrays over frames): Newton or optimizer iterations,
    wall-clock seconds, ‖Φ‖ over the active equations, max |topological Φ|, the solver's
    verdict, and (optimizers) its own message; and of the whole solve: its messages, and its
    wall-clock time where frames ran in parallel (else NaN)."""

    iterations: np.ndarray
    seconds: np.ndarray
    phi_norm: np.ndarray
    phi_top: np.ndarray
    converged: np.ndarray
    status: tuple[str, ...] = field(default=())
    messages: tuple[str, ...] | list[str] = field(default=())
    wall_s: float = float("nan")

"""Synthesize a trial: the prescribed motion through the AD analysis, tracked points out."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from fccgrb_cli.errors import InputError
from fccgrb_cli.model import Model
from fccgrb_cli.solvers import KinematicResult, solve_ad
from fccgrb_cli.system import System, compile_system


@dataclass(frozen=True)
class Synthesis:
    system: System
    result: KinematicResult
    markers: np.ndarray
    labels: tuple[str, ...]
    rate: float


def prescribed(model: Model, time: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """θ*, θ̇*, θ̈* (frames × angles) from every angle's prescribed motion."""
    missing = [a.name for a in model.angles if a.motion is None]
    if missing:
        raise InputError(f"{model.source}: angles: expected a motion for every angle to "
                         f"synthesize a trial, missing for {', '.join(missing)}")
    values = [a.motion.evaluate(time) for a in model.angles]
    return tuple(np.column_stack([v[k] for v in values]) for k in range(3))


def synthesize(model: Model, duration: float = 3.0, rate: float = 100.0, tol: float = 1e-10,
               progress: Callable[[int, int], None] | None = None) -> Synthesis:
    """Run the prescribed motion for ``duration`` s at ``rate`` Hz and read the tracked points.
    A floating base is held at its stated pose."""
    n_frames = round(duration * rate)
    if n_frames < 1:
        raise InputError(f"duration {duration} s at {rate} Hz gives no frame")
    time = np.arange(n_frames) / rate
    theta, theta_d, theta_dd = prescribed(model, time)
    system = compile_system(model, angles="driver")
    pose = system.layout.pose_q(model)
    held = np.broadcast_to(system.base_reference(pose), (n_frames, system.n_base_slots, 3))
    still = np.zeros_like(held)
    result = solve_ad(system, time, theta, theta_d, theta_dd, pose, tol=tol,
                      base=(np.array(held), still, still), progress=progress)
    if len(result.failed_frames):
        f = int(result.failed_frames[0])
        raise InputError(f"{model.source}: frame {f} (t = {time[f]:.3f} s): the kinematic "
                         f"analysis did not converge ({len(result.failed_frames)} frames failed); "
                         "the prescribed angles may pass through a singular configuration")
    which = [(tp.body, tp.point) for tp in model.tracked_points]
    markers = np.array([system.point_positions(q, which) for q in result.q])
    return Synthesis(system, result, markers.reshape(n_frames, len(which), 3),
                     model.marker_labels, rate)

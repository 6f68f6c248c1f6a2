"""Synthesize a trial: the prescribed motion through the AD analysis, tracked points out.

Every driven coordinate (angle or distance) follows its prescribed motion; a floating base
follows its own (``bodies.NAME.motion``: translation of its origin and rotations about the ground
axes), its drivers r*, u*, v*, w* given with their exact first and second time derivatives
(:class:`fccgrb_cli.model.BaseMotion`); without one it is held at its stated pose.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from fccgrb_cli.core.errors import InputError
from fccgrb_cli.core.stretches import runs
from fccgrb_cli.model import BaseMotion, Model
from fccgrb_cli.solvers import KinematicResult, solve_ad
from fccgrb_cli.solvers.ad.solve import stacked_drives
from fccgrb_cli.solvers.conditioning import conditioning
from fccgrb_cli.system import System, compile_system
from fccgrb_cli.system.constraints import joint_neighbours, reachable

FRAMES_MAX = 1_000_000  # ~2.5 h at 100 Hz; the five-bar's arrays then take ~3 GB


def frame_count(duration: float, rate: float, what: str = "duration × rate") -> int:
    """The frames of a synthesized trial, round(duration × rate): at least one, at most
    ``FRAMES_MAX`` (a duration of 1e7 s would ask for every array of a billion frames)."""
    product = duration * rate
    frames = round(product) if math.isfinite(product) else -1
    if not 1 <= frames <= FRAMES_MAX:
        raise InputError(f"{what}: expected 1 to {FRAMES_MAX:,} frames, got {duration:g} s × "
                         f"{rate:g} Hz = {product:g} frames")
    return frames


@dataclass(frozen=True)
class Synthesis:
    system: System
    result: KinematicResult
    markers: np.ndarray
    labels: tuple[str, ...]
    rate: float
    warnings: tuple[str, ...] = ()


def prescribed(model: Model, time: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """θ*, θ̇*, θ̈* (frames × coordinates) from every angle's and distance's prescribed motion."""
    missing = [a for a in model.angles if a.motion is None]
    if missing:
        distances = any(a.kind == "distance" for a in model.angles)
        section = "distances" if missing[0].kind == "distance" else "angles"
        raise InputError(f"{model.source}: {section}: expected a motion for every angle"
                         f"{' and distance' if distances else ''} to synthesize a trial, "
                         f"missing for {', '.join(a.name for a in missing)}")
    values = [a.motion.evaluate(time) for a in model.angles if a.motion is not None]  # all
    theta, rate, acceleration = (np.column_stack([v[k] for v in values]) for k in range(3))
    return theta, rate, acceleration


def base_trajectory(model: Model, time: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The floating bases' driven features r, u, v (, w) and their exact first and second
    derivatives (frames × slots × 3 each), in the order of ``System.base_reference``."""
    parts: list[list[np.ndarray]] = [[], [], []]
    for name in model.floating_bases:
        body = model.body(name)
        frames = (body.motion or BaseMotion()).frames(time, body.pose.as_array())
        for k in range(3):
            parts[k].append(frames[k][:, : 4 if body.form == "full" else 3])
    n = len(time)
    x, xd, xdd = (np.concatenate(p, axis=1) if p else np.zeros((n, 0, 3)) for p in parts)
    return x, xd, xdd


def start_pose(system: System) -> np.ndarray:
    """The model's pose with each floating base's group of bodies moved rigidly with the base
    to where its motion puts it at t = 0 (the joint coordinates stay as stated)."""
    model, layout = system.model, system.layout
    q = layout.pose_q(model)
    neighbours = joint_neighbours(model)
    for name in model.floating_bases:
        base = model.body(name)
        if base.motion is None:
            continue
        frame = base.motion.frames(np.zeros(1), base.pose.as_array())[0][0]
        R = base.motion.rotation_matrix(np.zeros(1))[0][0]
        origin = np.array(base.pose.r)
        for member in reachable(neighbours, name, set()):
            sl = layout.q_slice(member)
            block = q[sl].copy()
            block[:3] = frame[0] + R @ (block[:3] - origin)
            block[3:] = (block[3:].reshape(-1, 3) @ R.T).ravel()
            q[sl] = block
    return q


def synthesize(model: Model, duration: float = 3.0, rate: float = 100.0, tol: float = 1e-10,
               progress: Callable[[int, int], None] | None = None) -> Synthesis:
    """Run the prescribed motion for ``duration`` s at ``rate`` Hz and read the tracked points.
    A floating base follows its prescribed motion (held at its stated pose without one)."""
    n_frames = frame_count(duration, rate)
    time = np.arange(n_frames) / rate
    theta, theta_d, theta_dd = prescribed(model, time)
    system = compile_system(model, angles="driver")
    drives = stacked_drives(system, theta, theta_d, theta_dd, base_trajectory(model, time))
    result = solve_ad(system, time, drives, start_pose(system), tol=tol, progress=progress)
    near = _singular_positions(model, result)
    if near:  # again, following the branch through the singular positions
        result = solve_ad(system, time, drives, start_pose(system), tol=tol, continuation=True)
        near = _singular_positions(model, result)
    if len(result.failed_frames):
        f = int(result.failed_frames[0])
        raise InputError(f"{model.source}: frame {f} (t = {time[f]:.3f} s): the kinematic "
                         f"analysis did not converge ({len(result.failed_frames)} frames failed); "
                         "the prescribed angles may pass through a singular configuration")
    which = [(tp.body, tp.point) for tp in model.tracked_points]
    markers = np.array([system.point_positions(q, which) for q in result.q])
    return Synthesis(system, result, markers.reshape(n_frames, len(which), 3),
                     model.marker_labels, rate, tuple(near))


def _singular_positions(model: Model, result: KinematicResult) -> list[str]:
    """A warning for each stretch of frames the motion spends near a singular position of the
    driven model (solvers/conditioning.py), where the angles alone leave two assembly branches
    (a parallelogram's change point): the analysis followed the one it was on by continuation
    (the solutions' own curve through the position, not Φ_q q̇ = ν, which has no unique
    solution there)."""
    condition = conditioning(model, result.q)
    out = []
    for a, b in runs(condition.singular):
        f = a + int(np.argmin(condition.ratio[a:b]))
        out.append(f"{model.source}: frame indices {a}:{b} (t = {result.time[a]:.3f}–"
                   f"{result.time[b - 1]:.3f} s) pass near a singular position of the driven "
                   f"model (a change point: the angles alone leave two assembly branches; "
                   f"nearest at frame index {f}, angles "
                   f"{', '.join(f'{np.degrees(v):.1f}' for v in result.theta[f])} deg); the "
                   "motion follows the branch it was on by continuation, and `fccgrb solve` "
                   "flags these frames")
    return out

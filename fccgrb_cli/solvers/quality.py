"""Frames not to be trusted, whatever the solver said: no silent wrong answer.

A solver's own verdict (converged or not) says nothing of a frame that landed on the other
assembly branch, of a method whose per-frame optimum is not unique (goal attainment's minimax on
noisy markers) and so jumps from frame to frame, or of a topology left broken. Every run is
checked after its solve, and each frame gets a bit mask:

* ``UNCONVERGED``: the solver did not converge (or the frame was left unsolved);
* ``TOPOLOGY``: a method that keeps the model rigid (AD, CNO, MO) left max |Φ_top| above
  ``TOPOLOGY_PROMISE`` (NRM-LS/WLS relax the topology by design and are not judged on it);
* ``JUMP``: the model points' motion is rougher than the markers they follow allow. Joint
  moments rest on central-difference accelerations; jitter of δ in a frame's solution changes
  them by ~4δ/dt² there, while a smooth motion's second differences change slowly. So each
  frame's fourth difference of the model points (p[f−2] − 4p[f−1] + 6p[f] − 4p[f+1] + p[f+2],
  the change of the second differences, ≈ (ω dt)² times them for a smooth motion) is compared
  with the markers' largest over frames f−2…f+2: a fit to the markers cannot be rougher than the
  markers beyond a factor ``JUMP_RATIO`` (10). On the five-bar, NRM-WLS and CNO-SQP reach 4.1 at
  30 mm (0.8 without noise), goal attainment 18–12,000 (its per-frame optimum is not unique on
  noisy markers, and consecutive frames land anywhere on it); on the Qualisys gait trial
  NRM-WLS reaches 0.66 (its markers' own noise is rougher than any fit). The classical AD
  analysis is not judged on it: its drivers come from a pre-analysis, not from a fit of the
  model to the markers, and carry a segment's error down the chain with the lever arm (8× on the
  five-bar with P4 and P9 at 30 mm: inaccurate, but the pre-analysis's own). A frame on the
  other assembly branch shows as a jump where it leaves and where it rejoins the branch; the
  frames between are found by re-solving from a trusted neighbour (the parallel modes' repair,
  ``solvers/optimize/``). A frame whose neighbour jumps is flagged too: its central
  differences include the jump.

A trusted frame has mask 0. ``converged`` in the results file means trusted.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from fccgrb_cli.solvers.result import KinematicResult

UNCONVERGED, TOPOLOGY, JUMP = 1, 2, 4
BITS = {"unconverged": UNCONVERGED, "topology": TOPOLOGY, "jump": JUMP}
TOPOLOGY_PROMISE = 1e-6
JUMP_RATIO = 10.0
JUMP_FLOOR = 1e-5
EXACT_TOPOLOGY = ("ad", "cno", "mo")


def roughness(points: np.ndarray) -> np.ndarray:
    """max over points of the fourth difference ‖p[f−2] − 4p[f−1] + 6p[f] − 4p[f+1] + p[f+2]‖
    (frames × points × 3 → frames; the two frames at each end take the nearest value; NaN
    where no point is available)."""
    n = len(points)
    out = np.full(n, np.nan)
    if n < 5:
        return out
    d4 = np.linalg.norm(points[4:] - 4.0 * points[3:-1] + 6.0 * points[2:-2]
                        - 4.0 * points[1:-3] + points[:-4], axis=2)
    out[2:-2] = _nanmax(d4, axis=1)
    out[:2], out[-2:] = out[2], out[-3]
    return out


def _nanmax(a: np.ndarray, axis: int) -> np.ndarray:
    """np.nanmax without its warning: NaN where a slice holds no number."""
    known = np.isfinite(a)
    out = np.where(known, a, -np.inf).max(axis=axis)
    return np.where(known.any(axis=axis), out, np.nan)


def jump_ratio(points: np.ndarray, markers: np.ndarray) -> np.ndarray:
    """Per frame, the model points' roughness over the largest of the markers' in frames
    f−2…f+2 (plus ``JUMP_FLOOR`` m, the scale of the solver's and the markers' rounding); NaN
    where either is unknown."""
    data = roughness(markers)
    padded = np.concatenate([[np.nan] * 2, data, [np.nan] * 2])
    window = np.stack([padded[k:k + len(data)] for k in range(5)])
    return roughness(points) / (_nanmax(window, axis=0) + JUMP_FLOOR)


def flags_of(method: str, converged: np.ndarray, phi_top_max: np.ndarray, points: np.ndarray,
             markers: np.ndarray) -> np.ndarray:
    """The bit mask of every frame (see the module's docstring) of a run by ``method``, from
    the solver's verdict, max |Φ_top|, the model points and the input markers (frames × k × 3)
    they follow."""
    flags = np.where(converged, 0, UNCONVERGED).astype(np.uint8)
    if method.startswith(EXACT_TOPOLOGY):
        flags[~(phi_top_max <= TOPOLOGY_PROMISE) & converged] |= TOPOLOGY
    if method != "ad":
        jumps = jump_ratio(points, markers) > JUMP_RATIO
        near = jumps.copy()  # a neighbour's jump is inside this frame's central differences
        near[1:] |= jumps[:-1]
        near[:-1] |= jumps[1:]
        flags[near] |= JUMP
    return flags


def frame_flags(result: KinematicResult, points: np.ndarray,
                markers: np.ndarray) -> np.ndarray:
    """The bit mask of every frame of a solved run."""
    return flags_of(result.method, result.converged, result.phi_top_max, points, markers)


def describe(flags: np.ndarray, time: np.ndarray, method: str) -> list[str]:
    """One warning per kind of flag, naming how many frames and the first one."""
    out = []
    reasons = {
        TOPOLOGY: f"the topology is violated by more than {TOPOLOGY_PROMISE:g} m, which "
                  f"{method} promises to hold",
        JUMP: "the model moves more roughly than its markers (fourth differences more than "
              f"{JUMP_RATIO:g}× the markers'): a frame on another assembly branch, or a "
              "per-frame optimum that is not unique",
    }
    for bit, reason in reasons.items():
        hit = np.flatnonzero(flags & bit)
        if len(hit):
            f = int(hit[0])
            out.append(f"{len(hit)} frames flagged (first: frame index {f}, t = {time[f]:.3f} s):"
                       f" {reason}; they are not counted as converged, and velocities, "
                       "accelerations and joint moments there are not to be trusted")
    return out


def assessed(result: KinematicResult, points: np.ndarray,
             markers: np.ndarray) -> KinematicResult:
    """``result`` with its frames' flags and a warning for each kind found."""
    flags = frame_flags(result, points, markers)
    return replace(result, flags=flags,
                   messages=result.messages + tuple(describe(flags, result.time, result.method)))

"""Frames not to be trusted, whatever the solver said: no silent wrong answer.

A solver's own verdict (converged or not) says nothing of a frame that landed on the other
assembly branch, of a method whose per-frame optimum is not unique (goal attainment's minimax on
noisy markers) and so jumps from frame to frame, or of a topology left broken. Every run is
checked after its solve, and each frame gets a bit mask:

* ``UNCONVERGED``: the solver did not converge (or the frame was left unsolved);
* ``TOPOLOGY``: a method that keeps the model rigid (AD, CNO, MO) left max |Φ_top| above
  ``TOPOLOGY_PROMISE`` (NRM-LS/WLS relax the topology by design and are not judged on it);
* ``JUMP``: the model points move more abruptly than the markers they follow allow. The second
  difference of each frame's model points, p[f+1] − 2p[f] + p[f−1] (what the central-difference
  accelerations, and so the joint moments, are built on), is compared with the largest second
  difference of the input markers over frames f−1…f+1: a fit to the markers cannot need more
  acceleration than the markers have, beyond a factor ``JUMP_RATIO`` (a least-squares fit
  amplifies marker motion somewhat: NRM-WLS on the five-bar at 30 mm reaches 1.5, the Qualisys
  gait trial 1.06). The classical AD analysis is not judged on it: its drivers come from a
  pre-analysis, not from a fit of the model to the markers, and carry a segment's error down
  the chain with the lever arm (its end point moves up to 4× faster than the markers on the
  five-bar with P4 and P9 at 30 mm: inaccurate, but smooth). A frame on the other assembly branch shows as a jump where it leaves and
  where it rejoins the branch; the frames between are found by re-solving from a trusted
  neighbour (the optimizers' repair, ``solvers/optimize.py``). A frame whose neighbour jumps is
  flagged too: its central differences include the jump.

A trusted frame has mask 0. ``converged`` in the results file means trusted.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from fccgrb_cli.solvers.result import KinematicResult

UNCONVERGED, TOPOLOGY, JUMP = 1, 2, 4
BITS = {"unconverged": UNCONVERGED, "topology": TOPOLOGY, "jump": JUMP}
TOPOLOGY_PROMISE = 1e-6
JUMP_RATIO = 3.0
JUMP_FLOOR = 1e-5
EXACT_TOPOLOGY = ("ad", "cno", "mo")


def second_difference(points: np.ndarray) -> np.ndarray:
    """max over points of ‖p[f+1] − 2p[f] + p[f−1]‖ (frames × points × 3 → frames; the ends
    take their neighbour's value; NaN where no point is available)."""
    n = len(points)
    out = np.full(n, np.nan)
    if n < 3:
        return out
    d2 = np.linalg.norm(points[2:] - 2.0 * points[1:-1] + points[:-2], axis=2)
    seen = np.isfinite(d2).any(axis=1)
    inner = np.full(n - 2, np.nan)
    inner[seen] = np.nanmax(np.where(np.isfinite(d2[seen]), d2[seen], -np.inf), axis=1)
    out[1:-1] = inner
    out[0], out[-1] = out[1], out[-2]
    return out


def jump_ratio(points: np.ndarray, markers: np.ndarray) -> np.ndarray:
    """Per frame, the model points' second difference over the largest of the markers' in
    frames f−1…f+1 (plus ``JUMP_FLOOR`` m, the scale of the solver's and the markers' rounding);
    NaN where either is unknown."""
    model = second_difference(points)
    data = second_difference(markers)
    padded = np.concatenate([[np.nan], data, [np.nan]])
    window = np.stack([padded[:-2], padded[1:-1], padded[2:]])
    known = np.isfinite(window).any(axis=0)
    allowed = np.full(len(data), np.nan)
    allowed[known] = np.nanmax(np.where(np.isfinite(window[:, known]), window[:, known],
                                        -np.inf), axis=0)
    return model / (allowed + JUMP_FLOOR)


def frame_flags(result: KinematicResult, points: np.ndarray,
                markers: np.ndarray) -> np.ndarray:
    """The bit mask of every frame (see the module's docstring)."""
    flags = np.where(result.converged, 0, UNCONVERGED).astype(np.uint8)
    if result.method.startswith(EXACT_TOPOLOGY):
        broken = ~(result.phi_top_max <= TOPOLOGY_PROMISE)
        flags[broken & result.converged] |= TOPOLOGY
    if result.method != "ad":
        flags[jump_ratio(points, markers) > JUMP_RATIO] |= JUMP
    return flags


def describe(flags: np.ndarray, time: np.ndarray, method: str) -> list[str]:
    """One warning per kind of flag, naming how many frames and the first one."""
    out = []
    reasons = {
        TOPOLOGY: f"the topology is violated by more than {TOPOLOGY_PROMISE:g} m, which "
                  f"{method} promises to hold",
        JUMP: "the model moves more abruptly than its markers (second differences more than "
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

"""One count of turns for signed angles solved apart (docs/signed_angles.md).

A signed angle (``range: full``) is the same configuration every 2π, so a frame solved from a
fresh guess — a parallel worker's first frame, the first frame after a gap, a frame fitted on
its own by the angular-driver pre-analysis — comes back anywhere in (−π, π]. Each solved frame
is moved by whole turns to the one nearest to where the frames before it predict it:

* the first solved frame stays in (−π, π] (as the markers give it);
* the next frame, to the turn nearest the previous frame's angle (a frame-to-frame step below
  half a turn: ``numpy.unwrap``'s rule);
* the first frame after unsolved ones (a gap), to the turn nearest the last solved angle carried
  on across the gap at the rate of the two solved frames before it. Where that rate carries the
  angle half a turn or more across the gap, the count after it rests on the rate holding there,
  and the caller is told (``uncertain``).

Unsolved frames are not counted: their values (a stale guess, NaN) say nothing of the turn.
"""

from __future__ import annotations

import itertools

import numpy as np

TURN = 2.0 * np.pi


def counted(angles: np.ndarray, solved: np.ndarray
            ) -> tuple[np.ndarray, list[tuple[int, int]]]:
    """``angles`` (frames × k, rad) with each solved frame (``solved``: per frame) moved by
    whole turns onto one count, and the gaps [first unsolved, next solved) across which the
    count was carried by a rate over half a turn."""
    out = np.array(angles, dtype=float, copy=True)
    frames = np.flatnonzero(solved)
    uncertain: list[tuple[int, int]] = []
    if not len(frames) or not out.shape[1]:
        return out, uncertain
    first = frames[0]
    out[first] -= TURN * np.round(out[first] / TURN)
    for previous, f in itertools.pairwise(frames):
        expected = out[previous].copy()
        if f - previous > 1 and previous - 1 >= 0 and solved[previous - 1]:
            rate = out[previous] - out[previous - 1]  # per frame
            expected += rate * (f - previous)
            if np.abs(rate * (f - previous)).max() >= np.pi:
                uncertain.append((int(previous) + 1, int(f)))
        out[f] += TURN * np.round((expected - out[f]) / TURN)
    return out, uncertain


def gap_messages(uncertain: list[tuple[int, int]], time: np.ndarray) -> list[str]:
    """One warning per gap whose count of turns rests on the rate before it."""
    return [f"frame indices {a}:{b} (t = {time[a]:.3f}–{time[b]:.3f} s) unsolved: the signed "
            "angles turn half a turn or more across them at the rate before, so the whole turns "
            "after them are counted by carrying that rate on; check that no turn was gained or "
            "lost there" for a, b in uncertain]

"""Which foot stands on a force plate: each contact (a run of loaded frames) goes to the contact
body whose points come closest to the centre of pressure over that contact."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

MAX_DISTANCE = 0.25  # m: a contact farther than this from every contact body is left unassigned


@dataclass(frozen=True)
class Contact:
    """Frames [start, stop) of one contact, the body it went to (None: no body close enough)
    and the mean distance (m) from its centre of pressure to that body's nearest point."""

    start: int
    stop: int
    body: str | None
    distance: float


def contacts(loaded: np.ndarray) -> list[tuple[int, int]]:
    """The runs [start, stop) of True in a per-frame boolean array."""
    edges = np.diff(np.concatenate([[0], loaded.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(edges == 1).tolist(), np.flatnonzero(edges == -1).tolist(),
                    strict=True))


def assign(loaded: np.ndarray, cop: np.ndarray, bodies: dict[str, np.ndarray],
           max_distance: float = MAX_DISTANCE) -> list[Contact]:
    """Assign each contact of a plate (``loaded`` per frame, ``cop`` frames × 3) to the body
    (``bodies``: name → frames × points × 3) with the smallest mean distance from the centre of
    pressure to its nearest point, over the contact's frames where the body was solved (a
    body never solved during a contact is infinitely far)."""
    out = []
    for start, stop in contacts(loaded):
        c = cop[start:stop, None, :]
        distance = {name: _mean_nearest(p[start:stop], c) for name, p in bodies.items()}
        best = min(distance, key=distance.__getitem__)
        near = distance[best] <= max_distance
        out.append(Contact(start, stop, best if near else None, distance[best]))
    return out


def _mean_nearest(points: np.ndarray, cop: np.ndarray) -> float:
    """The mean over frames of the distance from the centre of pressure to the nearest of the
    points, over the frames where they are known (inf when none is)."""
    nearest = np.min(np.linalg.norm(points - cop, axis=2), axis=1)
    known = np.isfinite(nearest)
    return float(np.mean(nearest[known])) if known.any() else float("inf")

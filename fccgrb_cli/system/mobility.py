"""The joints' generic rank: the rank of the topological equations Φ_top at configurations near
a given one, where the mechanism is not at a singular position.

At a change point (a parallelogram four-bar with its links in line) Φ_top loses rank: the
joints leave one more degree of freedom there than anywhere else, and a count made at that
configuration is wrong. Near it, along the mechanism's own motion, the rank is the generic one.
So: step a little along a direction the joints allow at the configuration (Φ_top,q's null
space), bring the step back onto Φ_top = 0 by Gauss–Newton (least squares), and take the rank
there; the largest over a few seeded directions is the generic rank. Moving off the
constraints instead (any small change of q) would not do: redundant equations (a planar loop
written in 3D) are dependent only on Φ_top = 0, and off it they would count.
"""

from __future__ import annotations

import numpy as np

from fccgrb_cli.system.compiled import Drive, System
from fccgrb_cli.system.rank import rank_of

STEP = 1e-3      # the move along the null space, in q's units (m; unit vectors' components)
DIRECTIONS = 3   # seeded random directions tried
ITERATIONS = 30  # Gauss–Newton steps back onto Φ_top = 0
TOLERANCE = 1e-12


def _top_rows(system: System, q: np.ndarray, top: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    # the tracking rows (a floating base's model compiled with them) need targets: any will
    # do, only the topological rows are kept
    targets = np.zeros((system.n_targets, 3))
    phi, J = system.evaluate(q, Drive(theta=system.angles_at(q), ref=targets))
    return phi[top], J[top]


def generic_topology_rank(system: System, q: np.ndarray, seed: int = 0) -> int:
    """The rank of the topological rows of ``system`` near the assembled configuration ``q``.

    Parameters
    ----------
    system : System
        A compiled model (any angle mode: only its topological rows are used).
    q : ndarray, shape (nq,)
        An assembled configuration (Φ_top(q) = 0).
    seed : int
        Seed of the directions tried.

    Returns
    -------
    int
        The largest rank of Φ_top,q at the nearby assembled configurations reached; the rank
        at ``q`` itself where no step could be brought back onto the constraints.
    """
    top = system.masks()["topology"]
    _, J = _top_rows(system, q, top)
    rank = rank_of(J)
    vt = np.linalg.svd(J)[2]
    null = vt[rank:]
    if not len(null):
        return rank
    rng = np.random.default_rng(seed)
    best = rank
    for _ in range(DIRECTIONS):
        direction = rng.standard_normal(len(null)) @ null
        moved = q + STEP * direction / np.linalg.norm(direction)
        for _ in range(ITERATIONS):
            phi, Jm = _top_rows(system, moved, top)
            if np.linalg.norm(phi) < TOLERANCE:
                best = max(best, rank_of(Jm))
                break
            moved = moved - np.linalg.lstsq(Jm, phi, rcond=None)[0]
    return best

"""Feature vectors: every point and vector the constraints use, as F = A x + f0.

A body point with local (a, b, c) gives the rows C_P = [I3, a I3, b I3, c I3] (Eq. 2), a body
vector C_s = [0, α I3, β I3, γ I3] (Eq. 3); a ground point or vector is the constant f0.
"""

from __future__ import annotations

import numpy as np

from fccgrb_cli.model import GROUND, Model
from fccgrb_cli.system.layout import Layout


class FeatureTable:
    """Collects distinct features while constraints are compiled."""

    def __init__(self, model: Model, layout: Layout):
        self.model = model
        self.layout = layout
        self.rows: list[np.ndarray] = []
        self.offsets: list[np.ndarray] = []
        self.blocks: list[list[tuple[int, np.ndarray]]] = []
        self.index: dict[tuple, int] = {}

    def _add(self, key: tuple, blocks: list[tuple[int, np.ndarray]], offset: np.ndarray) -> int:
        """Register F = Σ_blocks [c0 I, c1 I, c2 I, c3 I] x_body + offset under ``key``."""
        if key not in self.index:
            rows = np.zeros((3, self.layout.nx))
            for start, coef in blocks:
                rows[:, start:start + 12] += np.hstack([c * np.eye(3) for c in coef])
            self.index[key] = len(self.rows)
            self.rows.append(rows)
            self.offsets.append(np.asarray(offset, dtype=float))
            self.blocks.append(blocks)
        return self.index[key]

    def _fixed(self, body: str, local: tuple[float, float, float] | np.ndarray, is_point: bool,
               key: tuple) -> int:
        if body == GROUND:
            return self._add(key, [], np.asarray(local, dtype=float))
        coef = np.array([1.0 if is_point else 0.0, *local])
        return self._add(key, [(self.layout.x_offset(body), coef)], np.zeros(3))

    def point(self, body: str, name: str) -> int:
        table = self.model.ground.points if body == GROUND else self.model.body(body).points
        return self._fixed(body, table[name].local, True, ("P", body, name))

    def vector(self, body: str, name: str) -> int:
        return self._fixed(body, self.local_of(body, name), False, ("s", body, name))

    def body_vector(self, body: str, local: np.ndarray) -> int:
        """An unnamed vector fixed in a body (ground: fixed in space) with the given components."""
        return self._fixed(body, local, False, ("s*", body, *np.round(local, 15)))

    def difference(self, a: int, b: int) -> int:
        """F_a − F_b, e.g. the vector between two joint points."""
        blocks = self.blocks[a] + [(start, -coef) for start, coef in self.blocks[b]]
        return self._add(("-", a, b), blocks, self.offsets[a] - self.offsets[b])

    def local_of(self, body: str, name: str) -> np.ndarray:
        """A named vector's components in its body's frame (global for the ground)."""
        table = self.model.ground.vectors if body == GROUND else self.model.body(body).vectors
        return np.array(table[name].local, dtype=float)

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """A (n_features, 3, nx) and f0 (n_features, 3)."""
        if not self.rows:
            return np.zeros((0, 3, self.layout.nx)), np.zeros((0, 3))
        return np.array(self.rows), np.array(self.offsets)


def perpendiculars(s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors a, b with (a, b, s) orthonormal: the a_j, b_j of a revolute joint."""
    s = s / np.linalg.norm(s)
    helper = np.eye(3)[int(np.argmin(np.abs(s)))]
    a = np.cross(s, helper)
    a /= np.linalg.norm(a)
    return a, np.cross(s, a)

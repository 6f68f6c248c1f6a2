"""External forces and moments on bodies, as generalized forces on x (docs/formulation.md §4).

A force f applied at a point with local coordinates (a, b, c) of body i gives C_Pᵀ f =
[f, a f, b f, c f]; a moment n gives ½ n × u, ½ n × v, ½ n × w on the u, v, w blocks. The point
may move over the body (a centre of pressure): its local coordinates are found each frame from
its global position.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np

from fccgrb_cli.signals.butterworth import lowpass


@dataclass(frozen=True)
class ExternalLoad:
    """Force (frames × 3, N) at ``point`` (frames × 3, global, m) and a free moment
    (frames × 3, N·m) acting on ``body``. ``name`` labels it in results."""

    name: str
    body: str
    force: np.ndarray
    point: np.ndarray
    moment: np.ndarray

    def generalized(self, x_body: np.ndarray, frame: int | np.ndarray) -> np.ndarray:
        """The 12 generalized forces on the body's fully-defined coordinates at one frame
        (x_body: 12 numbers, ``frame`` an index) or at many (x_body: frames × 12, ``frame``
        their indices; frames × 12 out)."""
        x = x_body.reshape(*x_body.shape[:-1], 4, 3)
        r, u, v, w = (x[..., k, :] for k in range(4))
        frame_axes = np.stack([u, v, w], axis=-1)
        local = np.linalg.solve(frame_axes, (self.point[frame] - r)[..., None])[..., 0]
        f = self.force[frame]
        n = self.moment[frame]
        return np.concatenate([f, local[..., 0:1] * f + 0.5 * np.cross(n, u),
                               local[..., 1:2] * f + 0.5 * np.cross(n, v),
                               local[..., 2:3] * f + 0.5 * np.cross(n, w)], axis=-1)

    def power(self, x_body: np.ndarray, xd_body: np.ndarray,
              frame: int | np.ndarray) -> np.ndarray:
        """Power of the load: f · (velocity of the body point under it) + n · ω (W; one
        number per frame, as ``generalized``)."""
        return np.einsum("...i,...i->...", self.generalized(x_body, frame), xd_body)

    def filtered(self, filter_: Callable[[np.ndarray], np.ndarray]) -> ExternalLoad:
        """The load with ``filter_`` (frames × 3 → frames × 3) applied to its force and free
        moment (:meth:`with_filtered`)."""
        if not self.loaded().size:
            return self
        return self.with_filtered(filter_(self.force), filter_(self.moment))

    def loaded(self) -> np.ndarray:
        """The frames with a force."""
        return np.flatnonzero(np.abs(self.force).any(axis=1))

    def with_filtered(self, force: np.ndarray, moment: np.ndarray) -> ExternalLoad:
        """The load with its force and free moment filtered (``force``, ``moment``). The point
        keeps its loaded values and holds the nearest loaded one where the filter spreads the
        force beyond contact."""
        loaded = self.loaded()
        nearest = loaded[np.abs(np.arange(len(self.force))[:, None] - loaded).argmin(axis=1)]
        return replace(self, force=force, moment=moment, point=self.point[nearest])


def lowpassed(loads: Sequence[ExternalLoad], rate: float, cutoff: float,
              order: int = 2) -> list[ExternalLoad]:
    """The loads with force and moment low-passed like the kinematics (the same cutoff keeps
    impact transients of the ground reaction from meeting smoothed accelerations:
    Kristianslund et al. 2012, J Biomech 45:666); a load never loaded is kept as it is. One
    pass of the filter over the columns of every load of the same frames (a trial's): each
    column is filtered alone, so the values are those of one call per signal, for one call's
    overhead."""
    out = list(loads)
    by_frames: dict[int, list[int]] = {}
    for k, load in enumerate(loads):
        if load.loaded().size:
            by_frames.setdefault(len(load.force), []).append(k)
    for group in by_frames.values():
        stacked = lowpass(np.concatenate([np.concatenate([loads[k].force, loads[k].moment],
                                                         axis=1) for k in group], axis=1),
                          rate, cutoff, order)
        for j, k in enumerate(group):
            out[k] = loads[k].with_filtered(
                np.ascontiguousarray(stacked[:, 6 * j:6 * j + 3]),
                np.ascontiguousarray(stacked[:, 6 * j + 3:6 * j + 6]))
    return out

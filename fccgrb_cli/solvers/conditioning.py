"""How near a motion comes to a singular position of the classical model (docs/formulation.md §4,
§11).

The inverse dynamics solves Φ_qᵀ λ = g − M q̈ on the classical model (the angles as drivers).
Where Φ_q loses rank — a closed loop's change point (a parallelogram four-bar with all links in
line), an angle at 0° or 180° where s1·s2 = cos θ is flat, a universal joint folded onto
itself — the drivers no longer determine q, and whatever part of the right-hand side falls
along the lost direction (rounding, the differenced accelerations' inconsistency) is divided by
the vanishing singular value: 10⁷ N·m from a mechanism whose true moments are a few N·m.

The measure is the ratio σ_min/σ_max of Φ_q, with its columns and rows in one unit of length:
positions (the bodies' r) in units of L, the median distance of the model's points from their
body's origin, and each equation that involves positions divided by L, so that a joint's
point equations and its axes' dot products weigh alike whatever the model's size. Redundant
equations (a planar loop written in 3D, a signed angle's sine row) do not count: σ_min is the
nq-th largest singular value, the one that vanishes when q is no longer determined. A frame is
near a singular position when its ratio falls below ``SINGULAR_RATIO`` (1/10) of the model's
well-conditioned value: the larger of the ratio at the model's stated pose and the motion's
90th percentile. On the shipped mechanisms and on clean gait trials the ratio never falls
below 0.49 of that value; on the parallelogram it is ~0.019 per degree from a change point
(README, "What fccgrb checks for you").

Every solved frame is looked at: a singular position is a point of the motion, and a trial
may hold it exactly (a parallelogram sampled at θ = 360.000°) with its neighbours a sampling
step away and well conditioned, so no sampling of the frames, however refined around low
values, can be sure to meet it. σ_min and σ_max (the eigenvalues of Φ̃_qᵀΦ̃_q) cost 0.45 ms
a frame on the 84 coordinates of the Plug-in Gait model (one thread), about half of that
frame's solve.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fccgrb_cli.core.blas import single_threaded
from fccgrb_cli.model import Model
from fccgrb_cli.solvers.batched import Stacked, blocks
from fccgrb_cli.system import System, compile_system

SINGULAR_RATIO = 0.1
REFERENCE_PERCENTILE = 90.0


@dataclass(frozen=True)
class Conditioning:
    """Per frame, σ_min/σ_max of the classical model's scaled Φ_q (NaN where the frame has no
    solution), the reference it is compared with, and which frames are near a singular
    position."""

    ratio: np.ndarray
    reference: float
    singular: np.ndarray

    def describe(self) -> str:
        """How near the worst frame came, relative to the reference."""
        if not np.isfinite(self.ratio).any():
            return ""
        f = int(np.nanargmin(self.ratio))
        return (f"the classical model's Jacobian reaches {self.ratio[f] / self.reference:.3g} of "
                f"its well-conditioned σ_min/σ_max at frame index {f} (flagged below "
                f"{SINGULAR_RATIO:g})")


def characteristic_length(model: Model) -> float:
    """L: the median distance of the model's named points from their body's origin (m)."""
    lengths = [float(np.linalg.norm(p.local)) for b in model.bodies for p in b.points.values()]
    lengths = [length for length in lengths if length > 0]
    return float(np.median(lengths)) if lengths else 1.0


class _Scaled:
    """The classical model's Φ_q in units of L (see the module's docstring)."""

    def __init__(self, model: Model) -> None:
        self.system: System = compile_system(model.with_form("full"), angles="driver")
        self.stacked = Stacked(self.system)
        nq = self.system.nq
        length = characteristic_length(model)
        columns = np.ones(nq)
        for body in model.bodies:
            columns[np.arange(nq)[self.system.layout.q_slice(body.name)][:3]] = length
        self.columns = columns  # q = columns · q̃
        # an equation involves positions where it has a term in some body's r, at any pose
        probe = self.stacked.jacobian(np.vstack([np.zeros(nq), np.eye(nq)]))
        lengthy = np.abs(probe[:, :, columns != 1.0]).max(axis=(0, 2)) > 0
        self.rows = np.where(lengthy, 1.0 / length, 1.0)

    def ratio(self, q: np.ndarray) -> np.ndarray:
        """σ_min/σ_max (σ_min the nq-th) per frame of q (frames × nq), in blocks."""
        nq = self.system.nq
        out = np.empty(len(q))
        for b in blocks(len(q)):
            J = self.stacked.jacobian(q[b]) * self.rows[None, :, None] * self.columns
            eigen = np.linalg.eigvalsh(np.matmul(J.transpose(0, 2, 1), J))
            out[b] = np.sqrt(np.maximum(eigen[:, -nq], 0.0) / eigen[:, -1])
        return out


@single_threaded
def conditioning(model: Model, q: np.ndarray) -> Conditioning:
    """The conditioning of the classical model along body coordinates q (frames × the model's
    body coordinates in its own body forms; NaN rows for unsolved frames)."""
    scaled = _Scaled(model)
    if any(body.form == "reduced" for body in model.bodies):  # to the fully-defined x
        q = Stacked(compile_system(model, angles="driver")).expand(q)
    n = len(q)
    ratio = np.full(n, np.nan)
    solved = np.flatnonzero(np.isfinite(q).all(axis=1))
    if not len(solved):
        return Conditioning(ratio, np.nan, np.zeros(n, dtype=bool))
    ratio[solved] = scaled.ratio(q[solved])
    pose = scaled.ratio(scaled.system.layout.pose_q(scaled.system.model)[None])[0]
    reference = max(float(np.percentile(ratio[solved], REFERENCE_PERCENTILE)), float(pose))
    cutoff = SINGULAR_RATIO * reference
    singular = np.zeros(n, dtype=bool)
    singular[solved] = ratio[solved] < cutoff
    return Conditioning(ratio, reference, singular)

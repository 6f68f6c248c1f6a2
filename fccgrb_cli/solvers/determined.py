"""Which frames the markers present can determine: no data, no answer.

A frame's tracking equations are those of its markers that are present; when they and the
topology no longer fix every coordinate (a body without its markers, or a leading second before
the subject walks in), no method may report the frame: an optimizer would return its warm start
as converged, and a frame it never saw would count among the solved ones. So the frames are
sorted before any method runs: with every marker present the model is determined (its check,
``fccgrb check``, found the mixed Jacobian of full rank); for each pattern of missing markers,
W^½Φ_q of the mixed system without those markers' rows must keep full column rank
(``nrm.problem.solvable``) at the model's stated pose or, should that pose be special, at a
turned copy of it. The AD baseline's pre-analysis fits every segment to its markers and needs
all of them.
"""

from __future__ import annotations

import numpy as np

from fccgrb_cli.solvers.nrm.problem import row_weights, solvable, without_gaps
from fccgrb_cli.system import System


def _probes(system: System) -> list[np.ndarray]:
    """Two configurations to test rank at: the model's pose (a paper-style angle at 90°, where
    its relation is steepest) and the pose with every body turned by a small fixed rotation."""
    layout = system.layout
    pose = layout.pose_q(system.model)
    theta = np.where(system.full_angles | system.distance_rows,
                     system.angles_at(pose) if len(system.full_angles) else 0.0, np.pi / 2)
    first = layout.pose_q(system.model, theta)
    c, s = np.cos(0.3), np.sin(0.3)
    turn = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ \
        np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])
    second = first.copy()
    for form, offset in zip(layout.forms, layout.q_offsets, strict=True):
        block = second[offset:offset + (12 if form == "full" else 9)].reshape(-1, 3)
        second[offset:offset + len(block) * 3] = (block @ turn.T).ravel()
    return [first, second]


def determined(system: System, targets: np.ndarray, every_marker: bool = False) -> np.ndarray:
    """Per frame (``targets``: frames × targets × 3, NaN where missing), whether the markers
    present determine the mixed system's coordinates; ``every_marker``: only frames with all of
    them (the AD baseline)."""
    missing = ~np.isfinite(targets).all(axis=2)
    out = ~missing.any(axis=1)
    if every_marker or out.all():
        return out
    weights = row_weights(system, 1e-3)
    probes = _probes(system)
    patterns, inverse = np.unique(missing, axis=0, return_inverse=True)
    verdict = np.array([not pattern.any() or (pattern.sum() < len(pattern) and any(
        solvable(system, q, without_gaps(weights, system, pattern)) for q in probes))
        for pattern in patterns])
    return verdict[np.asarray(inverse).ravel()]

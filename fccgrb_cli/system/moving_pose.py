"""Bodies placed by the coordinates of moving joints: forward kinematics on the compiled model.

Down the joint tree from the ground, each child's joint frame is its parent's joint frame moved by
the transform (R_PC(θ), p_PC(θ)), and the child body follows its joint frame: with the frame's
local axes A (columns) and origin c in the body, R_body = R_C Aᵀ and r_body = o_C − R_body c.
"""

from __future__ import annotations

import numpy as np

from fccgrb_cli.model import GROUND, Model
from fccgrb_cli.system.compiled import System

__all__ = ["pose_from_coordinates"]


def _frame(model: Model, body: str, origin: str, axes: tuple[str, str, str]
           ) -> tuple[np.ndarray, np.ndarray]:
    """A joint frame's local origin (3,) and axes (3 × 3, columns) in its body (global for the
    ground)."""
    points = model.ground.points if body == GROUND else model.body(body).points
    vectors = model.ground.vectors if body == GROUND else model.body(body).vectors
    return (np.asarray(points[origin].local, dtype=float),
            np.column_stack([vectors[a].local for a in axes]).astype(float))


def pose_from_coordinates(system: System, theta: np.ndarray) -> np.ndarray:
    """q (system.nq,) with every body where the coordinates θ (rad, m) put it and, for a mixed
    system, θ itself in the coordinates' slots.

    Parameters
    ----------
    system
        A compiled model with moving joints (``system.functions`` set).
    theta
        The coordinates in the order of ``model.angles`` (n_θ,).

    Returns
    -------
    numpy.ndarray
        The system coordinates q: [r, u, v, w] per body, then θ when mixed.
    """
    model, layout = system.model, system.layout
    placed = {GROUND: (np.eye(3), np.zeros(3))}
    names = [a.name for a in model.angles]
    pending = list(model.moving_joints)
    q = layout.pose_q(model)
    while pending:
        joint = next((j for j in pending if j.parent in placed), None)
        if joint is None:
            break  # bodies no moving joint reaches keep their stated pose
        pending.remove(joint)
        R_body, r_body = placed[joint.parent]
        p_local, A_P = _frame(model, joint.parent, joint.parent_origin, joint.parent_axes)
        R_P, o_P = R_body @ A_P, r_body + R_body @ p_local
        index = [names.index(c) for c in joint.transform.coordinates]
        h = joint.transform.terms(np.asarray(theta, dtype=float)[index], second=False)[0]
        R_C, o_C = R_P @ h[:9].reshape(3, 3), o_P + R_P @ h[9:]
        c_local, A_C = _frame(model, joint.child, joint.child_origin, joint.child_axes)
        R_child = R_C @ A_C.T
        r_child = o_C - R_child @ c_local
        placed[joint.child] = (R_child, r_child)
        block = layout.q_slice(joint.child)
        full = np.concatenate([r_child, R_child[:, 0], R_child[:, 1], R_child[:, 2]])
        q[block] = full[: block.stop - block.start]
    if system.mixed:
        q[layout.n_body_q:] = theta
    return q

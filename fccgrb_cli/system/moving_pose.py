"""Bodies placed by the coordinates of moving joints: forward kinematics on the compiled model.

Down the joint tree from the ground, each child's joint frame is its parent's joint frame moved by
the transform (R_PC(θ), p_PC(θ)), and the child body follows its joint frame: with the frame's
local axes A (columns) and origin c in the body, R_body = R_C Aᵀ and r_body = o_C − R_body c.
"""

from __future__ import annotations

import weakref
from typing import NamedTuple

import numpy as np

from fccgrb_cli.model import GROUND, Model
from fccgrb_cli.system.compiled import System

__all__ = ["pose_from_coordinates"]


class _Step(NamedTuple):
    """One joint of the walk down the tree: its index among the function rows' joints, its
    parent and child, the parent frame's and child frame's local origin and axes (columns), and
    the child's slice of q."""

    joint: int
    parent: str
    child: str
    parent_origin: np.ndarray
    parent_axes: np.ndarray
    child_origin: np.ndarray
    child_axes: np.ndarray
    block: slice


def _frame(model: Model, body: str, origin: str, axes: tuple[str, str, str]
           ) -> tuple[np.ndarray, np.ndarray]:
    """A joint frame's local origin (3,) and axes (3 × 3, columns) in its body (global for the
    ground)."""
    points = model.ground.points if body == GROUND else model.body(body).points
    vectors = model.ground.vectors if body == GROUND else model.body(body).vectors
    return (np.asarray(points[origin].local, dtype=float),
            np.column_stack([vectors[a].local for a in axes]).astype(float))


def _walk(system: System) -> tuple[_Step, ...]:
    """The moving joints in an order that places each parent before its child (joints no walk
    from the ground reaches left out: their bodies keep their stated pose); built once per
    system."""
    if system in _WALKS:
        return _WALKS[system]
    model, layout = system.model, system.layout
    placed, steps = {GROUND}, []
    pending = list(enumerate(model.moving_joints))
    while pending:
        found = next(((k, j) for k, j in pending if j.parent in placed), None)
        if found is None:
            break
        pending.remove(found)
        k, joint = found
        placed.add(joint.child)
        steps.append(_Step(k, joint.parent, joint.child,
                           *_frame(model, joint.parent, joint.parent_origin, joint.parent_axes),
                           *_frame(model, joint.child, joint.child_origin, joint.child_axes),
                           layout.q_slice(joint.child)))
    _WALKS[system] = tuple(steps)
    return _WALKS[system]


_WALKS: weakref.WeakKeyDictionary[System, tuple[_Step, ...]] = weakref.WeakKeyDictionary()


def pose_from_coordinates(system: System, theta: np.ndarray) -> np.ndarray:
    """q with every body where the coordinates θ (rad, m) put it and, for a mixed system, θ
    itself in the coordinates' slots; at one pose or at many.

    Parameters
    ----------
    system
        A compiled model with moving joints (``system.functions`` set).
    theta
        The coordinates in the order of ``model.angles``: (n_θ,), or (frames × n_θ).

    Returns
    -------
    numpy.ndarray
        The system coordinates q ((nq,), or frames × nq): [r, u, v, w] per body, then θ when
        mixed.
    """
    functions = system.functions
    assert functions is not None  # a model with moving joints has their function rows
    theta = np.asarray(theta, dtype=float)
    frames = theta.reshape(-1, theta.shape[-1])
    n = len(frames)
    R_PC, p_PC = functions.transforms(theta)  # frames × joints × (3 × 3, 3)
    placed = {GROUND: (np.broadcast_to(np.eye(3), (n, 3, 3)), np.zeros((n, 3)))}
    q = np.tile(system.layout.pose_q(system.model), (n, 1))
    for step in _walk(system):
        R_body, r_body = placed[step.parent]
        R_P, o_P = R_body @ step.parent_axes, r_body + R_body @ step.parent_origin
        R_C = R_P @ R_PC[:, step.joint]
        o_C = o_P + np.einsum("fij,fj->fi", R_P, p_PC[:, step.joint])
        R_child = R_C @ step.child_axes.T
        r_child = o_C - R_child @ step.child_origin
        placed[step.child] = (R_child, r_child)
        full = np.concatenate([r_child, R_child[:, :, 0], R_child[:, :, 1], R_child[:, :, 2]],
                              axis=1)
        q[:, step.block] = full[:, : step.block.stop - step.block.start]
    if system.mixed:
        q[:, system.layout.n_body_q:] = frames
    return q.reshape(*theta.shape[:-1], system.nq)

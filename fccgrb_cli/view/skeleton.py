"""What of a model the 3D view draws, as points fixed in its bodies (docs/view.md).

Every drawn point is body-fixed, so its place is ``r + a u + b v + c w`` (the paper's Eq. 2,
``C_P q``) with constant (a, b, c): a body's named points, the tips of its u, v, w vectors, a
joint's centre and the ends of its axes, a tracked vector's tip. A :class:`Skeleton` holds those
coefficients once; :meth:`Skeleton.place` gives every point's lab position for any number of
frames of body coordinates at once.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from fccgrb_cli.model import Model
from fccgrb_cli.model.elements import GROUND, JOINTS_WITH_AXES, Body
from fccgrb_cli.system.layout import build_layout

ARROW_MIN_M, ARROW_MAX_M = 0.03, 0.15  # the drawn length of a body's u, v, w (display only)


@dataclass
class Skeleton:
    """Drawn points (``labels``, ``kinds``; ``body`` the body index, −1 for the ground, and
    ``coeff`` (a, b, c), or the ground's fixed position) and the lines between them (index
    pairs, each with its kind and label)."""

    body_names: tuple[str, ...]
    labels: list[str] = field(default_factory=list)
    kinds: list[str] = field(default_factory=list)
    body: list[int] = field(default_factory=list)
    coeff: list[tuple[float, float, float]] = field(default_factory=list)
    lines: list[tuple[int, int]] = field(default_factory=list)
    line_kinds: list[str] = field(default_factory=list)
    line_labels: list[str] = field(default_factory=list)

    def add(self, body: int, coeff, label: str, kind: str) -> int:
        self.labels.append(label)
        self.kinds.append(kind)
        self.body.append(body)
        a, b, c = (float(x) for x in coeff)
        self.coeff.append((a, b, c))
        return len(self.labels) - 1

    def line(self, i: int, j: int, kind: str, label: str = "") -> None:
        self.lines.append((i, j))
        self.line_kinds.append(kind)
        self.line_labels.append(label)

    def place(self, x: np.ndarray) -> np.ndarray:
        """Lab positions of every point.

        Parameters
        ----------
        x : (frames, bodies, 12) each body's fully-defined coordinates [r, u, v, w] (m, unit
            vectors), in ``body_names`` order.

        Returns
        -------
        (frames, points, 3), m.
        """
        body = np.asarray(self.body, dtype=int)
        coeff = np.asarray(self.coeff, dtype=float).reshape(-1, 3)
        out = np.empty((len(x), len(body), 3))
        fixed = body < 0
        out[:, fixed] = coeff[fixed]
        moving = np.flatnonzero(~fixed)
        if len(moving):
            blocks = np.asarray(x, dtype=float)[:, body[moving]].reshape(len(x), -1, 4, 3)
            out[:, moving] = blocks[:, :, 0] + np.einsum("pk,fpkd->fpd", coeff[moving],
                                                         blocks[:, :, 1:])
        return out


def body_coordinates(model: Model, q: np.ndarray) -> np.ndarray:
    """Each body's fully-defined coordinates per frame: x = S V q (Eq. 5), w = u × v for a
    reduced body.

    Parameters
    ----------
    model : the model as solved (its bodies' forms give q's layout).
    q : (frames, nq) the system coordinates (body coordinates first, Eq. 9).

    Returns
    -------
    (frames, bodies, 12).
    """
    layout = build_layout(model, tuple(a.name for a in model.angles))
    q = np.atleast_2d(np.asarray(q, dtype=float))
    x = np.empty((len(q), layout.nx))
    x[:, layout.copy_x] = q[:, layout.copy_q]
    if len(layout.reduced_w):
        x[:, layout.reduced_w] = np.cross(q[:, layout.reduced_u], q[:, layout.reduced_v])
    return x.reshape(len(q), len(model.bodies), 12)


def pose_coordinates(model: Model) -> np.ndarray:
    """The bodies' coordinates in the model file's initial pose, (1, bodies, 12)."""
    return np.array([[b.pose.as_array() for b in model.bodies]])


def arrow_length(body: Body) -> float:
    """How long a body's u, v, w are drawn: half its largest point distance from r, bounded."""
    reach = max((float(np.linalg.norm(p.local)) for p in body.points.values()), default=0.0)
    return float(np.clip(0.5 * reach, ARROW_MIN_M, ARROW_MAX_M))


def skeleton(model: Model, labelled_points: bool = True) -> Skeleton:
    """The model's drawn points and lines: each body's point r, its segments (r to each named
    point), its u, v, w; each joint's centre and axes (two arms for a universal joint); each
    tracked vector. ``labelled_points`` labels every named point (the model view)."""
    names = tuple(b.name for b in model.bodies)
    s = Skeleton(names)
    where: dict[tuple[str, str], int] = {}
    for name, point in model.ground.points.items():
        where[GROUND, name] = s.add(-1, point.local, f"ground.{name}", "ground")
    for k, body in enumerate(model.bodies):
        origin = s.add(k, (0, 0, 0), body.name, "origin")
        for name, point in body.points.items():
            where[body.name, name] = s.add(k, point.local,
                                           f"{body.name}.{name}" if labelled_points else "",
                                           "point")
            s.line(origin, where[body.name, name], "segment", body.name)
        length = arrow_length(body)
        for axis, unit in zip("uvw", np.eye(3), strict=True):
            tip = s.add(k, length * unit, axis if labelled_points else "", axis)
            s.line(origin, tip, axis, f"{body.name}.{axis}")
    _joints(model, s, where)
    for tracked in model.tracked_vectors:
        k = names.index(tracked.body)
        body = model.bodies[k]
        local = np.asarray(body.vectors[tracked.vector].local)
        origin = s.add(k, (0, 0, 0), "", "hidden")
        tip = s.add(k, 2 * arrow_length(body) * local,
                    f"{tracked.body}.{tracked.vector} ← {tracked.marker}", "tracked_vector")
        s.line(origin, tip, "tracked_vector", tracked.marker)
    return s


def _joints(model: Model, s: Skeleton, where: dict[tuple[str, str], int]) -> None:
    """Each joint's centre (on its first body) and its axis through the centre (revolute,
    cylindrical, prismatic, parallel) or its two arms from the centre (universal, one in each
    body). A point's coefficients and a vector's components combine as r + (c + t s)·(u, v, w)
    = P + t s on a body, and as global coordinates on the ground: one formula for both."""
    names = tuple(b.name for b in model.bodies)

    def index(body: str) -> int:
        return names.index(body) if body != GROUND else -1

    for joint in model.joints:
        first, second = joint.bodies
        k = index(first)
        centre = np.asarray(s.coeff[where[first, joint.points[0]]]) \
            if joint.points is not None else np.zeros(3)  # a parallel joint: at body 1's r
        s.add(k, centre, f"{joint.name} ({joint.type})", "joint")
        if joint.type not in JOINTS_WITH_AXES or joint.axes is None:
            continue
        reach = 2 * max(arrow_length(b) for b in model.bodies
                        if b.name in (first, second))
        if joint.type == "universal":
            assert joint.points is not None  # a universal joint has its centre on each body
            arms = [(first, centre, joint.axes[0], 0.0),
                    (second, np.asarray(s.coeff[where[second, joint.points[1]]]),
                     joint.axes[1], 0.0)]
        else:
            arms = [(first, centre, joint.axes[0], -1.0)]
        for body, base, vector, back in arms:
            local = _vector(model, body, vector)
            start = s.add(index(body), base + back * reach * local, "", "hidden")
            end = s.add(index(body), base + reach * local, "", "hidden")
            s.line(start, end, "axis", f"{joint.name} axis {body}.{vector}")


def _vector(model: Model, body: str, name: str) -> np.ndarray:
    vectors = model.ground.vectors if body == GROUND else model.body(body).vectors
    return np.asarray(vectors[name].local, dtype=float)

"""Plug-in Gait's kinetics from a solved motion: each leg's ankle, knee and hip moments (N·mm/kg)
and powers (W/kg), as Vicon writes them (``LAnkleMoment``, ``LKneePower``, ...).

Newton–Euler from the foot up (Winter 2009, ch. 5), per frame, on the segments' solved motion
(the classical model's consistent q, q̇, q̈): with a segment's mass m, centre of mass c, inertia I
about it, angular velocity ω and acceleration α, and the loads on it (external ones, and the
distal joint's reaction −F_d, −M_d at the distal joint centre d), the force F and moment M the
proximal segment exerts on it at the proximal joint centre p (the net internal joint moment):

    F = m (c̈ − g) − Σ F_ext + F_d
    M = I α + ω × I ω + (c − p) × m (c̈ − g) − Σ [(r_ext − p) × F_ext + M_free]
        + M_d + (d − p) × F_d

ω = ½ Σ e × ė and α = ½ Σ e × ë over the body axes e = u, v, w. The joint power is
M · (ω_distal − ω_proximal). Plug-in Gait reports each moment in the distal segment's axes
(x anterior, y left, z up; the foot's x up, y left, z toe → heel) per side as
(``MOMENT_AXES``), divided by the body mass; the power in the Z component of a 3-vector.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fccgrb_cli.plugin_gait.angles import SIDES, pig_axes

# Plug-in Gait's (X, Y, Z) of each joint moment from its components (x, y, z) in the distal
# segment's axes: (component index, sign) per output, for the left and right sides (internal
# moments; e.g. X: hip and knee extensor and ankle plantarflexor moments positive).
MOMENT_AXES = {
    ("Hip", "l"): ((1, 1.0), (0, 1.0), (2, 1.0)),
    ("Hip", "r"): ((1, 1.0), (0, -1.0), (2, -1.0)),
    ("Knee", "l"): ((1, -1.0), (0, 1.0), (2, 1.0)),
    ("Knee", "r"): ((1, -1.0), (0, -1.0), (2, -1.0)),
    ("Ankle", "l"): ((1, 1.0), (2, -1.0), (0, 1.0)),
    ("Ankle", "r"): ((1, 1.0), (2, 1.0), (0, -1.0)),
}


@dataclass(frozen=True)
class Segment:
    """A body's solved motion (frames × …, SI, global): axes (columns u, v, w) and their first
    and second rates, the centre of mass and its acceleration, the inertia about it in the body
    axes, the mass."""

    axes: np.ndarray
    axes_d: np.ndarray
    axes_dd: np.ndarray
    com: np.ndarray
    com_dd: np.ndarray
    inertia: np.ndarray
    mass: float

    @property
    def omega(self) -> np.ndarray:
        return 0.5 * np.cross(self.axes, self.axes_d, axis=1).sum(axis=2)

    @property
    def alpha(self) -> np.ndarray:
        return 0.5 * np.cross(self.axes, self.axes_dd, axis=1).sum(axis=2)


def segment_motion(x: np.ndarray, xd: np.ndarray, xdd: np.ndarray, com_local: np.ndarray,
                   inertia: np.ndarray, mass: float) -> Segment:
    """A body's motion from its fully-defined coordinates [r, u, v, w] and their rates
    (frames × 12 each): c = r + a u + b v + c w with the CoM's local (a, b, c)."""
    def axes(values: np.ndarray) -> np.ndarray:
        return np.stack([values[:, 3:6], values[:, 6:9], values[:, 9:12]], axis=2)

    com = x[:, :3] + axes(x) @ com_local
    com_dd = xdd[:, :3] + axes(xdd) @ com_local
    return Segment(axes(x), axes(xd), axes(xdd), com, com_dd, inertia, mass)


def joint_load(seg: Segment, proximal: np.ndarray, gravity: np.ndarray,
               external: list[tuple[np.ndarray, np.ndarray, np.ndarray]],
               distal: tuple[np.ndarray, np.ndarray, np.ndarray] | None
               ) -> tuple[np.ndarray, np.ndarray]:
    """(F, M) the proximal segment exerts on ``seg`` at ``proximal`` (frames × 3 each; the
    module's equations); ``external``: (force, point, free moment) per load; ``distal``: the
    distal joint's (F_d, M_d, d), the distal segment's own (F, M) at its proximal joint d."""
    inertia = np.einsum("fij,jk,flk->fil", seg.axes, seg.inertia, seg.axes)
    omega, alpha = seg.omega, seg.alpha
    inertial = seg.mass * (seg.com_dd - gravity)
    force = inertial.copy()
    moment = (np.einsum("fij,fj->fi", inertia, alpha)
              + np.cross(omega, np.einsum("fij,fj->fi", inertia, omega))
              + np.cross(seg.com - proximal, inertial))
    for f, point, free in external:
        force -= f
        moment -= np.cross(point - proximal, f) + free
    if distal is not None:
        f_d, m_d, d = distal
        force += f_d
        moment += m_d + np.cross(d - proximal, f_d)
    return force, moment


def pig_moment(moment: np.ndarray, distal_axes: np.ndarray, joint: str, side: str,
               foot: bool) -> np.ndarray:
    """A joint moment (frames × 3, N·m, global) as Plug-in Gait's (X, Y, Z), N·m: its
    components in the distal segment's Plug-in Gait axes, ordered and signed by
    ``MOMENT_AXES``."""
    local = np.einsum("fji,fj->fi", pig_axes(distal_axes, foot=foot), moment)
    return np.column_stack([sign * local[:, k] for k, sign in MOMENT_AXES[(joint, side)]])


@dataclass(frozen=True)
class LegKinetics:
    """One leg's Plug-in Gait kinetics (frames × 3): moments in N·mm/kg, powers in W/kg (in Z),
    per joint name (Hip, Knee, Ankle)."""

    moments: dict[str, np.ndarray]
    powers: dict[str, np.ndarray]


def leg_kinetics(segments: dict[str, Segment], centres: dict[str, np.ndarray], side: str,
                 loads: list[tuple[np.ndarray, np.ndarray, np.ndarray]],
                 context: tuple[np.ndarray, float]) -> LegKinetics:
    """Plug-in Gait's kinetics of side ``side`` from the segments 'pelvis', 'thigh', 'shank',
    'foot' (that side's) and the joint centres 'hip', 'knee', 'ankle' (frames × 3, global);
    ``loads``: the external loads on the foot; ``context``: (gravity, body mass in kg)."""
    gravity, body_mass = context
    chain = (("Ankle", "foot", "shank", "ankle"), ("Knee", "shank", "thigh", "knee"),
             ("Hip", "thigh", "pelvis", "hip"))
    moments: dict[str, np.ndarray] = {}
    powers: dict[str, np.ndarray] = {}
    distal = None
    external = loads
    for joint, body, parent, centre in chain:
        f, m = joint_load(segments[body], centres[centre], gravity, external, distal)
        per_kg = pig_moment(m, segments[body].axes, joint, side, body == "foot") / body_mass
        moments[joint] = 1e3 * per_kg
        power = np.sum(m * (segments[body].omega - segments[parent].omega), axis=1) / body_mass
        powers[joint] = np.column_stack([np.zeros_like(power), np.zeros_like(power), power])
        distal, external = (f, m, centres[centre]), []
    return LegKinetics(moments, powers)


def pig_kinetics_names() -> tuple[tuple[str, ...], tuple[str, ...]]:
    """Plug-in Gait's moment and power outputs, left side first."""
    joints = ("Hip", "Knee", "Ankle")
    return (tuple(f"{SIDES[s]}{j}Moment" for s in ("l", "r") for j in joints),
            tuple(f"{SIDES[s]}{j}Power" for s in ("l", "r") for j in joints))

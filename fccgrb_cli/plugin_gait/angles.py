"""Plug-in Gait's output angles from segment frames: ``LPelvisAngles``, ``LHipAngles``,
``LKneeAngles``, ``LAnkleAngles``, ``LFootProgressAngles`` and the right side's (X, Y, Z in
degrees), as Vicon's Plug-in Gait computes them.

Each joint's angles are the Cardan angles of the distal segment's axes relative to the proximal
one's in Plug-in Gait's own segment axes (x anterior, y to the subject's left, z up; the foot's
x up, y left, z toe → heel), in the sequence y–x–z: R_proximalᵀ R_distal = R_y(a) R_x(b) R_z(c)
(a about the proximal's lateral axis, b about the floating antero-posterior axis, c about the
distal's long axis), and then, per output (X, Y, Z), with the signs Plug-in Gait gives each side
(``s`` = +1 right, −1 left):

* pelvis (pelvis in the progression frame): (a, −s b, s c) — tilt, obliquity, rotation;
* hip (pelvis → thigh): (−a, s b, s c) — flexion, adduction, internal rotation;
* knee (thigh → proximal tibia): (a, s b, s c) — flexion, varus, internal rotation;
* ankle (distal tibia → corrected foot): (−a − 90°, s c, s b) — dorsiflexion, inversion,
  internal rotation (the foot's long axis is its z);
* foot progression (corrected foot in the progression frame): (a, −s c, s b).

The progression frame is the laboratory's horizontal axis (±x or ±y) the pelvis travels along
over the trial, with the laboratory's up as z; a trial without travel (a static) takes the axis
nearest the pelvis's mean anterior axis. Angles are continuous over the frames as Vicon writes
them (no wrap at ±180°, and the other Cardan reading where it lies nearer the previous frame's:
:func:`_continuous`).

The model bodies' frames are the segments' in this project's order (u anterior, v superior, w
to the subject's right): Plug-in Gait's axes are x = u, y = −w, z = v (foot: x = v, y = −w,
z = −u); the distal tibia is the body's (proximal) tibia turned by the tibial torsion.
"""

from __future__ import annotations

import numpy as np

SIDES = {"l": "L", "r": "R"}
SIDE_SIGN = {"r": 1.0, "l": -1.0}
JOINTS = ("Pelvis", "Hip", "Knee", "Ankle", "FootProgress")
COMPONENTS = ("X", "Y", "Z")
TRAVEL = 0.5  # m: a pelvis moving less than this over the trial is a static trial


def output_names() -> tuple[str, ...]:
    """Plug-in Gait's angle outputs, left side first: LPelvisAngles ... RFootProgressAngles."""
    return tuple(f"{SIDES[s]}{j}Angles" for s in ("l", "r") for j in JOINTS)


def pig_axes(axes: np.ndarray, foot: bool = False) -> np.ndarray:
    """Plug-in Gait's segment axes (columns x, y, z) from a body's (u, v, w), frames × 3 × 3."""
    u, v, w = axes[..., 0], axes[..., 1], axes[..., 2]
    if foot:
        return np.stack([v, -w, -u], axis=-1)
    return np.stack([u, -w, v], axis=-1)


def cardan_yxz(proximal: np.ndarray, distal: np.ndarray) -> np.ndarray:
    """(a, b, c) in radians with proximalᵀ distal = R_y(a) R_x(b) R_z(c), per frame (axes as
    columns, frames × 3 × 3): b = asin(−R₁₂), a = atan2(R₀₂, R₂₂), c = atan2(R₁₀, R₁₁)."""
    r = np.einsum("fji,fjk->fik", proximal, distal)
    b = np.arcsin(np.clip(-r[:, 1, 2], -1.0, 1.0))
    a = np.arctan2(r[:, 0, 2], r[:, 2, 2])
    c = np.arctan2(r[:, 1, 0], r[:, 1, 1])
    return np.stack([a, b, c], axis=1)


def turn_about_z(axes: np.ndarray, angle: float) -> np.ndarray:
    """Plug-in Gait axes turned by ``angle`` (rad) about their z axis: x → cos x + sin y."""
    c, s = np.cos(angle), np.sin(angle)
    return axes @ np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def progression_frame(pelvis_origin: np.ndarray, pelvis_anterior: np.ndarray,
                      up: np.ndarray) -> np.ndarray:
    """The progression frame's axes (columns x, y, z; 3 × 3): x the laboratory axis (±x or ±y)
    nearest the pelvis's travel from its first to its last frame (or, when it travels less
    than 0.5 m, its mean anterior axis), z = ``up`` (a laboratory axis), y = z × x."""
    valid = np.flatnonzero(np.isfinite(pelvis_origin).all(axis=1))
    travel = pelvis_origin[valid[-1]] - pelvis_origin[valid[0]]
    horizontal = travel - (travel @ up) * up
    direction = horizontal if np.linalg.norm(horizontal) >= TRAVEL else \
        np.nanmean(pelvis_anterior, axis=0)
    candidates = [k for k in range(3) if abs(up[k]) < 0.5]
    k = max(candidates, key=lambda i: abs(direction[i]))
    x = np.zeros(3)
    x[k] = np.sign(direction[k])
    return np.stack([x, np.cross(up, x), up], axis=1)


def _continuous(degrees: np.ndarray) -> np.ndarray:
    """Plug-in Gait's continuity, frame by frame (Vicon's; pyCGM2's ``wrapEulerTo`` does the
    same): from (0, 0, 0) before the first frame with values, each frame's output (X, Y, Z)
    or its other reading (X + 180°, 180° − Y, Z + 180°), each component shifted by whole turns
    to lie nearest the previous frame's value, whichever lies nearer (its largest component
    difference the smaller; the first reading on a tie). Where the middle Cardan angle is Y
    (pelvis, hip, knee) the other reading is the same rotation; for the ankle and the foot
    progression (middle angle in Z) it is not, and Vicon writes it all the same: a foot
    turned ~90° from the progression axis at the first frame starts on it. Frames without
    values stay NaN; the next frame continues from the last one with values."""
    out = np.array(degrees, dtype=float)
    previous = np.zeros(3)
    for f in np.flatnonzero(np.isfinite(out).all(axis=1)):
        best: tuple[float, np.ndarray] | None = None
        for reading in (out[f], out[f] * [1.0, -1.0, 1.0] + 180.0):
            shifted = reading + 360.0 * np.floor((previous - reading + 180.0) / 360.0)
            distance = np.max(np.abs(shifted - previous))
            if best is None or distance < best[0]:
                best = (distance, shifted)
        assert best is not None  # two readings were compared
        out[f] = previous = best[1]
    return out


def pig_angles(frames: dict[str, np.ndarray], torsion: dict[str, float],
               progression: np.ndarray) -> dict[str, np.ndarray]:
    """Plug-in Gait's angles (name → frames × 3, deg) from the bodies' axes ``frames`` (body
    name → frames × 3 × 3, columns u, v, w: pelvis, thigh_s, shank_s, foot_s for s = l, r; the
    shank is the proximal tibia), the tibial torsion per side (rad) and the progression frame
    (3 × 3, :func:`progression_frame`); continuous over the frames as Plug-in Gait writes them
    (:func:`_continuous`)."""
    n = len(frames["pelvis"])
    lab = np.broadcast_to(progression, (n, 3, 3))
    pelvis = pig_axes(frames["pelvis"])
    out: dict[str, np.ndarray] = {}
    for s, prefix in SIDES.items():
        sign = SIDE_SIGN[s]
        thigh = pig_axes(frames[f"thigh_{s}"])
        tibia = pig_axes(frames[f"shank_{s}"])
        distal = turn_about_z(tibia, sign * torsion[s])
        foot = pig_axes(frames[f"foot_{s}"], foot=True)
        p = cardan_yxz(lab, pelvis)
        h = cardan_yxz(pelvis, thigh)
        k = cardan_yxz(thigh, tibia)
        a = cardan_yxz(distal, foot)
        f = cardan_yxz(lab, foot)
        deg = np.degrees
        out[f"{prefix}PelvisAngles"] = deg(p * [1.0, -sign, sign])
        out[f"{prefix}HipAngles"] = deg(h * [-1.0, sign, sign])
        out[f"{prefix}KneeAngles"] = deg(k * [1.0, sign, sign])
        out[f"{prefix}AnkleAngles"] = np.column_stack(
            [-deg(a[:, 0]) - 90.0, sign * deg(a[:, 2]), sign * deg(a[:, 1])])
        out[f"{prefix}FootProgressAngles"] = np.column_stack(
            [deg(f[:, 0]), -sign * deg(f[:, 2]), sign * deg(f[:, 1])])
    return {name: _continuous(out[name]) for name in output_names()}

"""Plug-in Gait's (the Conventional Gait Model's, CGM 1.0) segment definitions, per frame.

Vicon's Plug-in Gait (Kadaba et al. 1990; Davis et al. 1991) builds each lower-limb segment from
the joint centre above it and two markers, one frame at a time:

* pelvis: origin mid-ASIS, lateral axis from the right to the left ASIS, anterior axis in the
  plane of the ASIS and the sacrum marker (SACR, or the mid-PSIS point);
* hip centres: Davis et al. (1991)'s regression in the pelvis frame (:func:`davis_hip_centre`);
* knee centre: the chord construction (:func:`chord`) from the hip centre, the thigh wand and
  the lateral knee marker, at (knee width + marker diameter) / 2 from the marker, the wand
  turned by the thigh rotation offset; thigh: long axis knee → hip centre, lateral axis knee
  centre → knee marker;
* ankle centre: the same from the knee centre, the shank wand and the lateral malleolus with
  the ankle width and the shank rotation offset; the *distal* tibia: long axis ankle → knee
  centre, lateral axis ankle centre → malleolus (the ankle flexion axis); the *proximal* tibia,
  whose lateral axis is the knee's flexion axis, turned back by the tibial torsion about the long
  axis (:func:`proximal_tibia`);
* foot: the *uncorrected* foot's long axis from the toe marker to the ankle centre, its
  transverse axis perpendicular to it and to the proximal tibia's flexion axis (so that the
  foot has only two rotations relative to the shank, a universal joint); the *corrected* foot,
  turned by the plantarflexion and rotation offsets of a static trial so that its long axis lies
  along the static's heel-to-toe line (:func:`foot_offsets`, :func:`corrected_foot`).

Every function works on arrays of frames (frames × 3, metres) and returns ``Frames`` whose axes
are in the body order of this project (u anterior, v superior, w to the subject's right; Wu et
al. 2002): Plug-in Gait's own axes are x = u, y = −w (to the subject's left), z = v, and the
foot's are x = v (up), y = −w, z = −u (toe to heel). The side ``s`` is 'r' or 'l'; ``SIDE_SIGN``
is +1 on the right.

Checked against Vicon's outputs stored in Nexus C3D files (segment axes and angles to 1e-4° when
the same subject parameters are used): tests/test_plugin_gait.py.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fccgrb_cli.anatomy.frames import Frames, pelvis_frames

SIDE_SIGN = {"r": 1.0, "l": -1.0}
# Davis et al. (1991)'s angles of the hip centre from the ASIS, as Plug-in Gait holds them (rad).
DAVIS_THETA = 0.500000178813934
DAVIS_BETA = 0.314000427722931


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.sum(a * b, axis=-1, keepdims=True)


def _perpendicular(v: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """The unit part of ``v`` perpendicular to the unit ``axis`` (per frame)."""
    return _unit(v - _dot(v, axis) * axis)


def davis_hip_centre(leg_length: float, asis_trochanter: float, inter_asis: float,
                     marker_diameter: float, side: str) -> np.ndarray:
    """The hip centre in the pelvis frame (u, v, w; m) by Davis et al. (1991), Hum Mov Sci
    10:575–587, as Plug-in Gait computes it: C = 0.115 L − 15.3 mm (L the mean leg length),
    x = C cos θ sin β − (d + r) cos β, y = ±(C sin θ − A / 2) (+ on the right, where it is
    negative), z = −C cos θ cos β − (d + r) sin β in Plug-in Gait's pelvis axes (x anterior,
    y left, z up), with d the ASIS–trochanter
    distance, r the marker radius, A the inter-ASIS distance, θ = 0.5 rad, β = 0.314 rad."""
    c = leg_length * 0.115 - 0.0153
    reach = asis_trochanter + marker_diameter / 2.0
    x = c * np.cos(DAVIS_THETA) * np.sin(DAVIS_BETA) - reach * np.cos(DAVIS_BETA)
    y_left = SIDE_SIGN[side] * (c * np.sin(DAVIS_THETA) - inter_asis / 2.0)
    z = -c * np.cos(DAVIS_THETA) * np.cos(DAVIS_BETA) - reach * np.sin(DAVIS_BETA)
    return np.array([x, z, -y_left])


def asis_trochanter_distance(leg_length: float) -> float:
    """Plug-in Gait's ASIS–greater trochanter distance when none is measured (m): 0.1288 L −
    48.56 mm, L the leg length."""
    return 0.1288 * leg_length - 0.04856


def _rotation_about(axis: np.ndarray, target: np.ndarray, reference: np.ndarray,
                    centre: np.ndarray) -> np.ndarray:
    """The signed angle (rad, right hand about ``centre`` → ``axis`` point) from ``target``'s
    projection to ``reference``'s projection on the plane perpendicular to the bone axis
    through ``centre``."""
    n = _unit(axis - centre)
    t = target - centre
    t = t - _dot(t, n) * n
    k = reference - centre
    k = k - _dot(k, n) * n
    return np.arctan2(np.sum(np.cross(t, k) * n, axis=-1), np.sum(t * k, axis=-1))


def chord(proximal: np.ndarray, wand: np.ndarray, marker: np.ndarray, offset: float,
          rotation: float = 0.0) -> np.ndarray:
    """The joint centre J of Plug-in Gait's chord function, per frame: |J − marker| = offset
    and the angle proximal–J–marker a right angle (J on a circle about the proximal–marker
    line), at the point of that circle where the angle about the bone axis J → proximal from
    the wand's projection to the marker's is ``rotation`` (rad; 0: J in the plane of the three
    points, on the side away from the wand). Plug-in Gait passes the thigh (shank) rotation
    offset times +1 on the right and −1 on the left. Solved by Newton's method on the circle's
    angle from the in-plane point (the angle changes by about one radian per radian there)."""
    along = proximal - marker
    distance = np.linalg.norm(along, axis=-1, keepdims=True)
    e1 = along / distance
    e2 = -_perpendicular(wand - marker, e1)
    e3 = np.cross(e1, e2)
    cos = offset / distance
    centre = marker + offset * cos * e1
    radius = offset * np.sqrt(1.0 - cos ** 2)

    def point(phi: np.ndarray) -> np.ndarray:
        return centre + radius * (np.cos(phi)[:, None] * e2 + np.sin(phi)[:, None] * e3)

    phi = np.zeros(len(along))
    if rotation == 0.0:
        return point(phi)
    step = 1e-6
    for _ in range(50):
        error = _rotation_about(proximal, wand, marker, point(phi)) - rotation
        slope = (_rotation_about(proximal, wand, marker, point(phi + step)) - rotation
                 - error) / step
        change = error / slope
        phi = phi - change
        if np.all(np.abs(change) < 1e-13):
            break
    return point(phi)


def segment_frames(origin: np.ndarray, proximal_centre: np.ndarray, distal_centre: np.ndarray,
                   lateral: np.ndarray, side: str) -> Frames:
    """A thigh or distal tibia: long axis v from the distal joint centre to the proximal one,
    w towards the subject's right along the part of distal centre → ``lateral`` marker
    perpendicular to it (the flexion axis), u = v × w; origin ``origin``."""
    v = _unit(proximal_centre - distal_centre)
    w = SIDE_SIGN[side] * _perpendicular(lateral - distal_centre, v)
    return Frames(origin, np.stack([np.cross(v, w), v, w], axis=2))


def about_long_axis(frames: Frames, angle: float) -> Frames:
    """``frames`` turned by ``angle`` (rad, right hand) about their long axis v."""
    c, s = np.cos(angle), np.sin(angle)
    turn = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
    return Frames(frames.origin, frames.axes @ turn)


def proximal_tibia(distal: Frames, torsion: float, side: str) -> Frames:
    """The tibia whose flexion axis is the knee's: the distal (malleolar) tibia turned back by
    the tibial torsion about its long axis (Plug-in Gait turns its z axis by −torsion on the
    right, +torsion on the left)."""
    return about_long_axis(distal, -SIDE_SIGN[side] * torsion)


def uncorrected_foot(ankle: np.ndarray, toe: np.ndarray, tibia: Frames) -> Frames:
    """Plug-in Gait's uncorrected foot at the ankle centre: long axis u from the ankle centre
    towards the toe marker, its up axis v perpendicular to u and to the (proximal) tibia's
    flexion axis w (Plug-in Gait's x = y_tibia × z, that is v = w_tibia × u), w = u × v."""
    u = _unit(toe - ankle)
    v = _unit(np.cross(tibia.axes[:, :, 2], u))
    return Frames(ankle, np.stack([u, v, np.cross(u, v)], axis=2))


def foot_offsets(foot: Frames, heel: np.ndarray, toe: np.ndarray, up: np.ndarray,
                 flat: bool, sole_delta: float = 0.0) -> tuple[float, float]:
    """Plug-in Gait's static foot offsets (rad): the plantarflexion β and rotation α that carry
    the uncorrected ``foot``'s long axis onto the static's toe-to-heel line — level (its
    component along the unit ``up`` replaced by the sole delta, the heel's sole thickness above
    the toe's) when ``flat`` — per frame tan β = −h_x / h_z, tan α = h_y / √(h_x² + h_z²) with
    h the toe → heel unit vector in the uncorrected foot's Plug-in Gait axes (x up, y left, z
    toe → heel), averaged over the frames. Plug-in Gait stores β as ``StaticPlantFlex`` and α
    as ``StaticRotOff`` on the left, −α on the right."""
    h = heel - toe
    if flat:
        h = h - _dot(h, up) * up + sole_delta * up
    h = np.einsum("fji,fj->fi", foot.axes, _unit(h))  # (u, v, w) components
    x, y, z = h[:, 1], -h[:, 2], -h[:, 0]
    beta = np.arctan(-x / z)
    alpha = np.arctan(y / np.hypot(x, z))
    return float(np.nanmean(beta)), float(np.nanmean(alpha))


def offset_rotation(plantar_flexion: float, rotation: float) -> np.ndarray:
    """The corrected foot's axes (u, v, w) in the uncorrected foot's: Plug-in Gait turns its
    foot axes (x up, y left, z toe → heel) by β about y, then by α about the new x:
    x₁ = cos β x + sin β z, z₁ = −sin β x + cos β z, y₂ = cos α y − sin α z₁,
    z₂ = sin α y + cos α z₁."""
    cb, sb, ca, sa = np.cos(plantar_flexion), np.sin(plantar_flexion), np.cos(rotation), \
        np.sin(rotation)
    # Plug-in Gait's foot axes in the body order: x = v, y = −w, z = −u.
    x, y, z = np.array([0.0, 1.0, 0.0]), np.array([0.0, 0.0, -1.0]), np.array([-1.0, 0.0, 0.0])
    x1 = cb * x + sb * z
    z1 = -sb * x + cb * z
    y2 = ca * y - sa * z1
    z2 = sa * y + ca * z1
    return np.stack([-z2, x1, -y2], axis=1)


def corrected_foot(foot: Frames, plantar_flexion: float, rotation: float) -> Frames:
    """The uncorrected ``foot`` turned by the static offsets (:func:`offset_rotation`)."""
    return Frames(foot.origin, foot.axes @ offset_rotation(plantar_flexion, rotation))


@dataclass(frozen=True)
class SideGeometry:
    """What Plug-in Gait needs of one side (m, rad): the hip centre in the pelvis frame, the
    chord offsets (half the knee and ankle widths plus the marker radius), the thigh and shank
    rotation offsets, the tibial torsion, and the foot offsets (None: the uncorrected foot)."""

    hip: np.ndarray
    knee_offset: float
    ankle_offset: float
    thigh_rotation: float
    shank_rotation: float
    torsion: float
    foot_offsets: tuple[float, float] | None = None


def segments(lm: dict[str, np.ndarray], geometry: dict[str, SideGeometry]) -> dict[str, Frames]:
    """Plug-in Gait's segments per frame from its markers (``lm``: 'pelvis' → (RASI, LASI,
    SACR); per side s 'thigh_s' → (THI, KNE), 'shank_s' → (TIB, ANK), 'toe_s' → TOE; frames × 3
    each): 'pelvis', 'thigh_s' (origin the hip centre), 'shank_s' (the proximal tibia, origin
    the knee centre), 'tibia_s' (the distal tibia), 'foot_s' (origin the ankle centre; corrected
    when the side's foot offsets are given, else uncorrected)."""
    r_asis, l_asis, sacrum = lm["pelvis"]
    pelvis = pelvis_frames(r_asis, l_asis, sacrum, sacrum)
    out = {"pelvis": pelvis}
    for s, g in geometry.items():
        sign = SIDE_SIGN[s]
        hip = pelvis.origin + pelvis.axes @ g.hip
        thigh_wand, knee_marker = lm[f"thigh_{s}"]
        knee = chord(hip, thigh_wand, knee_marker, g.knee_offset, sign * g.thigh_rotation)
        out[f"thigh_{s}"] = segment_frames(hip, hip, knee, knee_marker, s)
        shank_wand, malleolus = lm[f"shank_{s}"]
        ankle = chord(knee, shank_wand, malleolus, g.ankle_offset, sign * g.shank_rotation)
        distal = segment_frames(knee, knee, ankle, malleolus, s)
        out[f"tibia_{s}"] = distal
        out[f"shank_{s}"] = proximal_tibia(distal, g.torsion, s)
        foot = uncorrected_foot(ankle, lm[f"toe_{s}"], out[f"shank_{s}"])
        out[f"foot_{s}"] = foot if g.foot_offsets is None else corrected_foot(foot,
                                                                             *g.foot_offsets)
    return out

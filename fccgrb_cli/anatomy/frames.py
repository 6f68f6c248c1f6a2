"""Anatomical segment frames from landmark trajectories (frames × 3, metres, global).

Every segment frame follows the ISB convention of Wu et al. (2002): u = X anterior, v = Y
superior (the segment's long axis, distal to proximal), w = Z to the subject's right, for both
sides, so that a model body's (u, v, w) is its anatomical frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Frames:
    """Per-frame origin (frames × 3) and axes (frames × 3 × 3, columns u, v, w)."""

    origin: np.ndarray
    axes: np.ndarray

    def local(self, points: np.ndarray) -> np.ndarray:
        """Global points (frames × 3) in the segment's coordinates, per frame."""
        return np.einsum("fji,fj->fi", self.axes, points - self.origin)

    def mean_local(self, points: np.ndarray) -> np.ndarray:
        """The mean local coordinates of a point over the frames (its body-fixed position)."""
        return np.nanmean(self.local(points), axis=0)

    def mean_direction(self, vectors: np.ndarray) -> np.ndarray:
        """The mean local direction of global vectors (frames × 3), as a unit vector."""
        mean = np.nanmean(np.einsum("fji,fj->fi", self.axes, vectors), axis=0)
        return mean / np.linalg.norm(mean)


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _frames(origin: np.ndarray, anterior_hint: np.ndarray | None, superior: np.ndarray,
            right_hint: np.ndarray) -> Frames:
    """v along ``superior``; u ⟂ v and ``right_hint``; w = u × v (right-handed)."""
    v = _unit(superior)
    u = _unit(np.cross(v, right_hint)) if anterior_hint is None else anterior_hint
    w = np.cross(u, v)
    return Frames(origin, np.stack([u, v, w], axis=2))


def pelvis_frames(r_asis: np.ndarray, l_asis: np.ndarray, r_psis: np.ndarray,
                  l_psis: np.ndarray) -> Frames:
    """ISB pelvis: origin mid-ASIS, w from left to right ASIS, u anterior in the plane of the
    ASIS and the mid-PSIS, v = w × u superior."""
    origin = 0.5 * (r_asis + l_asis)
    w = _unit(r_asis - l_asis)
    forward = origin - 0.5 * (r_psis + l_psis)
    u = _unit(forward - np.sum(forward * w, axis=1, keepdims=True) * w)
    return Frames(origin, np.stack([u, np.cross(w, u), w], axis=2))


def harrington_hip_centre(width: float, depth: float, side: str) -> np.ndarray:
    """The hip joint centre in the pelvis frame (m) from pelvic width PW (ASIS to ASIS) and
    depth PD (mid-ASIS to mid-PSIS), Harrington et al. (2007), J Biomech 40:595–602:
    x = −0.24 PD − 9.9 mm, y = −0.30 PW − 10.9 mm, z = ±(0.33 PW + 7.3 mm)."""
    pw, pd = 1e3 * width, 1e3 * depth
    z = 0.33 * pw + 7.3
    return 1e-3 * np.array([-0.24 * pd - 9.9, -0.30 * pw - 10.9, z if side == "r" else -z])


def chord_joint_centre(proximal: np.ndarray, wand: np.ndarray, marker: np.ndarray,
                       offset: float) -> np.ndarray:
    """A joint centre from a lateral marker (Davis et al. 1991; Plug-in Gait's chord function):
    the point J at ``offset`` (m; half the joint width plus the marker's radius) from the
    ``marker``, in the plane of the ``proximal`` joint centre, the ``wand`` and the marker, on
    the side away from the wand (medial), with the angle proximal–J–marker a right angle, so
    that J–marker is the joint's medio-lateral axis, perpendicular to the segment's long axis
    J–proximal. Per frame (frames × 3); the knee from the hip centre, the thigh wand and the
    lateral knee marker; the ankle from the knee centre, the shank wand and the malleolus."""
    along = proximal - marker
    distance = np.linalg.norm(along, axis=-1, keepdims=True)
    e1 = along / distance
    towards_wand = wand - marker
    e2 = -_unit(towards_wand - np.sum(towards_wand * e1, axis=-1, keepdims=True) * e1)
    cos = offset / distance  # the right angle at J: |J − marker| = offset = distance · cos
    return marker + offset * (cos * e1 + np.sqrt(1.0 - cos ** 2) * e2)


def _lateral_to_right(lateral: np.ndarray, medial: np.ndarray, side: str) -> np.ndarray:
    """The medio-lateral direction pointing to the subject's right, from a side's lateral and
    medial landmarks."""
    return lateral - medial if side == "r" else medial - lateral


def thigh_frames(hip: np.ndarray, lateral_epicondyle: np.ndarray,
                 medial_epicondyle: np.ndarray, side: str) -> Frames:
    """ISB femur: origin at the hip centre, v from the knee centre (mid-epicondyles) to the hip
    centre, u ⟂ to the plane of v and the epicondyles, w = u × v."""
    knee = 0.5 * (lateral_epicondyle + medial_epicondyle)
    return _frames(hip, None, hip - knee,
                   _lateral_to_right(lateral_epicondyle, medial_epicondyle, side))


def shank_frames(knee: np.ndarray, lateral_malleolus: np.ndarray,
                 medial_malleolus: np.ndarray, side: str) -> Frames:
    """ISB tibia/fibula with the origin at the knee centre: v from the ankle centre
    (mid-malleoli) to the knee centre, u ⟂ to the plane of v and the malleoli, w = u × v."""
    ankle = 0.5 * (lateral_malleolus + medial_malleolus)
    return _frames(knee, None, knee - ankle,
                   _lateral_to_right(lateral_malleolus, medial_malleolus, side))


def foot_frames_from_toe(ankle: np.ndarray, knee: np.ndarray, heel: np.ndarray,
                         toe: np.ndarray) -> Frames:
    """Foot from one forefoot marker (the Helen Hayes set's 2nd metatarsal head), origin at the
    ankle centre: u from the heel to the toe marker, v ⟂ u in the plane of u and the shank's
    long axis (ankle to knee centre; superior), w = u × v (right). The set has no transverse
    forefoot landmark, so the foot's roll about its long axis comes from the shank, as in
    Plug-in Gait, whose foot frame lies in the plane of the toe marker, the ankle and the knee
    centres (Vicon, Plug-in Gait Reference Guide); the calibration posture has no inversion."""
    u = _unit(toe - heel)
    up = knee - ankle
    v = _unit(up - np.sum(up * u, axis=1, keepdims=True) * u)
    return Frames(ankle, np.stack([u, v, np.cross(u, v)], axis=2))


def foot_frames(ankle: np.ndarray, heel: np.ndarray, first_metatarsal: np.ndarray,
                fifth_metatarsal: np.ndarray, side: str) -> Frames:
    """Foot with the origin at the ankle centre: u from the heel to the mid-metatarsal heads,
    v ⟂ to the plane of u and the metatarsal heads (superior), w = u × v (right)."""
    u = _unit(0.5 * (first_metatarsal + fifth_metatarsal) - heel)
    right = _lateral_to_right(fifth_metatarsal, first_metatarsal, side)
    v = _unit(np.cross(right, u))
    return Frames(ankle, np.stack([u, v, np.cross(u, v)], axis=2))

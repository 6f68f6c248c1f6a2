"""Is a calibration a person? Segment lengths and the calibration pose, checked against what
bodies do, each implausibility naming the landmarks that build the segment at fault.

A marker on the wrong face of a segment (a tibia wand put medially, left and right wands
swapped, a knee marker on the other condyle) still gives a right-handed frame, and calibration
averages it without complaint; the walking trial then comes out with, say, knee flexion of the
wrong sign. What gives it away is the pose: the frames of neighbouring segments are twisted
about the distal segment's long axis by an angle no joint and no bone torsion reaches. So the
calibration frames' mean pose is read as each joint's twist (the proximal segment's
medio-lateral axis against the distal one's, about the distal long axis: femoral anteversion
and hip rotation at the hip, tibial torsion and knee rotation at the knee) and flexion (the
long axes in the proximal segment's sagittal plane), and the segment lengths against adult and
child anthropometry:

==================================  ============================  ==================
quantity                             what bodies reach              flagged beyond
==================================  ============================  ==================
twist pelvis → thigh (hip)           hip rotation ±45°, anteversion  ±``TWIST_DEG``
twist thigh → shank (knee)           tibial torsion 10–40°,         ±``TWIST_DEG``
                                     knee rotation ±30°
knee flexion                         −10° … 140°                    ``KNEE_FLEXION_DEG``
thigh, shank length (hip–knee,       children 0.2 m … adults 0.55 m ``SEGMENT_M``
knee–ankle)
foot length (heel–toe)               0.10 … 0.32 m                  ``FOOT_M``
left against right                   within a few per cent          ``ASYMMETRY``
==================================  ============================  ==================

The thresholds sit well outside what the clean calibrations of the project's trials reach
(README, "What fccgrb checks for you"); a tibia wand misplaced onto the wrong face builds the
shank frame 125° from the thigh's.
"""

from __future__ import annotations

import numpy as np

from fccgrb_cli.anatomy.frames import Frames

TWIST_DEG = 70.0
KNEE_FLEXION_DEG = (-25.0, 100.0)
SEGMENT_M = (0.15, 0.65)
FOOT_M = (0.08, 0.35)
ASYMMETRY = 0.15
SIDES = {"r": "right", "l": "left"}


def twist(proximal: Frames, distal: Frames) -> np.ndarray:
    """Per frame, the angle (deg) from the proximal segment's medio-lateral axis w to the
    distal one's about the distal long axis v (both projected onto the plane ⟂ v)."""
    v = distal.axes[:, :, 1]
    a = proximal.axes[:, :, 2] - np.sum(proximal.axes[:, :, 2] * v, axis=1, keepdims=True) * v
    b = distal.axes[:, :, 2]
    return np.degrees(np.arctan2(np.sum(np.cross(a, b) * v, axis=1), np.sum(a * b, axis=1)))


def flexion(proximal: Frames, distal: Frames) -> np.ndarray:
    """Per frame, the angle (deg) from the proximal long axis to the distal one in the proximal
    segment's sagittal plane (⟂ its w), positive when the distal segment's end swings back
    (knee flexion)."""
    w = proximal.axes[:, :, 2]
    a = proximal.axes[:, :, 1]
    b = distal.axes[:, :, 1] - np.sum(distal.axes[:, :, 1] * w, axis=1, keepdims=True) * w
    return np.degrees(np.arctan2(np.sum(np.cross(b, a) * w, axis=1), np.sum(a * b, axis=1)))


def _mean_angle(degrees: np.ndarray) -> float:
    radians = np.radians(degrees)
    return float(np.degrees(np.arctan2(np.nanmean(np.sin(radians)), np.nanmean(np.cos(radians)))))


def pose(frames: dict[str, Frames]) -> dict[str, float]:
    """The calibration pose's twists at hip and knee and the knee's flexion (deg, mean over the
    frames), by ``<joint>_twist_<side>`` and ``knee_flexion_<side>``; a twist's sign is the
    right side's (external tibial torsion negative on both)."""
    out = {}
    for s in SIDES:
        pelvis, thigh, shank = frames["pelvis"], frames[f"thigh_{s}"], frames[f"shank_{s}"]
        # the left side's frames are mirrored: w points right on both, so a twist's sign flips
        sign = 1.0 if s == "r" else -1.0
        out[f"hip_twist_{s}"] = sign * _mean_angle(twist(pelvis, thigh))
        out[f"knee_twist_{s}"] = sign * _mean_angle(twist(thigh, shank))
        out[f"knee_flexion_{s}"] = _mean_angle(flexion(thigh, shank))
    return out


def implausibilities(frames: dict[str, Frames], lengths: dict[str, float],
                     builders: dict[str, str]) -> list[str]:
    """What is implausible in a calibration: ``frames`` by body (pelvis, thigh_r, …), the
    measured ``lengths`` (m, by body) and, by body, the landmarks (the trial's labels) its frame
    is built from, which each message names."""
    out = []
    measured = pose(frames)
    for s, side in SIDES.items():
        for name, angle, body in (("hip", measured[f"hip_twist_{s}"], f"thigh_{s}"),
                                  ("knee", measured[f"knee_twist_{s}"], f"shank_{s}")):
            if abs(angle) > TWIST_DEG:
                segment = body.split("_")[0]
                out.append(f"the {side} {segment}'s frame is turned {angle:.0f}° about its long "
                           f"axis from the {'pelvis' if name == 'hip' else 'thigh'}'s (at the "
                           f"{name}; bodies reach ±{TWIST_DEG:g}°): check the {side} "
                           f"{segment}'s markers {builders.get(body, '')} (a wand on the "
                           "wrong face, left and right swapped)")
        knee = measured[f"knee_flexion_{s}"]
        low, high = KNEE_FLEXION_DEG
        if not low <= knee <= high:
            out.append(f"the {side} knee is flexed {knee:.0f}° in the calibration pose "
                       f"(expected {low:g}…{high:g}°): check the markers "
                       f"{builders.get(f'thigh_{s}', '')}, {builders.get(f'shank_{s}', '')}")
    for body, length in lengths.items():
        low, high = FOOT_M if body.startswith("foot") else SEGMENT_M
        if not low <= length <= high:
            out.append(f"{body} is {1e3 * length:.0f} mm long (expected {1e3 * low:.0f}–"
                       f"{1e3 * high:.0f} mm): check the markers {builders.get(body, '')}")
    for segment in ("thigh", "shank", "foot"):
        right, left = lengths.get(f"{segment}_r"), lengths.get(f"{segment}_l")
        if right and left and abs(right - left) > ASYMMETRY * max(right, left):
            longer = "r" if right > left else "l"
            out.append(f"the {segment}s differ by {1e3 * abs(right - left):.0f} mm (right "
                       f"{1e3 * right:.0f}, left {1e3 * left:.0f}; more than "
                       f"{100 * ASYMMETRY:.0f} %): check the markers "
                       f"{builders.get(f'{segment}_{longer}', '')}")
    return out

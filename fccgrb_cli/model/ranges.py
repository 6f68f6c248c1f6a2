"""Physiological ranges of the clinical joint angles: beyond them a solved angle is not a
posture a person takes, and the frame is flagged (solvers/quality.py, ``angle_range``).

The ranges are the normal active ranges of motion of adults (AAOS; Soucie et al. 2011,
Haemophilia 17:500–507; Roaas & Andersson 1982, Acta Orthop Scand 53:205–208), widened by a
margin for children, for passive range and for the models' own definitions (the Helen Hayes
set cannot see the foot's roll, so its ankle inversion wanders further than a goniometer's):

============================  ====================  ============================
clinical angle (deg, + is)    normal range of motion  range used (deg)
============================  ====================  ============================
hip_flexion (flexion)          −30 … 120–140          −50 … 150
hip_adduction (adduction)      −45 … 30               −60 … 45
hip_rotation (internal)        −45 … 45               −70 … 70
knee_flexion (flexion)         −10 … 140–150          −25 … 160
ankle_dorsiflexion (dorsi.)    −50 … 20               −70 … 50
ankle_inversion (inversion)    −20 … 35               −75 … 75
============================  ====================  ============================

Clean walking and turning trials reach well inside them (README, "What fccgrb checks for
you"). An angle names its own range in the model file (``clinical: {sign: 1, range_deg:
[min, max]}``), which replaces the table's; an angle of another name has none unless it
declares one. The side suffix (``_r``, ``_l``, ``_right``, ``_left``) is not part of the name
looked up.
"""

from __future__ import annotations

PHYSIOLOGICAL_DEG: dict[str, tuple[float, float]] = {
    "hip_flexion": (-50.0, 150.0),
    "hip_adduction": (-60.0, 45.0),
    "hip_rotation": (-70.0, 70.0),
    "knee_flexion": (-25.0, 160.0),
    "ankle_dorsiflexion": (-70.0, 50.0),
    "ankle_inversion": (-75.0, 75.0),
}
SIDE_SUFFIXES = ("_right", "_left", "_r", "_l")


def physiological_range(name: str) -> tuple[float, float] | None:
    """The table's range (deg) for a clinical angle's name, side suffix dropped; None when the
    table has none."""
    for suffix in SIDE_SUFFIXES:
        if name.endswith(suffix):
            name = name[: -len(suffix)]
            break
    return PHYSIOLOGICAL_DEG.get(name)

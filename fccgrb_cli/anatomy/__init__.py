"""Anatomy for personalized models: ISB segment frames from landmarks, a hip-joint-centre
regression, Davis' chord construction of the knee and ankle centres, de Leva's segment inertia,
and the calibration that writes a subject's model."""

from fccgrb_cli.anatomy.anthropometry import SEGMENTS, segment_inertia
from fccgrb_cli.anatomy.frames import (
    Frames,
    chord_joint_centre,
    foot_frames,
    foot_frames_from_toe,
    harrington_hip_centre,
    pelvis_frames,
    shank_frames,
    thigh_frames,
)

__all__ = ["SEGMENTS", "Frames", "chord_joint_centre", "foot_frames", "foot_frames_from_toe",
           "harrington_hip_centre", "pelvis_frames", "segment_inertia", "shank_frames",
           "thigh_frames"]

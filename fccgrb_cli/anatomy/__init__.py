"""Anatomy for personalized models: ISB segment frames from landmarks, a hip-joint-centre
regression, de Leva's segment inertia, and the calibration that writes a subject's model."""

from fccgrb_cli.anatomy.anthropometry import SEGMENTS, segment_inertia
from fccgrb_cli.anatomy.frames import (
    Frames,
    foot_frames,
    harrington_hip_centre,
    pelvis_frames,
    shank_frames,
    thigh_frames,
)

__all__ = ["SEGMENTS", "Frames", "foot_frames", "harrington_hip_centre", "pelvis_frames",
           "segment_inertia", "shank_frames", "thigh_frames"]

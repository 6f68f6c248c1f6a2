"""The model: a validated, immutable description of a multibody system (YAML in)."""

from fccgrb_cli.model.elements import (
    GROUND,
    AngularCoordinate,
    Body,
    CalibrationRecord,
    Coordinate,
    DistanceCoordinate,
    Ground,
    Inertia,
    Joint,
    Model,
    Point,
    Pose,
    TrackedPoint,
    TrackedVector,
    Vector,
)
from fccgrb_cli.model.loader import load_model, parse_model
from fccgrb_cli.model.motion import BaseMotion, Motion

__all__ = [
    "GROUND",
    "AngularCoordinate",
    "BaseMotion",
    "Body",
    "CalibrationRecord",
    "Coordinate",
    "DistanceCoordinate",
    "Ground",
    "Inertia",
    "Joint",
    "Model",
    "Motion",
    "Point",
    "Pose",
    "TrackedPoint",
    "TrackedVector",
    "Vector",
    "load_model",
    "parse_model",
]

"""Segment inertia from de Leva (1996), J Biomech 29:1223–1230, Table 4 (adult males).

Each segment's mass is a fraction of body mass, its centre of mass a fraction of its length
from the proximal end, and its radii of gyration fractions of its length about the sagittal
(antero-posterior), transverse (medio-lateral) and longitudinal axes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Segment:
    """de Leva's parameters: mass fraction, CoM fraction of the length from the proximal end,
    radii of gyration (sagittal, transverse, longitudinal) as fractions of the length."""

    mass: float
    com: float
    radii: tuple[float, float, float]


SEGMENTS: dict[str, Segment] = {
    "thigh": Segment(0.1416, 0.4095, (0.329, 0.329, 0.149)),
    "shank": Segment(0.0433, 0.4459, (0.255, 0.249, 0.103)),
    "foot": Segment(0.0137, 0.4415, (0.257, 0.245, 0.124)),
    "pelvis": Segment(0.1117, 0.6115, (0.615, 0.551, 0.587)),
}


def segment_inertia(segment: str, body_mass: float, length: float,
                    long_axis: int = 1) -> tuple[float, np.ndarray]:
    """Mass (kg) and principal moments about the CoM along (u, v, w) (kg·m²) of a segment of
    the given length, with u antero-posterior, w medio-lateral and ``long_axis`` the index of
    the longitudinal axis (1 = v for the leg segments, 0 = u for the foot)."""
    s = SEGMENTS[segment]
    mass = s.mass * body_mass
    sagittal, transverse, longitudinal = (mass * (r * length) ** 2 for r in s.radii)
    if long_axis == 0:
        return mass, np.array([longitudinal, sagittal, transverse])
    return mass, np.array([sagittal, longitudinal, transverse])

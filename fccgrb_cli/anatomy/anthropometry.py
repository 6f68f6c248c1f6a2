"""Segment inertia from de Leva (1996), J Biomech 29:1223–1230, Table 4 (adult males).

Each segment's mass is a fraction of body mass, its centre of mass a fraction of its length
from the proximal end, and its radii of gyration fractions of its length about the sagittal
(antero-posterior), transverse (medio-lateral) and longitudinal axes. The head is Table 4's
second definition (vertex to C7, its CoM fraction counted from the vertex); the thorax is the
upper trunk (suprasternale to xiphoid) and the middle trunk (xiphoid to omphalion) together
(``anatomy.full_body``); the hand runs from the wrist centre to the 3rd metacarpal head.
``REFERENCE_LENGTHS`` are de Leva's male segment lengths (m), for segments whose ends no
marker shows.
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
    "head": Segment(0.0694, 0.5002, (0.303, 0.315, 0.261)),
    "upper_trunk": Segment(0.1596, 0.2999, (0.716, 0.454, 0.659)),
    "middle_trunk": Segment(0.1633, 0.4502, (0.482, 0.383, 0.468)),
    "upper_arm": Segment(0.0271, 0.5772, (0.285, 0.269, 0.158)),
    "forearm": Segment(0.0162, 0.4574, (0.276, 0.265, 0.121)),
    "hand": Segment(0.0061, 0.7900, (0.628, 0.513, 0.401)),
}
REFERENCE_LENGTHS: dict[str, float] = {
    "thigh": 0.4222, "shank": 0.4340, "head": 0.2429, "upper_trunk": 0.1707,
    "upper_arm": 0.2817, "forearm": 0.2689, "hand": 0.0862}


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


def principal(segment: str, body_mass: float, length: float) -> tuple[float, np.ndarray]:
    """Mass and the inertia tensor about the CoM (3 × 3, kg·m², body frame) of a segment whose
    long axis is v (:func:`segment_inertia`)."""
    mass, moments = segment_inertia(segment, body_mass, length)
    return mass, np.diag(moments)


def combine(parts: list[tuple[float, np.ndarray, np.ndarray]]
            ) -> tuple[float, np.ndarray, np.ndarray]:
    """One rigid body from parts (mass, CoM, inertia tensor about the part's CoM, all in one
    frame): the total mass, the mass-weighted CoM and the tensor about it by the parallel-axis
    theorem, I = Σ [I_k + m_k (|d_k|² 1 − d_k d_kᵀ)], d_k the part's CoM from the total's."""
    mass: float = sum(m for m, _, _ in parts)
    com = sum((m * np.asarray(c, float) for m, c, _ in parts), np.zeros(3)) / mass
    tensor = np.zeros((3, 3))
    for m, c, inertia in parts:
        d = np.asarray(c, float) - com
        tensor += inertia + m * (d @ d * np.eye(3) - np.outer(d, d))
    return mass, com, tensor

"""A synthetic whole body for the residual tests: configs/models/full_body.yaml with segment
inertia (de Leva's mass fractions of a 70 kg subject, CoMs along the template's segments),
every angle and the pelvis given a prescribed motion, and the external wrench that makes its
motion consistent, written here from Newton–Euler for each body (no K matrices, no multipliers):

    F = Σ_i m_i (a_Gi − g),   M_O = Σ_i [r_Gi × m_i (a_Gi − g) + I_i α_i + ω_i × I_i ω_i],

ω_i = ½ Σ_k e_k × ė_k and α_i = ½ Σ_k e_k × ë_k from the body's unit vectors e_k = u, v, w.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml

from fccgrb_cli.dynamics.loads import ExternalLoad
from fccgrb_cli.model import Model

ROOT = Path(__file__).resolve().parents[1]
TEMPLATE = ROOT / "configs" / "models" / "full_body.yaml"
BODY_MASS = 70.0
GRAVITY = np.array([0.0, 0.0, -9.81])

# body: (mass fraction, CoM (local, m), radii of gyration about u, v, w (m))
SEGMENTS = {
    "pelvis": (0.1117, [-0.048, -0.027, 0.0], [0.089, 0.085, 0.080]),
    "thigh": (0.1416, [0.0, -0.172, 0.0], [0.138, 0.063, 0.138]),
    "shank": (0.0433, [0.0, -0.183, 0.0], [0.105, 0.042, 0.102]),
    "foot": (0.0137, [0.05, -0.03, 0.0], [0.025, 0.051, 0.049]),
    "thorax": (0.3229, [-0.06, -0.19, 0.0], [0.150, 0.115, 0.130]),
    "head": (0.0694, [0.0, -0.03, 0.0], [0.073, 0.063, 0.076]),
    "upper_arm": (0.0271, [0.0, -0.167, 0.0], [0.083, 0.046, 0.078]),
    "forearm": (0.0162, [0.0, -0.119, 0.0], [0.072, 0.031, 0.069]),
    "hand": (0.0061, [0.0, -0.063, 0.0], [0.050, 0.032, 0.041]),
}
# angle name (side removed) → (mean offset from 90 deg, amplitude deg)
MOTIONS = {
    "hip_flexion": (10, 25), "hip_adduction": (0, 10), "hip_rotation": (0, 15),
    "knee_flexion": (30, 25), "ankle_dorsiflexion": (0, 20), "ankle_inversion": (0, 15),
    "trunk_flexion": (0, 20), "trunk_lateral_bending": (0, 12), "trunk_rotation": (0, 20),
    "neck_flexion": (0, 12), "neck_lateral_bending": (0, 8), "neck_rotation": (0, 15),
    "shoulder_flexion": (0, 30), "shoulder_abduction": (10, 12), "shoulder_rotation": (0, 15),
    "elbow_flexion": (50, 35), "elbow_pronation": (60, 25), "wrist_flexion": (0, 20),
    "wrist_deviation": (0, 10),
}


def _segment(body: str) -> str:
    return body.rsplit("_", 1)[0] if body.endswith(("_r", "_l")) else body


# Trunk markers placed so that the ISB construction (anatomy.upper_body.thorax_frames) gives
# the thorax's own frame: mid(IJ, C7) straight above mid(PX, T8), all four in its sagittal plane.
ISB_TRUNK = {"SNJ": [0.0, 0.0, 0.0], "CV7": [-0.13, 0.0, 0.0], "SXS": [0.0, -0.17, 0.0],
             "TV8": [-0.13, -0.17, 0.0]}


def acromion_height(hang: float, lateral: float) -> float:
    """How far above the shoulder centre an acromion marker sits for Rab et al.'s (2002) rule
    (the centre 17 % of the acromion–lateral epicondyle distance below it) to hold with the arm
    hanging along the thorax: s = 0.17 √((s + hang)² + lateral²), by fixed-point iteration."""
    s = 0.0
    for _ in range(100):
        s = 0.17 * np.hypot(s + hang, lateral)
    return float(s)


def full_body_text(seed: int = 0, mass_scale: dict[str, float] | None = None,
                   static: bool = False) -> str:
    """The template with inertia (masses times ``mass_scale``'s factor per body), seeded
    motions for every angle and a pelvis motion (``static``: every angle held at 90°, the
    template's anatomical posture, the pelvis still), the trunk markers of ISB_TRUNK and
    acromion markers (R_SAJ, L_SAJ) on the thorax where Rab et al.'s rule puts the shoulder
    centres."""
    rng = np.random.default_rng(seed)
    doc = yaml.safe_load(TEMPLATE.read_text())
    thorax = doc["bodies"]["thorax"]["points"]
    thorax.update(ISB_TRUNK)
    for s, label in (("r", "R_SAJ"), ("l", "L_SAJ")):
        elbow = doc["bodies"][f"upper_arm_{s}"]["points"]
        hang, lateral = -elbow["EJC"][1], abs(elbow[f"{label[0]}_HLE"][2])
        gh = np.array(thorax[f"GH_{s}"])
        thorax[label] = (gh + np.array([0.0, acromion_height(hang, lateral), 0.0])).tolist()
        doc["tracking"]["points"].append({"marker": label, "point": f"thorax.{label}"})
    for name, spec in doc["bodies"].items():
        fraction, com, radii = SEGMENTS[_segment(name)]
        mass = float(fraction * BODY_MASS * (mass_scale or {}).get(name, 1.0))
        spec.update(mass=mass, com=com, inertia=[mass * r**2 for r in radii])
    for angle in doc["angles"]:
        base = angle["name"].removesuffix("_r").removesuffix("_l")
        offset, amplitude = MOTIONS[base]
        sign = angle["clinical"]["sign"]
        angle["motion"] = {"mean": 90 + (0 if static else sign * offset),
                           "terms": [] if static else [
            {"amplitude": amplitude, "frequency": float(rng.uniform(0.6, 1.9)),
             "phase": float(rng.uniform(0, 360))},
            {"amplitude": 0.3 * amplitude, "frequency": float(rng.uniform(2.0, 3.5)),
             "phase": float(rng.uniform(0, 360))}]}
    if static:
        doc.pop("loads", None)
        return yaml.safe_dump(doc, sort_keys=False)
    doc["bodies"]["pelvis"]["motion"] = {
        "translation": [{"mean": 0, "terms": [{"amplitude": 0.25, "frequency": 0.5}]},
                        {"mean": 0, "terms": [{"amplitude": 0.03, "frequency": 0.9,
                                               "phase": 40}]},
                        {"mean": 0, "terms": [{"amplitude": 0.03, "frequency": 1.7}]}],
        "rotation": [{"mean": 0, "terms": [{"amplitude": 6, "frequency": 0.8}]},
                     {"mean": 0, "terms": [{"amplitude": 5, "frequency": 1.1, "phase": 30}]},
                     {"mean": 0, "terms": [{"amplitude": 10, "frequency": 0.9, "phase": 70}]}]}
    doc.pop("loads", None)
    return yaml.safe_dump(doc, sort_keys=False)


def newton_euler(model: Model, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
    """The external force and its moment about the global origin (frames × 3 each) that the
    motion needs (module docstring); fully-defined bodies in model order in q."""
    force = np.zeros((len(q), 3))
    moment = np.zeros((len(q), 3))
    for k, body in enumerate(model.bodies):
        block = slice(12 * k, 12 * k + 12)
        x, xd, xdd = (a[:, block].reshape(-1, 4, 3) for a in (q, qd, qdd))
        c = np.array(body.inertia.com)
        m = body.inertia.mass
        r_g = x[:, 0] + np.einsum("j,fjc->fc", c, x[:, 1:])
        a_g = xdd[:, 0] + np.einsum("j,fjc->fc", c, xdd[:, 1:])
        omega = 0.5 * np.cross(x[:, 1:], xd[:, 1:]).sum(axis=1)
        alpha = 0.5 * np.cross(x[:, 1:], xdd[:, 1:]).sum(axis=1)
        R = x[:, 1:].transpose(0, 2, 1)  # columns u, v, w
        inertia = R @ np.array(body.inertia.tensor) @ R.transpose(0, 2, 1)
        spin = np.einsum("fij,fj->fi", inertia, alpha) + np.cross(
            omega, np.einsum("fij,fj->fi", inertia, omega))
        f = m * (a_g - GRAVITY)
        force += f
        moment += np.cross(r_g, f) + spin
    return force, moment


def wrench_load(body: str, point: np.ndarray, force: np.ndarray, moment: np.ndarray
                ) -> ExternalLoad:
    """The wrench (force, moment about the origin) as a load on ``body``: the force at
    ``point`` (frames × 3) and the free moment that keeps the total."""
    return ExternalLoad("wrench", body, force, point, moment - np.cross(point, force))

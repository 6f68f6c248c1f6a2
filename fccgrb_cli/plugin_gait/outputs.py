"""A run's outputs in Plug-in Gait's conventions, for a model calibrated as Plug-in Gait
(``calibration.method: plugin-gait``): the angles (gait/plugin_gait.py) from the solved segment
frames, and with the dynamics the joint moments and powers (gait/plugin_gait_kinetics.py) from
the classical model's motion and the force plates. Each output is frames × 3 under Plug-in
Gait's name; frames the quality checks do not trust keep their values (the run's ``trusted``
says which; exports mark them), frames not solved are NaN. On a full-body trial, the upper
body's angles (plugin_gait/upper.py: ``LThoraxAngles`` … ``RWristAngles``) join them, built
frame by frame from the trial's markers as Vicon builds them (its spine from the solved
pelvis), where the subject's measurements give the arms' and the trial has the markers; a
frame where a marker is missing is NaN there.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fccgrb_cli.dynamics.convert import Dynamics
from fccgrb_cli.model import Model
from fccgrb_cli.model.subject import PIG_KEYS
from fccgrb_cli.plugin_gait.angles import pig_angles, pig_axes, progression_frame
from fccgrb_cli.plugin_gait.kinetics import leg_kinetics, segment_motion
from fccgrb_cli.plugin_gait.upper import MARKERS as UPPER_MARKERS
from fccgrb_cli.plugin_gait.upper import UpperGeometry, segments
from fccgrb_cli.plugin_gait.upper import upper_angles as upper_body_angles
from fccgrb_cli.system.layout import build_layout

UNITS = {"angles": "deg", "moments": "N.mm/kg", "powers": "W/kg"}
# Each joint centre's body and point. Plug-in Gait's knee centre is the chord point built from
# the thigh's markers, and its tibia starts there every frame (its length follows the skin); here
# that point is the thigh's KJC, which the knee's slide keeps on the tibia's long axis (the
# shank's KJC is where the static put the tibia's origin, millimetres away along that axis).
JOINT_POINTS = {"hip": ("thigh", "HJC"), "knee": ("thigh", "KJC"), "ankle": ("foot", "AJC")}


@dataclass(frozen=True)
class PluginGaitResults:
    """Plug-in Gait's outputs (name → frames × 3): angles (deg), moments (N·mm/kg) and powers
    (W/kg, in Z); the progression frame's axes (3 × 3, columns x, y, z in the laboratory)."""

    angles: dict[str, np.ndarray]
    moments: dict[str, np.ndarray]
    powers: dict[str, np.ndarray]
    progression: np.ndarray

    def kinds(self) -> dict[str, dict[str, np.ndarray]]:
        """Each kind of output ('angles', 'moments', 'powers') with its curves."""
        return {"angles": self.angles, "moments": self.moments, "powers": self.powers}


def _body_coordinates(model: Model, q: np.ndarray) -> dict[str, np.ndarray]:
    """Each body's fully-defined coordinates [r, u, v, w] per frame (frames × 12)."""
    layout = build_layout(model, tuple(a.name for a in model.angles))
    out = {}
    for body in model.bodies:
        x = np.asarray(q[:, layout.q_slice(body.name)], dtype=float)
        if x.shape[1] == 9:  # reduced: w = u × v
            x = np.concatenate([x, np.cross(x[:, 3:6], x[:, 6:9])], axis=1)
        out[body.name] = x
    return out


def _axes(x: np.ndarray) -> np.ndarray:
    return np.stack([x[:, 3:6], x[:, 6:9], x[:, 9:12]], axis=2)


def _point(model: Model, x: np.ndarray, body: str, point: str) -> np.ndarray:
    local = np.array(model.body(body).points[point].local)
    return x[:, :3] + _axes(x) @ local


def upper_geometry(model: Model) -> UpperGeometry | None:
    """The subject's upper-body measurements from the model's ``subject:`` section (the marker
    radius Plug-in Gait's 7 mm without a diameter, the head offset 0), or None when a side's
    shoulder offset, elbow or wrist width or hand thickness is not given."""
    m = model.measurements
    sided = (m.shoulder_offset, m.elbow_width, m.wrist_width, m.hand_thickness)
    values = [{s: v for s in "lr" if (v := q.side(s)) is not None} for q in sided]
    if any(len(side) < 2 for side in values):
        return None
    shoulder, elbow, wrist, hand = values
    diameter = m.marker_diameter if m.marker_diameter is not None else 0.014
    return UpperGeometry(diameter / 2.0, m.head_offset or 0.0, shoulder, elbow, wrist, hand)


def upper_body_missing(model: Model, labels: tuple[str, ...]) -> str | None:
    """Why a trial with Plug-in Gait's upper-body markers (all of ``UPPER_MARKERS`` among
    ``labels``) gets no upper-body angles — the subject's measurements lacking an arm's — or
    None (they are computed, or the trial is not a full-body one)."""
    if any(label not in labels for label in UPPER_MARKERS) or upper_geometry(model):
        return None
    m = model.measurements
    absent = [f"{side}{q.vicon}" for name, q in PIG_KEYS.items()
              if name in ("shoulder_offset", "elbow_width", "wrist_width", "hand_thickness")
              for s, side in (("l", "Left"), ("r", "Right")) if getattr(m, name).side(s) is None]
    return (f"{model.source}: the trial has Plug-in Gait's upper-body markers but the subject's "
            f"measurements lack {', '.join(absent)} (calibrate with --subject a .vsk or .mp that "
            "gives them): no upper-body angles")


def upper_angles(model: Model, markers: dict[str, np.ndarray], pelvis: np.ndarray,
                 progression: np.ndarray) -> dict[str, np.ndarray]:
    """The upper body's Plug-in Gait angles from the trial's ``markers`` (label → frames × 3,
    m) and the solved pelvis's axes (frames × 3 × 3, u, v, w), or none when the trial lacks
    one of ``UPPER_MARKERS`` or the subject's measurements lack the arms'."""
    geometry = upper_geometry(model)
    if geometry is None or any(label not in markers for label in UPPER_MARKERS):
        return {}
    axes, _ = segments({k: markers[k] for k in UPPER_MARKERS}, geometry)
    return upper_body_angles({**axes, "pelvis": pig_axes(pelvis)}, progression)


def plugin_gait_results(model: Model, q: np.ndarray, trusted: np.ndarray,
                        dynamics: Dynamics | None,
                        markers: dict[str, np.ndarray] | None = None) -> PluginGaitResults:
    """The outputs of a run of a Plug-in Gait model: its solved coordinates ``q`` (frames ×
    nq), which frames are trusted, its dynamics (None: angles only), and the trial's markers
    (label → frames × 3, m, the frames of ``q``; the upper body's angles where they allow:
    :func:`upper_angles`)."""
    x = _body_coordinates(model, q)
    up = -np.asarray(model.gravity) / np.linalg.norm(model.gravity)
    frames = {name: _axes(value) for name, value in x.items()}
    pelvis = np.where(trusted[:, None], x["pelvis"][:, :3], np.nan)
    lab = progression_frame(pelvis, frames["pelvis"][trusted, :, 0], up)
    torsion = {"l": model.measurements.tibial_torsion.left or 0.0,
               "r": model.measurements.tibial_torsion.right or 0.0}
    angles = pig_angles(frames, torsion, lab)
    if markers:
        angles.update(upper_angles(model, markers, frames["pelvis"], lab))
    moments: dict[str, np.ndarray] = {}
    powers: dict[str, np.ndarray] = {}
    if dynamics is not None and model.subject_mass is not None:
        moments, powers = _kinetics(model, dynamics, model.subject_mass)
    return PluginGaitResults(angles, moments, powers, lab)


def _kinetics(model: Model, dynamics: Dynamics, body_mass: float
              ) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    kin = dynamics.kinematics
    x, xd, xdd = (_body_coordinates(model, np.asarray(values))
                  for values in (kin.q, kin.qd, kin.qdd))
    segments = {}
    for body in model.bodies:
        inertia = body.inertia
        assert inertia is not None  # the inverse dynamics that gave ``dynamics`` required it
        segments[body.name] = segment_motion(x[body.name], xd[body.name], xdd[body.name],
                                             np.array(inertia.com), np.array(inertia.tensor),
                                             inertia.mass)
    gravity = np.asarray(model.gravity)
    moments: dict[str, np.ndarray] = {}
    powers: dict[str, np.ndarray] = {}
    for s, prefix in (("l", "L"), ("r", "R")):
        chain = {"pelvis": segments["pelvis"], **{seg: segments[f"{seg}_{s}"]
                                                  for seg in ("thigh", "shank", "foot")}}
        centres = {joint: _point(model, x[f"{seg}_{s}"], f"{seg}_{s}", point)
                   for joint, (seg, point) in JOINT_POINTS.items()}
        loads = [(load.force, load.point, load.moment) for load in dynamics.loads
                 if load.body == f"foot_{s}"]
        leg = leg_kinetics(chain, centres, s, loads, (gravity, body_mass))
        for joint in ("Hip", "Knee", "Ankle"):
            moments[f"{prefix}{joint}Moment"] = leg.moments[joint]
            powers[f"{prefix}{joint}Power"] = leg.powers[joint]
    return moments, powers

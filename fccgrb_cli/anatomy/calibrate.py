"""Personalize a lower-limb template from marker data (``fccgrb calibrate``).

Over the chosen frames, each segment's ISB frame is built from its landmarks every frame; joint
centres come from the landmarks (the hip from Harrington et al.'s regression in the pelvis
frame, the knee and ankle midway between the epicondyles and the malleoli); every tracked
marker, joint centre and joint vector is then the mean of its local coordinates over the frames.
Segment inertia follows de Leva (1996), scaled by body mass and the measured segment lengths.
The template's joints, angles and tracking are kept; its numbers are replaced.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import yaml

from fccgrb_cli.anatomy.anthropometry import SEGMENTS, segment_inertia
from fccgrb_cli.anatomy.frames import (
    Frames,
    foot_frames,
    harrington_hip_centre,
    pelvis_frames,
    shank_frames,
    thigh_frames,
)
from fccgrb_cli.errors import InputError
from fccgrb_cli.io.trial import Trial
from fccgrb_cli.model import Model

SIDES = {"r": "right", "l": "left"}
LANDMARKS = ("right_asis", "left_asis", "right_psis", "left_psis", *(
    f"{side}_{name}" for side in SIDES.values() for name in (
        "lateral_epicondyle", "medial_epicondyle", "lateral_malleolus", "medial_malleolus",
        "heel", "first_metatarsal", "fifth_metatarsal")))
BODIES = ("pelvis", *(f"{seg}_{s}" for s in SIDES for seg in ("thigh", "shank", "foot")))
PELVIS_LENGTH_PER_WIDTH = 0.6  # de Leva's lower-trunk length (145.7 mm) over a typical ASIS width


@dataclass(frozen=True)
class Calibration:
    """The personalized model text and what was measured (metres, kg)."""

    text: str
    frames: tuple[int, int]
    lengths: dict[str, float]
    pelvis_width: float
    pelvis_depth: float
    mass: float | None


def _landmarks(model: Model, trial: Trial, frames: slice) -> dict[str, np.ndarray]:
    missing = [name for name in LANDMARKS if name not in model.landmarks]
    if missing:
        raise InputError(f"{model.source}: calibration.landmarks: expected the landmarks "
                         f"{', '.join(missing)} mapped to trial labels")
    out = {}
    for name in LANDMARKS:
        out[name] = _marker(trial, model.landmarks[name], frames,
                            f"{model.source} calibration.landmarks.{name}")
    return out


def _marker(trial: Trial, label: str, frames: slice, used_by: str) -> np.ndarray:
    found = trial.find(label)
    if found is None:
        raise InputError(f"{trial.path}: expected the marker {label} (used by {used_by})")
    xyz = trial.select([found])[frames, 0]
    if np.isnan(xyz).all(axis=1).any():
        first = int(np.flatnonzero(np.isnan(xyz).any(axis=1))[0]) + (frames.start or 0)
        raise InputError(f"{trial.path}: frame index {first}: expected the marker {label} "
                         f"(used by {used_by}); choose calibration frames without gaps "
                         "(--frames A:B)")
    return xyz


def segment_frames(lm: dict[str, np.ndarray]) -> tuple[dict[str, Frames], float, float]:
    """Every body's anatomical frames over the calibration frames, pelvic width and depth."""
    pelvis = pelvis_frames(lm["right_asis"], lm["left_asis"], lm["right_psis"], lm["left_psis"])
    width = float(np.mean(np.linalg.norm(lm["right_asis"] - lm["left_asis"], axis=1)))
    depth = float(np.mean(np.linalg.norm(
        pelvis.origin - 0.5 * (lm["right_psis"] + lm["left_psis"]), axis=1)))
    out = {"pelvis": pelvis}
    for s, side in SIDES.items():
        hip = pelvis.origin + pelvis.axes @ harrington_hip_centre(width, depth, s)
        lat_e, med_e = lm[f"{side}_lateral_epicondyle"], lm[f"{side}_medial_epicondyle"]
        lat_m, med_m = lm[f"{side}_lateral_malleolus"], lm[f"{side}_medial_malleolus"]
        out[f"thigh_{s}"] = thigh_frames(hip, lat_e, med_e, s)
        out[f"shank_{s}"] = shank_frames(0.5 * (lat_e + med_e), lat_m, med_m, s)
        out[f"foot_{s}"] = foot_frames(0.5 * (lat_m + med_m), lm[f"{side}_heel"],
                                       lm[f"{side}_first_metatarsal"],
                                       lm[f"{side}_fifth_metatarsal"], s)
    return out, width, depth


def _perpendicular(vector: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """The unit vector of ``vector``'s part perpendicular to the unit ``axis``."""
    p = vector - (vector @ axis) * axis
    return p / np.linalg.norm(p)


def _round(values, digits: int) -> list[float]:
    return [round(float(x), digits) + 0.0 for x in values]


def _significant(value: float) -> float:
    return float(f"{value:.6g}")


def _pose(frames: Frames) -> dict:
    axes = frames.axes[0]
    return {"r": _round(frames.origin[0], 6), "u": _round(axes[:, 0], 9),
            "v": _round(axes[:, 1], 9), "w": _round(axes[:, 2], 9)}


def calibrate(model: Model, trial: Trial, frames: tuple[int, int] | None = None,
              mass: float | None = None) -> Calibration:
    """The template ``model`` personalized from ``trial`` over frame indices [A, B)."""
    if mass is not None and not (np.isfinite(mass) and mass > 0):
        raise InputError(f"--mass: expected a positive, finite body mass in kg, got {mass}")
    start, stop = frames if frames is not None else (0, trial.n_frames)
    if not 0 <= start < stop <= trial.n_frames:
        raise InputError(f"--frames: expected A:B with 0 ≤ A < B ≤ {trial.n_frames} (frame "
                         f"indices of {trial.path}), got {start}:{stop}")
    names = {b.name for b in model.bodies}
    absent = [b for b in BODIES if b not in names]
    if absent:
        raise InputError(f"{model.source}: bodies: expected the lower-limb bodies "
                         f"{', '.join(BODIES)}; missing {', '.join(absent)}")
    window = slice(start, stop)
    lm = _landmarks(model, trial, window)
    seg, width, depth = segment_frames(lm)
    doc = yaml.safe_load(model.text)
    points: dict[str, dict[str, list[float]]] = {b: {} for b in BODIES}
    vectors: dict[str, dict[str, list[float]]] = {b: {} for b in BODIES}
    lengths: dict[str, float] = {}
    inertia: dict[str, dict] = {}
    for s, side in SIDES.items():
        thigh, shank, foot = seg[f"thigh_{s}"], seg[f"shank_{s}"], seg[f"foot_{s}"]
        knee_local = thigh.mean_local(shank.origin)
        ankle_local = shank.mean_local(foot.origin)
        heel = foot.mean_local(lm[f"{side}_heel"])
        toes = foot.mean_local(0.5 * (lm[f"{side}_first_metatarsal"]
                                      + lm[f"{side}_fifth_metatarsal"]))
        points["pelvis"][f"HJC_{s}"] = harrington_hip_centre(width, depth, s)
        points[f"thigh_{s}"].update(HJC=np.zeros(3), KJC=knee_local)
        points[f"shank_{s}"].update(KJC=np.zeros(3), AJC=ankle_local)
        points[f"foot_{s}"]["AJC"] = np.zeros(3)
        knee_axis = shank.mean_direction(thigh.axes[:, :, 2])
        ankle_axis = foot.mean_direction(shank.axes[:, :, 2])
        arm = _perpendicular(np.array([1.0, 0.0, 0.0]), ankle_axis)
        vectors[f"shank_{s}"].update(
            knee_axis=knee_axis, knee_anterior=_perpendicular(np.array([1.0, 0.0, 0.0]),
                                                              knee_axis))
        vectors[f"foot_{s}"].update(ankle_arm=arm,
                                    ankle_up=_perpendicular(np.array([0.0, 1.0, 0.0]), arm))
        lengths.update({f"thigh_{s}": float(np.linalg.norm(knee_local)),
                        f"shank_{s}": float(np.linalg.norm(ankle_local)),
                        f"foot_{s}": float(np.linalg.norm(toes - heel))})
        if mass is not None:
            for name, origin_to_end, start_point, long_axis in (
                    (f"thigh_{s}", knee_local, np.zeros(3), 1),
                    (f"shank_{s}", ankle_local, np.zeros(3), 1),
                    (f"foot_{s}", toes - heel, heel, 0)):
                segment = name.split("_")[0]
                m, moments = segment_inertia(segment, mass, lengths[name], long_axis)
                com = start_point + SEGMENTS[segment].com * origin_to_end
                inertia[name] = {"mass": _significant(m), "com": _round(com, 5),
                                 "inertia": _round(moments, 7)}
    if mass is not None:
        m, moments = segment_inertia("pelvis", mass, PELVIS_LENGTH_PER_WIDTH * width)
        com = 0.5 * (points["pelvis"]["HJC_r"] + points["pelvis"]["HJC_l"])
        inertia["pelvis"] = {"mass": _significant(m), "com": _round(com, 5),
                             "inertia": _round(moments, 7)}
    for tp in model.tracked_points:
        if tp.body in seg:
            points[tp.body][tp.point] = seg[tp.body].mean_local(
                _marker(trial, tp.marker, window, f"{model.source} tracking.points"))
    for body in BODIES:
        spec = doc["bodies"][body]
        spec["points"] = {**spec.get("points", {}),
                          **{k: _round(v, 6) for k, v in points[body].items()}}
        if vectors[body]:
            spec["vectors"] = {**spec.get("vectors", {}),
                               **{k: _round(v, 9) for k, v in vectors[body].items()}}
        spec["pose"] = _pose(seg[body])
        for key in ("mass", "com", "inertia"):
            spec.pop(key, None)
        spec.update(inertia.get(body, {}))
    doc.pop("subject", None)
    if mass is not None:
        doc["subject"] = {"mass": mass}
    header = (f"# {doc.get('name', 'model')} personalized by `fccgrb calibrate` from {trial.path}, "
              f"frame indices {start}:{stop}\n# from the template {model.source}. Hip centres: "
              "Harrington et al. (2007); inertia: de Leva (1996)"
              f"{'' if mass is not None else ' (not computed: no --mass)'}.\n")
    text = header + yaml.safe_dump(doc, sort_keys=False, default_flow_style=None, width=100)
    return Calibration(text, (start, stop), lengths, width, depth, mass)

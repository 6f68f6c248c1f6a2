"""Personalize a lower-limb template from marker data (``fccgrb calibrate``).

Over the chosen frames, each segment's ISB frame is built from its landmarks every frame; joint
centres come from the landmarks; every tracked marker, joint centre and joint vector is then the
mean of its local coordinates over the frames. Segment inertia follows de Leva (1996), scaled by
body mass and the measured segment lengths. The template's joints, angles and tracking are kept;
its numbers are replaced.

The landmarks the template's ``calibration.landmarks`` maps choose the method:

* ``anatomical`` (ASIS, PSIS, both epicondyles, both malleoli, heel, 1st and 5th metatarsal
  heads): hip centres by Harrington et al. (2007), knee and ankle centres midway between the
  epicondyles and the malleoli.
* ``davis``, the Helen Hayes set (Kadaba et al. 1990; Davis et al. 1991), which has no medial
  and no PSIS markers (sacrum, ASIS, thigh wand, lateral knee, shank wand, lateral malleolus,
  heel, 2nd metatarsal head): the pelvis frame from the ASIS and the sacrum, which stands for
  the mid-PSIS point (Plug-in Gait's SACR does the same); hip centres by Harrington et al.
  (2007) with the pelvic depth to the sacrum (it was more accurate than Bell et al. 1990's and
  Davis et al. 1991's regressions in Harrington's own comparison, and needs no leg length);
  knee and ankle centres by Davis' chord construction from the knee and ankle widths and the
  marker diameter (:class:`Measurements`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import yaml

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
from fccgrb_cli.anatomy.lab_axes import LabAxes, lab_axes
from fccgrb_cli.anatomy.plausibility import implausibilities, pose
from fccgrb_cli.core.errors import InputError
from fccgrb_cli.model import Model
from fccgrb_cli.trial.record import Trial

SIDES = {"r": "right", "l": "left"}
LANDMARKS = ("right_asis", "left_asis", "right_psis", "left_psis", *(
    f"{side}_{name}" for side in SIDES.values() for name in (
        "lateral_epicondyle", "medial_epicondyle", "lateral_malleolus", "medial_malleolus",
        "heel", "first_metatarsal", "fifth_metatarsal")))
DAVIS_LANDMARKS = ("right_asis", "left_asis", "sacrum", *(
    f"{side}_{name}" for side in SIDES.values() for name in (
        "thigh_wand", "lateral_epicondyle", "shank_wand", "lateral_malleolus", "heel",
        "second_metatarsal")))
METHODS = {"anatomical": LANDMARKS, "davis": DAVIS_LANDMARKS}
# the landmarks each segment's frame is built from, by method (named by calibrate's warnings)
BUILDERS: dict[str, dict[str, tuple[str, ...]]] = {
    "anatomical": {"thigh": ("lateral_epicondyle", "medial_epicondyle"),
                   "shank": ("lateral_malleolus", "medial_malleolus"),
                   "foot": ("heel", "first_metatarsal", "fifth_metatarsal")},
    "davis": {"thigh": ("thigh_wand", "lateral_epicondyle"),
              "shank": ("shank_wand", "lateral_malleolus"),
              "foot": ("heel", "second_metatarsal")},
}
BODIES = ("pelvis", *(f"{seg}_{s}" for s in SIDES for seg in ("thigh", "shank", "foot")))
PELVIS_LENGTH_PER_WIDTH = 0.6  # de Leva's lower-trunk length (145.7 mm) over a typical ASIS width


@dataclass(frozen=True)
class Measurements:
    """The subject measurements Davis' joint centres need (m): knee width (across the femoral
    epicondyles), ankle width (across the malleoli) and the markers' diameter. The defaults
    (100, 70 and 14 mm: an adult's knee and ankle, a common marker) are stand-ins: measure the
    subject with a caliper, as Davis et al. (1991) and Plug-in Gait require."""

    knee_width: float = 0.100
    ankle_width: float = 0.070
    marker_diameter: float = 0.014

    @classmethod
    def from_mm(cls, knee_width: float | None = None, ankle_width: float | None = None,
                marker_diameter: float | None = None) -> Measurements:
        """From millimetres (None: the default), each checked against a plausible range (a
        value in cm or m by mistake falls outside it)."""
        given = {"knee_width": (knee_width, 40.0, 250.0),
                 "ankle_width": (ankle_width, 30.0, 200.0),
                 "marker_diameter": (marker_diameter, 0.0, 50.0)}
        out = {}
        for name, (value, low, high) in given.items():
            if value is None:
                continue
            if not (np.isfinite(value) and low <= value <= high):
                raise InputError(f"--{name.replace('_', '-')}: expected {low:g}–{high:g} mm, "
                                 f"got {value:g}")
            out[name] = 1e-3 * float(value)
        return cls(**out)

    def describe(self) -> str:
        return (f"knee width {1e3 * self.knee_width:g} mm, ankle width "
                f"{1e3 * self.ankle_width:g} mm, marker diameter {1e3 * self.marker_diameter:g} mm")


@dataclass(frozen=True)
class Calibration:
    """The personalized model text and what was measured (metres, kg); ``method`` is
    'anatomical' or 'davis', ``measurements`` the ones Davis' method used (else None);
    ``fit_mm``: how far the tracked markers strayed from their mean place in their segment over
    the frames (mean, largest; mm); ``warnings``: what is implausible (anatomy/plausibility.py),
    each naming the markers to check; ``pose``: its twists and knee flexion (deg,
    ``anatomy.plausibility.pose``)."""

    text: str
    frames: tuple[int, int]
    lengths: dict[str, float]
    pelvis_width: float
    pelvis_depth: float
    mass: float | None
    method: str = "anatomical"
    measurements: Measurements | None = None
    fit_mm: tuple[float, float] = (float("nan"), float("nan"))
    warnings: tuple[str, ...] = ()
    pose: dict[str, float] | None = None
    axes: LabAxes | None = None


def calibration_method(model: Model) -> str:
    """The method whose landmarks the template maps (anatomical when both are complete); an
    error names what the nearest one lacks."""
    for method, names in METHODS.items():
        if all(name in model.landmarks for name in names):
            return method
    nearest = max(METHODS, key=lambda m: sum(n in model.landmarks for n in METHODS[m]))
    missing = [name for name in METHODS[nearest] if name not in model.landmarks]
    raise InputError(f"{model.source}: calibration.landmarks: expected the landmarks "
                     f"{', '.join(missing)} mapped to trial labels (the {nearest} set; "
                     f"the other: {', '.join(n for n in METHODS if n != nearest)})")


def read_landmarks(model: Model, trial: Trial, frames: slice, names: tuple[str, ...],
                   mapping: dict[str, str]) -> dict[str, np.ndarray]:
    """Each named landmark's trajectory (frames × 3) over ``frames``, by the template's
    ``calibration.landmarks`` label (through ``mapping``)."""
    return {name: read_marker(trial, model.landmarks[name], frames,
                              f"{model.source} calibration.landmarks.{name}", mapping)
            for name in names}


def read_marker(trial: Trial, label: str, frames: slice, used_by: str,
                mapping: dict[str, str]) -> np.ndarray:
    """A marker's trajectory over ``frames``; an error names it (and ``used_by``) when it is
    absent or has a gap there."""
    wanted = mapping.get(label, label)
    found = trial.find(wanted)
    if found is None:
        mapped = f" (mapped from {label})" if wanted != label else ""
        raise InputError(f"{trial.path}: expected the marker {wanted}{mapped} (used by "
                         f"{used_by})")
    label = wanted
    xyz = trial.select([found])[frames, 0]
    if np.isnan(xyz).all(axis=1).any():
        first = int(np.flatnonzero(np.isnan(xyz).any(axis=1))[0]) + (frames.start or 0)
        raise InputError(f"{trial.path}: frame index {first}: expected the marker {label} "
                         f"(used by {used_by}); choose calibration frames without gaps "
                         "(--frames A:B)")
    return xyz


@dataclass(frozen=True)
class Anatomy:
    """Every body's anatomical frames over the calibration frames, pelvic width and depth (m),
    and each foot's heel and forefoot point (frames × 3), which measure its length."""

    frames: dict[str, Frames]
    width: float
    depth: float
    heel: dict[str, np.ndarray]
    toe: dict[str, np.ndarray]


def _pelvis(r_asis: np.ndarray, l_asis: np.ndarray, posterior: np.ndarray
            ) -> tuple[Frames, float, float]:
    """The pelvis frame, width (ASIS to ASIS) and depth (mid-ASIS to ``posterior``, the
    mid-PSIS point or the sacrum marker)."""
    pelvis = pelvis_frames(r_asis, l_asis, posterior, posterior)
    width = float(np.mean(np.linalg.norm(r_asis - l_asis, axis=1)))
    depth = float(np.mean(np.linalg.norm(pelvis.origin - posterior, axis=1)))
    return pelvis, width, depth


def segment_frames(lm: dict[str, np.ndarray]) -> Anatomy:
    """The anatomical set: frames from the ASIS, PSIS, epicondyles, malleoli, heel and 1st/5th
    metatarsal heads; hip centres by Harrington et al. (2007); knee and ankle centres midway
    between the epicondyles and the malleoli."""
    pelvis, width, depth = _pelvis(lm["right_asis"], lm["left_asis"],
                                   0.5 * (lm["right_psis"] + lm["left_psis"]))
    out, heel, toe = {"pelvis": pelvis}, {}, {}
    for s, side in SIDES.items():
        hip = pelvis.origin + pelvis.axes @ harrington_hip_centre(width, depth, s)
        lat_e, med_e = lm[f"{side}_lateral_epicondyle"], lm[f"{side}_medial_epicondyle"]
        lat_m, med_m = lm[f"{side}_lateral_malleolus"], lm[f"{side}_medial_malleolus"]
        heel[s] = lm[f"{side}_heel"]
        toe[s] = 0.5 * (lm[f"{side}_first_metatarsal"] + lm[f"{side}_fifth_metatarsal"])
        out[f"thigh_{s}"] = thigh_frames(hip, lat_e, med_e, s)
        out[f"shank_{s}"] = shank_frames(0.5 * (lat_e + med_e), lat_m, med_m, s)
        out[f"foot_{s}"] = foot_frames(0.5 * (lat_m + med_m), heel[s],
                                       lm[f"{side}_first_metatarsal"],
                                       lm[f"{side}_fifth_metatarsal"], s)
    return Anatomy(out, width, depth, heel, toe)


def _chord(proximal: np.ndarray, wand: np.ndarray, marker: np.ndarray, offset: float,
           joint: str) -> np.ndarray:
    """Davis' joint centre, or an error when the offset does not fit the segment."""
    reach = float(np.min(np.linalg.norm(proximal - marker, axis=1)))
    if offset >= 0.5 * reach:
        width = f"--{joint.split()[1]}-width"
        raise InputError(f"{width}: expected the {joint} centre ((width + marker diameter) / 2 = "
                         f"{1e3 * offset:.0f} mm from its lateral marker) much nearer that marker "
                         f"than the joint above it ({1e3 * reach:.0f} mm); check the width's unit")
    return chord_joint_centre(proximal, wand, marker, offset)


def davis_segment_frames(lm: dict[str, np.ndarray], measured: Measurements) -> Anatomy:
    """The Helen Hayes set (Davis et al. 1991): the pelvis from the ASIS and the sacrum, hip
    centres by Harrington et al. (2007), the knee centre by the chord construction from the hip
    centre, the thigh wand and the lateral knee marker at (knee width + marker diameter) / 2,
    the ankle centre likewise from the knee centre, the shank wand and the lateral malleolus at
    (ankle width + marker diameter) / 2; each lateral marker mirrored through its joint centre
    stands for the medial landmark, so the thigh and shank frames are the anatomical set's.
    The foot: from the heel to the 2nd metatarsal head, rolled as the shank (Plug-in Gait)."""
    pelvis, width, depth = _pelvis(lm["right_asis"], lm["left_asis"], lm["sacrum"])
    out, heel, toe = {"pelvis": pelvis}, {}, {}
    knee_offset = 0.5 * (measured.knee_width + measured.marker_diameter)
    ankle_offset = 0.5 * (measured.ankle_width + measured.marker_diameter)
    for s, side in SIDES.items():
        hip = pelvis.origin + pelvis.axes @ harrington_hip_centre(width, depth, s)
        knee_marker, malleolus = lm[f"{side}_lateral_epicondyle"], lm[f"{side}_lateral_malleolus"]
        knee = _chord(hip, lm[f"{side}_thigh_wand"], knee_marker, knee_offset, f"{side} knee")
        ankle = _chord(knee, lm[f"{side}_shank_wand"], malleolus, ankle_offset, f"{side} ankle")
        heel[s], toe[s] = lm[f"{side}_heel"], lm[f"{side}_second_metatarsal"]
        out[f"thigh_{s}"] = thigh_frames(hip, knee_marker, 2.0 * knee - knee_marker, s)
        out[f"shank_{s}"] = shank_frames(knee, malleolus, 2.0 * ankle - malleolus, s)
        out[f"foot_{s}"] = foot_frames_from_toe(ankle, knee, heel[s], toe[s])
    return Anatomy(out, width, depth, heel, toe)


def _perpendicular(vector: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """The unit vector of ``vector``'s part perpendicular to the unit ``axis``."""
    p = vector - (vector @ axis) * axis
    return p / np.linalg.norm(p)


def write_segments(doc: dict, bodies: tuple[str, ...], seg: dict[str, Frames],
                   points: dict[str, dict], vectors: dict[str, dict], inertia: dict) -> None:
    """Write each calibrated body into the model document ``doc``: its points (m, 6 decimals)
    and vectors (9 decimals) over the template's, its pose from its segment frames, and its
    inertia in place of the template's (none where ``inertia`` has no entry for it)."""
    for body in bodies:
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


def _round(values, digits: int) -> list[float]:
    return [round(float(x), digits) + 0.0 for x in values]


def _significant(value: float) -> float:
    return float(f"{value:.6g}")


def _pose(frames: Frames) -> dict:
    axes = frames.axes[0]
    return {"r": _round(frames.origin[0], 6), "u": _round(axes[:, 0], 9),
            "v": _round(axes[:, 1], 9), "w": _round(axes[:, 2], 9)}


def tracked_markers(model: Model, trial: Trial, window: slice,
                     mapping: dict[str, str]) -> np.ndarray:
    """The template's tracked markers over the window (frames × points × 3, NaN where the
    trial lacks one)."""
    out = np.full((len(range(trial.n_frames)[window]), len(model.tracked_points), 3), np.nan)
    for k, tp in enumerate(model.tracked_points):
        found = trial.find(mapping.get(tp.marker, tp.marker))
        if found is not None:
            out[:, k] = trial.select([found])[window, 0]
    return out


def calibrate(model: Model, trial: Trial, frames: tuple[int, int] | None = None,
              mass: float | None = None, measurements: Measurements | None = None,
              mapping: dict[str, str] | None = None, vertical: str = "auto") -> Calibration:
    """The template ``model`` personalized from ``trial`` over frame indices [A, B), by the
    method its landmarks choose (:func:`calibration_method`); ``measurements`` (Davis' method
    only; default :class:`Measurements`), ``mapping``: the template's label → the trial's,
    where a lab spells them otherwise. The personal model's gravity points down the trial's
    vertical (``anatomy.lab_axes``; ``vertical``: 'auto' or the axis up), as its poses lie in the
    trial's frame."""
    method = calibration_method(model)
    if method != "davis" and measurements is not None:
        raise InputError(f"--knee-width, --ankle-width, --marker-diameter: expected only with a "
                         f"template of the Helen Hayes/Davis set (wands, lateral markers); "
                         f"{model.source} maps medial epicondyles and malleoli, whose midpoints "
                         "are the joint centres")
    mapping = mapping or {}
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
    lm = read_landmarks(model, trial, window, METHODS[method], mapping)
    axes = lab_axes(model, trial, tracked_markers(model, trial, window, mapping), vertical)
    if method == "davis":
        measurements = measurements or Measurements()
        anatomy = davis_segment_frames(lm, measurements)
    else:
        anatomy = segment_frames(lm)
    seg, width, depth = anatomy.frames, anatomy.width, anatomy.depth
    doc = yaml.safe_load(model.text)
    points: dict[str, dict[str, np.ndarray]] = {b: {} for b in BODIES}
    vectors: dict[str, dict[str, np.ndarray]] = {b: {} for b in BODIES}
    lengths: dict[str, float] = {}
    inertia: dict[str, dict] = {}
    for s in SIDES:
        thigh, shank, foot = seg[f"thigh_{s}"], seg[f"shank_{s}"], seg[f"foot_{s}"]
        knee_local = thigh.mean_local(shank.origin)
        ankle_local = shank.mean_local(foot.origin)
        heel = foot.mean_local(anatomy.heel[s])
        toes = foot.mean_local(anatomy.toe[s])
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
    strayed = []
    for tp in model.tracked_points:
        if tp.body in seg:
            local = seg[tp.body].local(
                read_marker(trial, tp.marker, window, f"{model.source} tracking.points", mapping))
            points[tp.body][tp.point] = np.nanmean(local, axis=0)
            strayed.append(np.linalg.norm(local - points[tp.body][tp.point], axis=1))
    fit = (1e3 * float(np.mean(strayed)), 1e3 * float(np.max(strayed))) if strayed else \
        (float("nan"), float("nan"))
    builders = {f"{segment}_{s}": ", ".join(
        mapping.get(model.landmarks[f"{side}_{name}"], model.landmarks[f"{side}_{name}"])
        for name in names) for s, side in SIDES.items()
        for segment, names in BUILDERS[method].items()}
    warnings = implausibilities(seg, lengths, builders)
    write_segments(doc, BODIES, seg, points, vectors, inertia)
    if tuple(axes.gravity) != tuple(model.gravity):
        doc["gravity"] = _round(axes.gravity, 9)
    doc.pop("subject", None)
    if mass is not None:
        doc["subject"] = {"mass": mass}
    doc["calibrated"] = {"trial": str(trial.path), "frames": [start, stop],
                         "fit_mm": [round(fit[0], 3), round(fit[1], 3)], "warnings": warnings}
    header = (f"# {doc.get('name', 'model')} personalized by `fccgrb calibrate` from {trial.path}, "
              f"frame indices {start}:{stop}\n# from the template {model.source}. Hip centres: "
              "Harrington et al. (2007); "
              + ("knee and ankle centres: Davis et al. (1991), " + measurements.describe()
                 + "; " if measurements is not None else "")
              + "inertia: de Leva (1996)"
              f"{'' if mass is not None else ' (not computed: no --mass)'}.\n"
              f"# {axes.note()}\n")
    text = header + yaml.safe_dump(doc, sort_keys=False, default_flow_style=None, width=100)
    return Calibration(text, (start, stop), lengths, width, depth, mass, method, measurements,
                       fit, tuple(warnings), pose(seg), axes)

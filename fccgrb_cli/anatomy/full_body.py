"""Personalize a whole-body template (``fccgrb calibrate``): the pelvis and legs as
``anatomy.calibrate`` does them, then the thorax, head, upper arms, forearms and hands from the
landmarks of ``anatomy.upper_body`` (or all of them lumped into one head-arms-trunk body,
``hat``), each marker's local coordinates averaged over the calibration frames, and de Leva's
(1996) inertia for every segment.

The trunk is split as de Leva splits it: the pelvis is his lower trunk (omphalion to the hip
centres' midpoint), the thorax his upper and middle trunk together (suprasternale to xiphoid, then
to the omphalion). The omphalion's level divides the measured height from the hip centres'
midpoint to the xiphoid in de Leva's ratio of the two lengths (145.7 : 215.5 mm); the lumbar
joint lies at that level, midway between the ASIS and PSIS planes. Along a segment the CoM sits
at de Leva's fraction between its ends; the thorax's CoM at mid-depth between the sternal and
the spinal markers. The head (vertex to C7) has no vertex marker: its length is de Leva's scaled
by the subject's leg length (hip to ankle centres), its CoM on the line from C7 through the head
markers' centroid.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
import yaml

from fccgrb_cli.anatomy.anthropometry import REFERENCE_LENGTHS, SEGMENTS, combine, principal
from fccgrb_cli.anatomy.calibrate import (
    BODIES as LOWER_BODIES,
)
from fccgrb_cli.anatomy.calibrate import (
    SIDES,
    Calibration,
    Measurements,
    calibrate,
    calibration_method,
    davis_segment_frames,
    read_landmarks,
    read_marker,
    segment_frames,
    tracked_markers,
)
from fccgrb_cli.anatomy.frames import Frames, harrington_hip_centre, pelvis_frames
from fccgrb_cli.anatomy.lab_axes import lab_axes
from fccgrb_cli.anatomy.upper_body import (
    forearm_frames,
    hand_frames,
    head_frames,
    shoulder_centre,
    thorax_frames,
    upper_arm_frames,
)
from fccgrb_cli.core.errors import InputError
from fccgrb_cli.model import Model
from fccgrb_cli.trial.record import Trial

TRUNK_LANDMARKS = ("c7", "t8", "suprasternal_notch", "xiphoid")
HEAD_LANDMARKS = ("left_front_head", "right_front_head", "left_back_head", "right_back_head")
ARM_NAMES = ("acromion", "lateral_humeral_epicondyle", "medial_humeral_epicondyle",
             "radial_styloid", "ulnar_styloid", "second_metacarpal", "fifth_metacarpal")
# Plug-in Gait's arm: one elbow marker (lateral), the wrist bar's two (radial and ulnar
# styloids), one finger marker (just distal to the 2nd metacarpal head)
PIG_ARM_NAMES = ("acromion", "lateral_humeral_epicondyle", "radial_styloid", "ulnar_styloid",
                 "finger")
ARM_LANDMARKS = tuple(f"{side}_{name}" for side in SIDES.values()
                      for name in (*ARM_NAMES, "finger"))
ELBOW_WIDTH = 0.25  # an elbow's width over its upper arm's length (adults: ~70 over 280 mm)
MARKER_DIAMETER = 0.014  # m, without a measured one
UPPER_BODIES = ("thorax", "head", *(f"{seg}_{s}" for s in SIDES
                                    for seg in ("upper_arm", "forearm", "hand")))
LUMPED = "hat"
LOWER_OVER_MIDDLE = 0.1457 / (0.1457 + 0.2155)  # de Leva: lower trunk / (lower + middle)
E_U, E_V = np.eye(3)[0], np.eye(3)[1]


@dataclass
class Part:
    """A calibrated upper-body segment: its frames over the calibration frames, its points and
    vectors (local), and its inertia (mass, CoM, tensor about the CoM; None without a mass)."""

    frames: Frames
    points: dict[str, np.ndarray] = field(default_factory=dict)
    vectors: dict[str, np.ndarray] = field(default_factory=dict)
    inertia: tuple[float, np.ndarray, np.ndarray] | None = None
    length: float = 0.0


def is_full_body(model: Model) -> bool:
    """Whether a template has an upper body (a thorax, or the lumped ``hat``)."""
    names = {b.name for b in model.bodies}
    return "thorax" in names or LUMPED in names


def personalize(model: Model, trial: Trial, frames: tuple[int, int] | None = None,
                mass: float | None = None, measurements: Measurements | None = None,
                mapping: dict[str, str] | None = None, vertical: str = "auto") -> Calibration:
    """``calibrate`` for any template: a lower-limb one as it is, a whole-body one (or an upper
    body on a pelvis, without legs) with its upper body (this module) on top; ``vertical`` as
    :func:`calibrate` takes it (the lab's up: found, or stated)."""
    names = {b.name for b in model.bodies}
    if not is_full_body(model):
        return calibrate(model, trial, frames, mass, measurements, mapping, vertical)
    mapping = mapping or {}
    legs = all(b in names for b in LOWER_BODIES)
    lower = (calibrate(model, trial, frames, mass, measurements, mapping, vertical) if legs
             else _pelvis_alone(model, trial, frames, mass, mapping, vertical))
    lumped = LUMPED in names
    needed: tuple[str, ...] = TRUNK_LANDMARKS
    if not lumped:
        needed += HEAD_LANDMARKS if "head" in names else ()
        needed += tuple(f"{side}_{n}" for s, side in SIDES.items() if f"upper_arm_{s}" in names
                        for n in _arm_set(model.landmarks, side))
    absent = [n for n in needed if n not in model.landmarks]
    if absent:
        raise InputError(f"{model.source}: calibration.landmarks: expected the upper-body "
                         f"landmarks {', '.join(absent)} mapped to trial labels")
    window = slice(*lower.frames)
    optional = tuple(n for n in HEAD_LANDMARKS + ARM_LANDMARKS
                     if n in model.landmarks and n not in needed)
    rest = tuple(k for k in model.landmarks if k not in needed + optional)
    lm = read_landmarks(model, trial, window, needed + optional + rest, mapping)
    if not legs:
        pelvis = _pelvis_frames(lm)[0]
    elif calibration_method(model) == "davis":
        assert lower.measurements is not None  # Davis' calibration keeps the ones it used
        pelvis = davis_segment_frames(lm, lower.measurements).frames["pelvis"]
    else:
        pelvis = segment_frames(lm).frames["pelvis"]
    doc = yaml.safe_load(lower.text)
    parts, pelvis_part = _parts(lm, pelvis, doc, lower, mass, lumped)
    if lumped:
        parts = {LUMPED: _lumped(parts)}
    for tp in model.tracked_points:
        if tp.body in parts:
            parts[tp.body].points[tp.point] = parts[tp.body].frames.mean_local(
                read_marker(trial, tp.marker, window, f"{model.source} tracking.points",
                            mapping))
    _write(doc, "pelvis", pelvis_part)
    for name, part in parts.items():
        _write(doc, name, part)
    lengths = {**lower.lengths, **{n: p.length for n, p in parts.items() if p.length}}
    header = lower.text.split("\n", 2)
    text = (header[0] + "\n" + header[1].rstrip(".") + "; shoulder centres: Rab et al. "
            "(2002); upper body: ISB (Wu et al. 2005), de Leva (1996) trunk split (fccgrb_cli/"
            "anatomy/full_body.py).\n"
            + (f"# {lower.axes.note()}\n" if lower.axes is not None else "")
            + yaml.safe_dump(doc, sort_keys=False, default_flow_style=None, width=100))
    return replace(lower, text=text, lengths=lengths)


def _pelvis_frames(lm: dict[str, np.ndarray]) -> tuple[Frames, float, float]:
    """The pelvis from the ASIS and the PSIS (or the sacrum), its width and depth."""
    posterior = (lm["sacrum"] if "sacrum" in lm
                 else 0.5 * (lm["right_psis"] + lm["left_psis"]))
    pelvis = pelvis_frames(lm["right_asis"], lm["left_asis"], posterior, posterior)
    width = float(np.mean(np.linalg.norm(lm["right_asis"] - lm["left_asis"], axis=1)))
    depth = float(np.mean(np.linalg.norm(pelvis.origin - posterior, axis=1)))
    return pelvis, width, depth


def _pelvis_alone(model: Model, trial: Trial, frames: tuple[int, int] | None,
                  mass: float | None, mapping: dict[str, str], vertical: str) -> Calibration:
    """A template without legs: the pelvis alone from its landmarks (ASIS and PSIS, or the
    sacrum), its markers, and the hip centres (Harrington et al. 2007) as points of it; the
    gravity down the lab's vertical (``anatomy.lab_axes``; ``vertical``: 'auto' or the axis up), as
    a lower-limb template's (a y-up lab's upper-limb trial kept the template's −z)."""
    start, stop = frames if frames is not None else (0, trial.n_frames)
    if not 0 <= start < stop <= trial.n_frames:
        raise InputError(f"--frames: expected A:B with 0 ≤ A < B ≤ {trial.n_frames} (frame "
                         f"indices of {trial.path}), got {start}:{stop}")
    if mass is not None and not (np.isfinite(mass) and mass > 0):
        raise InputError(f"--mass: expected a positive, finite body mass in kg, got {mass}")
    back = ("sacrum",) if "sacrum" in model.landmarks else ("right_psis", "left_psis")
    names = ("right_asis", "left_asis", *back)
    absent = [n for n in names if n not in model.landmarks]
    if absent:
        raise InputError(f"{model.source}: calibration.landmarks: expected the pelvis's "
                         f"landmarks {', '.join(absent)} mapped to trial labels")
    window = slice(start, stop)
    pelvis, width, depth = _pelvis_frames(read_landmarks(model, trial, window, names, mapping))
    axes = lab_axes(model, trial, tracked_markers(model, trial, window, mapping), vertical)
    doc = yaml.safe_load(model.text)
    if tuple(axes.gravity) != tuple(model.gravity):
        doc["gravity"] = _round(axes.gravity, 9)
    part = Part(pelvis, {f"HJC_{s}": harrington_hip_centre(width, depth, s) for s in SIDES})
    for tp in model.tracked_points:
        if tp.body == "pelvis":
            part.points[tp.point] = pelvis.mean_local(read_marker(
                trial, tp.marker, window, f"{model.source} tracking.points", mapping))
    _write(doc, "pelvis", part)
    doc.pop("subject", None)
    if mass is not None:
        doc["subject"] = {"mass": mass}
    text = (f"# {doc.get('name', 'model')} personalized by `fccgrb calibrate` from {trial.path}, "
            f"frame indices {start}:{stop}\n# from the template {model.source}. Hip centres: "
            "Harrington et al. (2007); inertia: de Leva (1996).\n"
            f"# {axes.note()}\n"
            + yaml.safe_dump(doc, sort_keys=False, default_flow_style=None, width=100))
    return Calibration(text, (start, stop), {}, width, depth, mass, axes=axes)


def _parts(lm: dict[str, np.ndarray], pelvis: Frames, doc: dict, lower: Calibration,
           mass: float | None, lumped: bool) -> tuple[dict[str, Part], Part]:
    """Every upper-body segment whose landmarks are given (for a ``lumped`` body also those
    that are not, in an assumed posture), and the pelvis's lumbar joint and inertia (de Leva's
    lower trunk)."""
    spec = doc["bodies"]["pelvis"]
    hips = 0.5 * (np.array(spec["points"]["HJC_r"]) + np.array(spec["points"]["HJC_l"]))
    hip_mid = pelvis.origin + pelvis.axes @ hips
    xiphoid_height = float(np.mean(np.einsum("fi,fi->f", lm["xiphoid"] - hip_mid,
                                             pelvis.axes[:, :, 1])))
    lower_trunk = LOWER_OVER_MIDDLE * xiphoid_height
    lumbar = np.array([-0.5 * lower.pelvis_depth, hips[1] + lower_trunk, 0.0])
    pelvis_part = Part(pelvis, {"LJC": lumbar}, length=lower_trunk)
    if mass is not None:
        m, tensor = principal("pelvis", mass, lower_trunk)
        com = hips + np.array([0.0, (1.0 - SEGMENTS["pelvis"].com) * lower_trunk, 0.0])
        pelvis_part.inertia = (m, com, tensor)
    lumbar_global = pelvis.origin + pelvis.axes @ lumbar
    scale = _scale(lower.lengths, lm)
    parts = {"thorax": _thorax(lm, lumbar_global, mass)}
    thorax = parts["thorax"].frames
    if all(n in lm for n in HEAD_LANDMARKS):
        parts["head"] = _head(lm, mass, scale)
    elif lumped and mass is not None:
        parts["head"] = _upright_head(parts["thorax"], mass, scale)
    for s, side in SIDES.items():
        if all(f"{side}_{n}" in lm for n in _arm_set(lm, side)):
            parts |= _arm(lm, thorax, parts["thorax"], s, side, mass)
        elif lumped and mass is not None:
            parts |= _hanging_arm(lm, parts["thorax"], s, side, mass, scale)
    return parts, pelvis_part


def _scale(lengths: dict[str, float], lm: dict[str, np.ndarray]) -> float:
    """The subject's size over de Leva's: by the legs (thigh + shank, mean of both sides), or
    without legs by the upper trunk (suprasternal notch to xiphoid)."""
    if all(f"thigh_{s}" in lengths for s in SIDES):
        legs = [lengths[f"thigh_{s}"] + lengths[f"shank_{s}"] for s in SIDES]
        return float(np.mean(legs)) / (REFERENCE_LENGTHS["thigh"] + REFERENCE_LENGTHS["shank"])
    trunk = np.linalg.norm(lm["suprasternal_notch"] - lm["xiphoid"], axis=1)
    return float(np.mean(trunk)) / REFERENCE_LENGTHS["upper_trunk"]


def _thorax(lm: dict[str, np.ndarray], lumbar: np.ndarray, mass: float | None) -> Part:
    """The thorax: ISB frame, the lumbar and cervicothoracic joints, de Leva's upper and middle
    trunk (suprasternale → xiphoid → the omphalion at the lumbar joint's level)."""
    ij, px, c7, t8 = (lm[n] for n in ("suprasternal_notch", "xiphoid", "c7", "t8"))
    frames = thorax_frames(ij, px, c7, t8)
    local = {name: frames.mean_local(lm[name]) for name in TRUNK_LANDMARKS}
    part = Part(frames, {"LJC": frames.mean_local(lumbar),
                         "CJC": frames.mean_local(0.5 * (c7 + ij))})
    upper = float(np.linalg.norm(local["xiphoid"] - local["suprasternal_notch"]))
    middle = float(local["xiphoid"][1] - part.points["LJC"][1])
    if middle <= 0:
        raise InputError("calibration.landmarks.xiphoid: expected the xiphoid above the lumbar "
                         "joint (check the trunk markers' labels)")
    part.length = upper + middle
    if mass is not None:
        depth = np.mean([p[0] for p in local.values()])  # mid-depth, sternum to spine
        side = np.mean([p[2] for p in local.values()])
        v_top, v_px = local["suprasternal_notch"][1], local["xiphoid"][1]
        pieces = []
        for segment, top, length in (("upper_trunk", v_top, upper),
                                     ("middle_trunk", v_px, middle)):
            m, tensor = principal(segment, mass, length)
            com = np.array([depth, top - SEGMENTS[segment].com * length, side])
            pieces.append((m, com, tensor))
        part.inertia = combine(pieces)
    return part


def _head(lm: dict[str, np.ndarray], mass: float | None, scale: float) -> Part:
    """The head from its band's markers; the neck joint midway between C7 and the suprasternal
    notch; de Leva's head (vertex to C7) scaled by the legs, its CoM at his fraction from C7
    towards the band's centroid."""
    frames = head_frames(*(lm[n] for n in HEAD_LANDMARKS))
    c7 = frames.mean_local(lm["c7"])
    part = Part(frames, {"CJC": frames.mean_local(0.5 * (lm["c7"] + lm["suprasternal_notch"]))})
    part.length = REFERENCE_LENGTHS["head"] * scale
    if mass is not None:
        m, tensor = principal("head", mass, part.length)
        com = c7 - (1.0 - SEGMENTS["head"].com) * part.length * c7 / np.linalg.norm(c7)
        part.inertia = (m, com, tensor)
    return part


def _perpendicular(vector: np.ndarray, axis: np.ndarray) -> np.ndarray:
    p = vector - (vector @ axis) * axis
    return p / np.linalg.norm(p)


def _segment(frames: Frames, distal: np.ndarray, segment: str, mass: float | None) -> Part:
    """A long-bone segment from its proximal joint (the origin) to ``distal`` (global,
    frames × 3): its distal joint's local position, length and de Leva's inertia."""
    end = frames.mean_local(distal)
    part = Part(frames, length=float(np.linalg.norm(end)))
    if mass is not None:
        m, tensor = principal(segment, mass, part.length)
        part.inertia = (m, SEGMENTS[segment].com * end, tensor)
    part.points["distal"] = end
    return part


def _arm_set(landmarks, side: str) -> tuple[str, ...]:
    """The arm landmarks of a side: the ISB set when its medial epicondyle is given, else
    Plug-in Gait's."""
    return ARM_NAMES if f"{side}_medial_humeral_epicondyle" in landmarks else PIG_ARM_NAMES


def _lateral_elbow(shoulder: np.ndarray, lateral: np.ndarray, thorax: Frames, s: str
                   ) -> np.ndarray:
    """The elbow centre from the lateral epicondyle alone (Plug-in Gait's set): medial of the
    marker by half the elbow width (ELBOW_WIDTH × the upper arm's length) and the marker's
    radius, perpendicular to the humerus and in the plane of the humerus and the thorax's
    medio-lateral axis (the epicondylar axis of an arm in neutral rotation, as in the static
    posture calibration assumes)."""
    axis = lateral - shoulder
    length = float(np.mean(np.linalg.norm(axis, axis=1)))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    medial = -thorax.axes[:, :, 2] if s == "r" else thorax.axes[:, :, 2]
    medial = medial - np.sum(medial * axis, axis=1, keepdims=True) * axis
    medial /= np.linalg.norm(medial, axis=1, keepdims=True)
    return lateral + 0.5 * (ELBOW_WIDTH * length + MARKER_DIAMETER) * medial


def _arm(lm: dict[str, np.ndarray], thorax: Frames, thorax_part: Part, s: str, side: str,
         mass: float | None) -> dict[str, Part]:
    """Upper arm, forearm and hand of one side, and the shoulder centre on the thorax; from the
    ISB landmarks or Plug-in Gait's (one elbow marker, one finger marker: the elbow centre by
    :func:`_lateral_elbow`, the hand from the wrist centre to the finger marker, its lateral
    direction the wrist bar's)."""
    get = {name: lm[f"{side}_{name}"] for name in _arm_set(lm, side)}
    lateral = get["lateral_humeral_epicondyle"]
    reach = float(np.mean(np.linalg.norm(get["acromion"] - lateral, axis=1)))
    shoulder = shoulder_centre(get["acromion"], thorax, reach)
    thorax_part.points[f"GH_{s}"] = thorax.mean_local(shoulder)
    if "medial_humeral_epicondyle" in get:
        elbow = 0.5 * (lateral + get["medial_humeral_epicondyle"])
    else:
        elbow = _lateral_elbow(shoulder, lateral, thorax, s)
    radial, ulnar = get["radial_styloid"], get["ulnar_styloid"]
    wrist = 0.5 * (radial + ulnar)
    if "finger" in get:  # the wrist bar's direction, about the finger marker
        knuckles = get["finger"]
        second, fifth = knuckles + 0.5 * (radial - ulnar), knuckles - 0.5 * (radial - ulnar)
    else:
        second, fifth = get["second_metacarpal"], get["fifth_metacarpal"]
        knuckles = 0.5 * (second + fifth)
    upper = _segment(upper_arm_frames(shoulder, lateral, 2.0 * elbow - lateral, s), elbow,
                     "upper_arm", mass)
    fore = _segment(forearm_frames(elbow, radial, ulnar, s), wrist, "forearm", mass)
    hand = _segment(hand_frames(wrist, second, fifth, s), knuckles, "hand", mass)
    upper.points.update(GH=np.zeros(3), EJC=upper.points.pop("distal"))
    fore.points.update(EJC=np.zeros(3), WJC=fore.points.pop("distal"))
    hand.points.update(WJC=np.zeros(3))
    hand.points.pop("distal")
    elbow_axis = fore.frames.mean_direction(upper.frames.axes[:, :, 2])
    arm = _perpendicular(E_V, elbow_axis)
    fore.vectors.update(elbow_arm=arm, pronation_ref=_perpendicular(E_U, arm))
    wrist_axis = hand.frames.mean_direction(fore.frames.axes[:, :, 2])
    arm = _perpendicular(E_U, wrist_axis)
    hand.vectors.update(wrist_arm=arm, wrist_up=_perpendicular(E_V, arm))
    return {f"upper_arm_{s}": upper, f"forearm_{s}": fore, f"hand_{s}": hand}


def _upright_head(thorax: Part, mass: float, scale: float) -> Part:
    """Without head markers (the lumped body only): the head upright over the cervicothoracic
    joint along the thorax's long axis, its CoM at de Leva's fraction of his length (scaled by
    the legs) from C7's level."""
    length = REFERENCE_LENGTHS["head"] * scale
    m, tensor = principal("head", mass, length)
    com = thorax.points["CJC"] + np.array([0.0, (1.0 - SEGMENTS["head"].com) * length, 0.0])
    return Part(thorax.frames, inertia=(m, com, tensor))


def _hanging_arm(lm: dict[str, np.ndarray], thorax: Part, s: str, side: str, mass: float,
                 scale: float) -> dict[str, Part]:
    """Without arm markers (the lumped body only): the arm hanging straight down the thorax's
    long axis from the shoulder centre (Rab et al.'s rule from the acromion, the acromion–
    epicondyle distance taken as the upper arm's length), de Leva's lengths scaled by the
    legs."""
    if f"{side}_acromion" not in lm:
        raise InputError(f"calibration.landmarks.{side}_acromion: expected the acromion mapped "
                         "to a trial label (the shoulder centre of the lumped body's arms)")
    lengths = {seg: REFERENCE_LENGTHS[seg] * scale for seg in ("upper_arm", "forearm", "hand")}
    shoulder = shoulder_centre(lm[f"{side}_acromion"], thorax.frames, lengths["upper_arm"])
    thorax.points[f"GH_{s}"] = thorax.frames.mean_local(shoulder)
    top, out = thorax.points[f"GH_{s}"].copy(), {}
    for seg, length in lengths.items():
        m, tensor = principal(seg, mass, length)
        com = top - np.array([0.0, SEGMENTS[seg].com * length, 0.0])
        out[f"{seg}_{s}"] = Part(thorax.frames, inertia=(m, com, tensor))
        top = top - np.array([0.0, length, 0.0])
    return out


def _lumped(parts: dict[str, Part]) -> Part:
    """Every upper-body part as one rigid body in the thorax's frame: each part's CoM and
    inertia tensor seen from the thorax, averaged over the calibration frames, then combined."""
    thorax = parts["thorax"]
    frames = thorax.frames
    pieces = []
    for part in parts.values():
        if part.inertia is None:
            continue
        m, com, tensor = part.inertia
        centre = frames.mean_local(part.frames.origin + part.frames.axes @ com)
        turn = np.einsum("fji,fjk->fik", frames.axes, part.frames.axes)  # part → thorax axes
        pieces.append((m, centre, np.mean(turn @ tensor @ turn.transpose(0, 2, 1), axis=0)))
    hat = Part(frames, {"LJC": thorax.points["LJC"]}, length=thorax.length)
    if pieces:
        hat.inertia = combine(pieces)
    return hat


def _round(values, digits: int) -> list:
    return np.round(np.asarray(values, dtype=float), digits).tolist()


def _write(doc: dict, name: str, part: Part) -> None:
    """A body's calibrated points, vectors, first-frame pose and inertia into the model
    document."""
    spec = doc["bodies"][name]
    spec["points"] = {**spec.get("points", {}),
                      **{k: _round(v, 6) for k, v in part.points.items()}}
    if part.vectors:
        spec["vectors"] = {**spec.get("vectors", {}),
                           **{k: _round(v, 9) for k, v in part.vectors.items()}}
    axes = part.frames.axes[0]
    spec["pose"] = {"r": _round(part.frames.origin[0], 6), "u": _round(axes[:, 0], 9),
                    "v": _round(axes[:, 1], 9), "w": _round(axes[:, 2], 9)}
    for key in ("mass", "com", "inertia"):
        spec.pop(key, None)
    if part.inertia is not None:
        m, com, tensor = part.inertia
        spec.update(mass=float(f"{m:.6g}"), com=_round(com, 5), inertia=_round(tensor, 7))

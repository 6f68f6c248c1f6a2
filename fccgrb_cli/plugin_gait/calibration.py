"""Personalize the Plug-in Gait template (``calibration.method: plugin-gait``) from a static trial.

Over the chosen frames, Plug-in Gait's segments are built every frame from the markers and the
subject's measurements (anatomy/plugin_gait.py): pelvis, Davis hip centres, chord knee and ankle
centres with the thigh and shank rotation offsets, the proximal tibia (tibial torsion), the
uncorrected foot. The static's foot offsets (plantarflexion and rotation of the toe-to-heel line
in the uncorrected foot) are averaged over the frames as Plug-in Gait does, and the corrected
foot follows. Every marker and joint centre is then the mean of its local coordinates in its
segment; the universal ankle's foot arm is the uncorrected foot's up axis. The measurements used
(given, computed or defaulted) and the static offsets are written into the model's ``subject:``
section with where each came from.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
import yaml

from fccgrb_cli.anatomy.calibrate import write_segments
from fccgrb_cli.core.errors import InputError
from fccgrb_cli.model import Model
from fccgrb_cli.model.subject import PIG_KEYS, Sided, SubjectMeasurements
from fccgrb_cli.plugin_gait import segments as pg
from fccgrb_cli.trial.record import Trial

SIDES = {"r": "right", "l": "left"}
LANDMARKS = ("right_asis", "left_asis", "sacrum", *(
    f"{side}_{name}" for side in SIDES.values() for name in (
        "thigh_wand", "lateral_epicondyle", "shank_wand", "lateral_malleolus", "heel", "toe")))
BODIES = ("pelvis", *(f"{seg}_{s}" for s in SIDES for seg in ("thigh", "shank", "foot")))
REQUIRED = ("leg_length", "knee_width", "ankle_width")
MARKER_DIAMETER = 0.014  # Plug-in Gait's default where the subject's parameters give none (m)
# Plug-in Gait's kinetic segments (Vicon, Plug-in Gait Reference Guide, "Kinetic modeling"; the
# same numbers in pyCGM2's Bsp table, after Dempster 1955): mass as a fraction of body mass,
# centre of mass as the fraction of the segment's length from its distal end towards its
# proximal one, radius of gyration as a fraction of the length (about the two transverse axes,
# none about the long axis).
PIG_SEGMENTS = {"thigh": (0.1, 0.567, 0.540), "shank": (0.0465, 0.567, 0.528),
                "foot": (0.0145, 0.5, 0.690)}
# The pelvis: 14.2 % of body mass, length 0.925 × the distance between the hip centres (mid-hip
# to the top of L5), its centre of mass 0.895 of the way from mid-hip along the pelvis's up axis,
# radius of gyration 0.31 of the length about all three axes (Vicon's table; pyCGM2, cgm.py).
PIG_PELVIS = (0.142, 0.925, 0.895, 0.31)


# Static foot offsets a subject file records (Vicon's) agree with the ones this static gives
# with an option when every one lies within this (rad; Vicon's own agree to ~1e-6° when its
# option is the same, and the two options differ by degrees on a foot that is not level).
OFFSETS_AGREE = np.radians(0.1)


@dataclass(frozen=True)
class Options:
    """Calibration options: frame indices [A, B) (None: every frame); Plug-in Gait's static
    'foot flat' (the heel-to-toe line taken level, the heel raised by the sole delta; None:
    the option whose offsets equal the ones the subject's files record — Vicon's, computed on
    this static — else foot flat)."""

    frames: tuple[int, int] | None = None
    foot_flat: bool | None = None


@dataclass(frozen=True)
class PigCalibration:
    """The personalized model text, the frames used, the measurements used (given, computed and
    defaulted, SI; the static foot offsets included), what was computed or defaulted (notes),
    segment lengths (m), and what the user should know (``warnings``: a default standing for
    a measurement, a value read in another unit than written)."""

    text: str
    frames: tuple[int, int]
    measurements: SubjectMeasurements
    notes: tuple[str, ...]
    lengths: dict[str, float]
    warnings: tuple[str, ...] = ()
    foot_flat: bool = True


def _marker(trial: Trial, label: str, window: slice, used_by: str,
            mapping: dict[str, str]) -> np.ndarray:
    wanted = mapping.get(label, label)
    found = trial.find(wanted)
    if found is None:
        mapped = f" (mapped from {label})" if wanted != label else ""
        raise InputError(f"{trial.path}: expected the marker {wanted}{mapped} (used by "
                         f"{used_by})")
    xyz = trial.select([found])[window, 0]
    if np.isnan(xyz).all(axis=1).any():
        first = int(np.flatnonzero(np.isnan(xyz).any(axis=1))[0]) + (window.start or 0)
        raise InputError(f"{trial.path}: frame index {first}: expected the marker {wanted} "
                         f"(used by {used_by}); choose calibration frames without gaps "
                         "(--frames A:B)")
    return xyz


def resolve(measured: SubjectMeasurements, lm: dict[str, np.ndarray]
            ) -> tuple[SubjectMeasurements, tuple[str, ...]]:
    """The measurements Plug-in Gait uses: the required ones must be given (an error lists the
    missing Vicon keys); the marker diameter defaults to Plug-in Gait's 14 mm; the inter-ASIS
    distance to the markers' mean distance, the ASIS–trochanter distance to 0.1288 leg length
    − 48.56 mm, rotations, torsion and sole delta to 0. Returns them with a note per value
    computed or defaulted."""
    missing = measured.missing(REQUIRED)
    if missing:
        raise InputError(f"Plug-in Gait calibration: expected the subject measurements "
                         f"{', '.join(missing)} (from the static C3D's PROCESSING group, "
                         "--subject FILE.vsk|FILE.mp|FILE.yaml, or --knee-width/--ankle-width"
                         f"); sources read: {measured.source or 'none'}")
    notes = []
    values: dict = {}
    if measured.marker_diameter is None:
        values["marker_diameter"] = MARKER_DIAMETER
        notes.append(f"MarkerDiameter {1e3 * MARKER_DIAMETER:g} mm, Plug-in Gait's default "
                     "(no source gives it)")
    if measured.inter_asis_distance is None:
        distance = float(np.mean(np.linalg.norm(lm["right_asis"] - lm["left_asis"], axis=1)))
        values["inter_asis_distance"] = distance
        notes.append(f"InterAsisDistance {1e3 * distance:.1f} mm measured between the ASIS "
                     "markers")
    at = measured.asis_trochanter_distance
    sided = {}
    for s, side in SIDES.items():
        if at.side(s) is None:
            sided[side] = pg.asis_trochanter_distance(_resolved(measured.leg_length.side(s)))
            notes.append(f"{side} AsisTrocanterDistance {1e3 * sided[side]:.1f} mm from the "
                         "leg length (0.1288 L − 48.56 mm)")
    if sided:
        values["asis_trochanter_distance"] = replace(at, **sided)
    for name in ("thigh_rotation", "shank_rotation", "tibial_torsion", "sole_delta"):
        value: Sided = getattr(measured, name)
        if value.left is None or value.right is None:
            values[name] = Sided(value.left or 0.0, value.right or 0.0)
            notes.append(f"{PIG_KEYS[name].vicon} 0 where not given")
    return replace(measured, **values), tuple(notes)


def _resolved(value: float | None) -> float:
    """A measurement :func:`resolve` guarantees (required, measured or defaulted)."""
    assert value is not None
    return value


def side_geometry(m: SubjectMeasurements, offsets: dict[str, tuple[float, float]] | None = None
              ) -> dict[str, pg.SideGeometry]:
    leg = 0.5 * (_resolved(m.leg_length.left) + _resolved(m.leg_length.right))
    marker = _resolved(m.marker_diameter)
    out = {}
    for s in SIDES:
        hip = pg.davis_hip_centre(leg, _resolved(m.asis_trochanter_distance.side(s)),
                                  _resolved(m.inter_asis_distance), marker, s)
        out[s] = pg.SideGeometry(
            hip, 0.5 * (_resolved(m.knee_width.side(s)) + marker),
            0.5 * (_resolved(m.ankle_width.side(s)) + marker),
            _resolved(m.thigh_rotation.side(s)), _resolved(m.shank_rotation.side(s)),
            _resolved(m.tibial_torsion.side(s)),
            None if offsets is None else offsets[s])
    return out


def _round(values, digits: int) -> list[float]:
    return [round(float(x), digits) + 0.0 for x in values]


def _subject_section(m: SubjectMeasurements, angle_scale: float) -> dict:
    """The ``subject:`` section: lengths in m, angles in the file's unit, mass in kg."""
    out: dict = {}
    for name, q in PIG_KEYS.items():
        value = getattr(m, name)
        key = "mass" if name == "body_mass" else name
        scale = 1.0 / angle_scale if q.kind == "angle" else 1.0
        if isinstance(value, Sided):
            if value.left is not None or value.right is not None:
                out[key] = {side: round(getattr(value, side) * scale, 9) + 0.0
                            for side in ("left", "right") if getattr(value, side) is not None}
        elif value is not None:
            out[key] = round(value * scale, 9) + 0.0
    out["source"] = m.source
    return out


def calibrate_plugin_gait(model: Model, trial: Trial, measured: SubjectMeasurements,
                          options: Options, mapping: dict[str, str] | None = None
                          ) -> PigCalibration:
    """The Plug-in Gait template ``model`` personalized from the static ``trial`` with the
    subject's ``measured`` values (:func:`resolve`); ``mapping``: the template's label → the
    trial's."""
    mapping = mapping or {}
    start, stop = options.frames if options.frames is not None else (0, trial.n_frames)
    if not 0 <= start < stop <= trial.n_frames:
        raise InputError(f"--frames: expected A:B with 0 ≤ A < B ≤ {trial.n_frames} (frame "
                         f"indices of {trial.path}), got {start}:{stop}")
    absent = [b for b in BODIES if b not in {b.name for b in model.bodies}]
    missing = [name for name in LANDMARKS if name not in model.landmarks]
    if absent or missing:
        raise InputError(f"{model.source}: expected the Plug-in Gait bodies {', '.join(BODIES)} "
                         f"and calibration.landmarks {', '.join(LANDMARKS)}; missing "
                         f"{', '.join(absent + missing)}")
    window = slice(start, stop)
    lm = {name: _marker(trial, model.landmarks[name], window,
                        f"{model.source} calibration.landmarks.{name}", mapping)
          for name in LANDMARKS}
    m, notes = resolve(measured, lm)
    warnings = list(measured.notes)
    if measured.marker_diameter is None:
        warnings.append(f"no marker diameter in {measured.source or 'any source'}: Plug-in "
                        f"Gait's default {1e3 * MARKER_DIAMETER:g} mm used (--marker-diameter "
                        "MM if the markers differ)")
    markers: dict = {"pelvis": (lm["right_asis"], lm["left_asis"], lm["sacrum"])}
    for s, side in SIDES.items():
        markers[f"thigh_{s}"] = (lm[f"{side}_thigh_wand"], lm[f"{side}_lateral_epicondyle"])
        markers[f"shank_{s}"] = (lm[f"{side}_shank_wand"], lm[f"{side}_lateral_malleolus"])
        markers[f"toe_{s}"] = lm[f"{side}_toe"]
    uncorrected = pg.segments(markers, side_geometry(m))
    up = -np.asarray(model.gravity) / np.linalg.norm(model.gravity)

    def computed(flat: bool) -> dict[str, tuple[float, float]]:
        return {s: pg.foot_offsets(uncorrected[f"foot_{s}"], lm[f"{side}_heel"],
                                   lm[f"{side}_toe"], up, flat, _resolved(m.sole_delta.side(s)))
                for s, side in SIDES.items()}

    flat, said = _foot_flat(options.foot_flat, measured, computed)
    warnings += said
    offsets = computed(flat)
    m = replace(m, static_plantar_flexion=Sided(offsets["l"][0], offsets["r"][0]),
                static_rotation_offset=Sided(offsets["l"][1], -offsets["r"][1]))
    seg = pg.segments(markers, side_geometry(m, offsets))
    geometry = side_geometry(m)
    doc = yaml.safe_load(model.text)
    points: dict[str, dict] = {b: {} for b in BODIES}
    vectors: dict[str, dict] = {b: {} for b in BODIES}
    lengths: dict[str, float] = {}
    toes: dict[str, np.ndarray] = {}
    for s, side in SIDES.items():
        thigh, shank, foot = seg[f"thigh_{s}"], seg[f"shank_{s}"], seg[f"foot_{s}"]
        points["pelvis"][f"HJC_{s}"] = geometry[s].hip
        knee, ankle = thigh.mean_local(shank.origin), shank.mean_local(foot.origin)
        points[f"thigh_{s}"].update(HJC=np.zeros(3), KJC=knee)
        points[f"shank_{s}"].update(KJC=np.zeros(3), AJC=ankle)
        points[f"foot_{s}"]["AJC"] = np.zeros(3)
        turn = pg.offset_rotation(*offsets[s])  # corrected axes in the uncorrected foot's
        vectors[f"foot_{s}"].update(uncorrected_u=turn[0], uncorrected_v=turn[1])
        heel, toe = foot.mean_local(lm[f"{side}_heel"]), foot.mean_local(lm[f"{side}_toe"])
        toes[s] = toe
        lengths.update({f"thigh_{s}": float(np.linalg.norm(knee)),
                        f"shank_{s}": float(np.linalg.norm(ankle)),
                        f"foot_{s}": float(np.linalg.norm(toe - heel))})
    for tp in model.tracked_points:
        if tp.body in seg:
            points[tp.body][tp.point] = seg[tp.body].mean_local(
                _marker(trial, tp.marker, window, f"{model.source} tracking.points", mapping))
    inertia = _inertia(m.body_mass, points, toes)
    write_segments(doc, BODIES, seg, points, vectors, inertia)
    angle_scale = np.pi / 180.0 if (doc.get("units") or {}).get("angle", "deg") == "deg" \
        else 1.0
    doc["subject"] = _subject_section(m, angle_scale)
    header = (f"# {doc.get('name', 'model')} personalized by `fccgrb calibrate` from "
              f"{trial.path}, frame indices {start}:{stop}\n# from the template {model.source}: "
              "Plug-in Gait's segments (Davis hip centres, chord knee and ankle centres, "
              f"{'foot flat' if flat else 'foot not flat'}); inertia: Plug-in "
              f"Gait's{'' if m.body_mass is not None else ' (not computed: no body mass)'}.\n"
              + "".join(f"# {note}\n" for note in notes))
    text = header + yaml.safe_dump(doc, sort_keys=False, default_flow_style=None, width=100)
    return PigCalibration(text, (start, stop), m, notes, lengths, tuple(warnings), flat)


def _foot_flat(chosen: bool | None, measured: SubjectMeasurements,
               computed: Callable[[bool], dict[str, tuple[float, float]]]
               ) -> tuple[bool, list[str]]:
    """The foot-flat option to calibrate with, and what to tell: ``chosen`` when given; else
    the option whose static offsets (``computed(flat)``: side → (β, α)) equal, within
    ``OFFSETS_AGREE``, the ones ``measured`` records (``StaticPlantFlex``, ``StaticRotOff``:
    Vicon computed them on this static with its option, which its files do not name), foot flat
    first; else foot flat, saying how far the recorded ones lie from either."""
    if chosen is not None:
        return chosen, []
    given = (measured.static_plantar_flexion.left, measured.static_plantar_flexion.right,
             measured.static_rotation_offset.left, measured.static_rotation_offset.right)
    recorded = [v for v in given if v is not None]
    if len(recorded) < len(given):
        return True, []

    def gap(flat: bool) -> float:
        o = computed(flat)
        ours = (o["l"][0], o["r"][0], o["l"][1], -o["r"][1])  # Vicon's signs
        return max(abs(a - b) for a, b in zip(ours, recorded, strict=True))

    gaps = {flat: gap(flat) for flat in (True, False)}
    source = measured.source or "the subject's files"
    if gaps[True] <= OFFSETS_AGREE:
        return True, []
    if gaps[False] <= OFFSETS_AGREE:
        return False, [f"foot not flat: the static foot offsets {source} records are this "
                       "static's without Plug-in Gait's foot-flat option (with it they would "
                       f"differ by up to {np.degrees(gaps[True]):.2f}°); --foot-flat to "
                       "override"]
    return True, [f"the static foot offsets {source} records differ from this static's by up "
                  f"to {np.degrees(gaps[True]):.2f}° with foot flat (used) and "
                  f"{np.degrees(gaps[False]):.2f}° without (--no-foot-flat): recorded on "
                  "another static, or with other measurements"]


def _inertia(mass: float | None, points: dict[str, dict], toes: dict[str, np.ndarray]
             ) -> dict[str, dict]:
    """Plug-in Gait's segment inertia (``PIG_SEGMENTS``, ``PIG_PELVIS``) from the body mass and
    the static's joint centres (local ``points``) and toe markers (``toes``, local to each
    foot): thigh from the knee centre (distal) to the hip centre, shank from the ankle centre
    to the knee centre, foot from the toe marker to the ankle centre; each centre of mass on
    that line, each tensor about it
    m (k L)² (1 − e eᵀ) with e the unit line (in the body's axes: the corrected foot's long axis
    is the heel-to-toe line, not the ankle-to-toe one). None without a body mass."""
    if mass is None:
        return {}
    out = {}
    ends = {"thigh": ("KJC", "HJC"), "shank": ("AJC", "KJC"), "foot": (None, "AJC")}
    for s in SIDES:
        for segment, (distal, proximal) in ends.items():
            name = f"{segment}_{s}"
            fraction, com_from_distal, gyration = PIG_SEGMENTS[segment]
            low = toes[s] if distal is None else np.asarray(points[name][distal])
            high = np.asarray(points[name][proximal])
            length = float(np.linalg.norm(high - low))
            e = (high - low) / length
            m = fraction * mass
            tensor = m * (gyration * length) ** 2 * (np.eye(3) - np.outer(e, e))
            out[name] = {"mass": float(f"{m:.6g}"),
                         "com": _round(low + com_from_distal * (high - low), 5),
                         "inertia": [_round(row, 12) for row in tensor]}
    fraction, per_hip_width, com_fraction, gyration = PIG_PELVIS
    right, left = np.asarray(points["pelvis"]["HJC_r"]), np.asarray(points["pelvis"]["HJC_l"])
    length = per_hip_width * float(np.linalg.norm(left - right))
    m = fraction * mass
    com = 0.5 * (right + left) + com_fraction * length * np.array([0.0, 1.0, 0.0])
    out["pelvis"] = {"mass": float(f"{m:.6g}"), "com": _round(com, 5),
                     "inertia": _round(np.full(3, m * (gyration * length) ** 2), 7)}
    return out

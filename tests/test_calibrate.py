"""Calibration of the lower-limb template (``fccgrb calibrate``) against synthetic subjects built
here from known geometry.

Every expectation comes from a construction in this file: segment frames are known rotation
matrices, landmarks and markers sit at chosen local coordinates (on a micrometre grid, so the
model text's rounding to 1e-6 m is exact), joint centres follow from the definitions (hip:
Harrington et al. 2007, typed here in mm; knee mid-epicondyles; ankle mid-malleoli), and each
joint motion is a rotation about an anatomical direction (u anterior, v superior, w to the
subject's right) whose physical effect is asserted on the built markers before any clinical
angle is compared with it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest
import yaml
from cli_helpers import run_cli

from fccgrb_cli.anatomy.calibrate import calibrate
from fccgrb_cli.anatomy.frames import (
    foot_frames,
    harrington_hip_centre,
    pelvis_frames,
    shank_frames,
    thigh_frames,
)
from fccgrb_cli.model import load_model, parse_model
from fccgrb_cli.pipeline.options import SolveOptions
from fccgrb_cli.pipeline.solve import solve_trial
from fccgrb_cli.trial.record import Trial, write_trial

ROOT = Path(__file__).resolve().parents[1]
TEMPLATE = ROOT / "configs" / "models" / "lower_limb.yaml"
SIGN = {"r": 1.0, "l": -1.0}  # the side's lateral direction along w (w = subject's right)
PREFIX = {"r": "R_", "l": "L_"}
BODIES = ("pelvis", "thigh_r", "shank_r", "foot_r", "thigh_l", "shank_l", "foot_l")
JOINT_ANGLES = ("hip_flexion", "hip_adduction", "hip_rotation", "knee_flexion",
                "ankle_dorsiflexion", "ankle_inversion")

# The subject's geometry (m), on a micrometre grid.
PELVIS_WIDTH, PELVIS_DEPTH = 0.236, 0.148
THIGH = {"r": 0.421, "l": 0.417}                   # hip centre to knee centre
SHANK = {"r": 0.408, "l": 0.412}                   # knee centre to ankle centre
TORSION = {"r": np.radians(12.0), "l": np.radians(-7.0)}  # shank frame about v, off the hinge


@pytest.fixture(scope="module")
def template():
    return load_model(TEMPLATE)


# --- rotations ------------------------------------------------------------------------------

def rx(a: np.ndarray) -> np.ndarray:
    """Rotations by angles a (rad, shape n) about the first axis (right-hand rule), n × 3 × 3."""
    a = np.asarray(a, float)
    c, s, o, i = np.cos(a), np.sin(a), np.zeros_like(a), np.ones_like(a)
    return np.stack([np.stack([i, o, o], -1), np.stack([o, c, -s], -1),
                     np.stack([o, s, c], -1)], -2)


def ry(a: np.ndarray) -> np.ndarray:
    a = np.asarray(a, float)
    c, s, o, i = np.cos(a), np.sin(a), np.zeros_like(a), np.ones_like(a)
    return np.stack([np.stack([c, o, s], -1), np.stack([o, i, o], -1),
                     np.stack([-s, o, c], -1)], -2)


def rz(a: np.ndarray) -> np.ndarray:
    a = np.asarray(a, float)
    c, s, o, i = np.cos(a), np.sin(a), np.zeros_like(a), np.ones_like(a)
    return np.stack([np.stack([c, -s, o], -1), np.stack([s, c, o], -1),
                     np.stack([o, o, i], -1)], -2)


def random_rotations(rng: np.random.Generator, n: int) -> np.ndarray:
    """n proper rotations from the QR decomposition of Gaussian matrices."""
    q, r = np.linalg.qr(rng.normal(size=(n, 3, 3)))
    q = q * np.sign(np.diagonal(r, axis1=1, axis2=2))[:, None, :]
    q[np.linalg.det(q) < 0, :, 0] *= -1.0
    return q


def test_rotation_helpers_are_proper_and_right_handed() -> None:
    a = np.radians([30.0])
    e = np.eye(3)
    # right-hand rule: x→y about z, y→z about x, z→x about y
    np.testing.assert_allclose(rz(a)[0] @ e[0], [np.cos(a[0]), np.sin(a[0]), 0], atol=1e-15)
    np.testing.assert_allclose(rx(a)[0] @ e[1], [0, np.cos(a[0]), np.sin(a[0])], atol=1e-15)
    np.testing.assert_allclose(ry(a)[0] @ e[2], [np.sin(a[0]), 0, np.cos(a[0])], atol=1e-15)
    q = random_rotations(np.random.default_rng(0), 20)
    np.testing.assert_allclose(q @ np.swapaxes(q, 1, 2), np.broadcast_to(e, q.shape), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(q), 1.0, atol=1e-12)


# --- the subject's local geometry ----------------------------------------------------------

def harrington_mm(width_m: float, depth_m: float, side: str) -> np.ndarray:
    """Harrington et al. (2007) in mm, from PW and PD in mm; returned in m."""
    pw, pd = 1000.0 * width_m, 1000.0 * depth_m
    x = -0.24 * pd - 9.9
    y = -0.30 * pw - 10.9
    z = 0.33 * pw + 7.3
    return np.array([x, y, z if side == "r" else -z]) / 1000.0


def local_points() -> dict[str, dict[str, np.ndarray]]:
    """Every marker's (and landmark's) coordinates in its segment's ISB frame."""
    half = PELVIS_WIDTH / 2
    out = {"pelvis": {"R_IAS": [0, 0, half], "L_IAS": [0, 0, -half],
                      "R_IPS": [-PELVIS_DEPTH, 0, 0.046], "L_IPS": [-PELVIS_DEPTH, 0, -0.046]}}
    for side, s in SIGN.items():
        p, lt, ls = PREFIX[side], THIGH[side], SHANK[side]
        out[f"thigh_{side}"] = {
            f"{p}FLE": [0, -lt, s * 0.048], f"{p}FME": [0, -lt, -s * 0.048],
            f"{p}FTC": [0.012, -0.031, s * 0.081], f"{p}WAND1": [0.021, -0.203, s * 0.093]}
        out[f"shank_{side}"] = {
            f"{p}FAL": [0, -ls, s * 0.035], f"{p}TAM": [0, -ls, -s * 0.035],
            f"{p}FAX": [-0.012, -0.052, s * 0.049], f"{p}TTC": [0.041, -0.071, s * 0.002],
            f"{p}WAND2": [0.003, -0.252, s * 0.071]}
        # heel and the metatarsal heads' midpoint on the foot's u axis line (same v, w = 0)
        out[f"foot_{side}"] = {
            f"{p}FCC": [-0.052, -0.047, 0], f"{p}FM1": [0.151, -0.047, -s * 0.036],
            f"{p}FM5": [0.129, -0.047, s * 0.036]}
    return {b: {k: np.array(v, float) for k, v in pts.items()} for b, pts in out.items()}


LOCAL = local_points()


@dataclass
class Subject:
    """A pelvis pose per frame and each joint's rotation (deg) per frame and side:
    hip: thigh = pelvis · Rz(flexion) · Rx(s·adduction) · Ry(s·internal rotation);
    knee: shank = thigh · Rz(−flexion) · Ry(torsion) (a hinge about the thigh's w);
    ankle: foot = shank · Rz(dorsiflexion) · Rx(s·inversion) (a universal joint),
    with s = +1 on the right, −1 on the left (medial is −s·w)."""

    pelvis_origin: np.ndarray
    pelvis_axes: np.ndarray
    angles: dict[str, np.ndarray] = field(default_factory=dict)  # "hip_flexion_r" → deg (n,)

    @property
    def n(self) -> int:
        return len(self.pelvis_origin)

    def angle(self, name: str) -> np.ndarray:
        return np.radians(self.angles.get(name, np.zeros(self.n)))

    def segments(self) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """Each body's origin (n × 3) and axes (n × 3 × 3, columns u, v, w)."""
        out = {"pelvis": (self.pelvis_origin, self.pelvis_axes)}
        for side, s in SIGN.items():
            a = {name: self.angle(f"{name}_{side}") for name in JOINT_ANGLES}
            pelvis_o, pelvis_r = out["pelvis"]
            hip = pelvis_o + pelvis_r @ harrington_mm(PELVIS_WIDTH, PELVIS_DEPTH, side)
            thigh = pelvis_r @ rz(a["hip_flexion"]) @ rx(s * a["hip_adduction"]) \
                @ ry(s * a["hip_rotation"])
            knee = hip + thigh @ np.array([0, -THIGH[side], 0])
            shank = thigh @ rz(-a["knee_flexion"]) @ ry(np.full(self.n, TORSION[side]))
            ankle = knee + shank @ np.array([0, -SHANK[side], 0])
            foot = shank @ rz(a["ankle_dorsiflexion"]) @ rx(s * a["ankle_inversion"])
            out.update({f"thigh_{side}": (hip, thigh), f"shank_{side}": (knee, shank),
                        f"foot_{side}": (ankle, foot)})
        return out

    def markers(self) -> dict[str, np.ndarray]:
        seg = self.segments()
        return {label: seg[body][0] + seg[body][1] @ xyz
                for body, points in LOCAL.items() for label, xyz in points.items()}

    def trial(self, labels: tuple[str, ...]) -> Trial:
        m = self.markers()
        return Trial("synthetic.trc", labels, np.stack([m[label] for label in labels], 1), 100.0)

    def expected_clinical(self) -> dict[str, np.ndarray]:
        """The clinical angles (deg) implied by the rotations: knee and ankle exactly the
        imposed rotations; the hip's flexion and rotation the dot-product angles of the ISB
        sequence, asin(sin(flexion)·cos(adduction)) and asin(sin(rotation)·cos(adduction))."""
        out = {}
        for side in SIGN:
            f, a, r = (self.angle(f"{n}_{side}") for n in JOINT_ANGLES[:3])
            out[f"hip_flexion_{side}"] = np.degrees(np.arcsin(np.sin(f) * np.cos(a)))
            out[f"hip_adduction_{side}"] = np.degrees(a)
            out[f"hip_rotation_{side}"] = np.degrees(np.arcsin(np.sin(r) * np.cos(a)))
            for name in JOINT_ANGLES[3:]:
                out[f"{name}_{side}"] = np.degrees(self.angle(f"{name}_{side}"))
        return out


LAB = np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])  # pelvis u, v, w → lab x, z, −y


def walking_subject(n: int = 50) -> Subject:
    """A smooth pelvis pose and smoothly varying rotations at every joint, sides out of phase."""
    t = np.linspace(0.0, 1.0, n)
    ph = 2 * np.pi * t
    origin = np.stack([1.2 * t, 0.02 * np.sin(ph), 0.93 + 0.01 * np.sin(2 * ph)], 1)
    axes = LAB @ rz(np.radians(8 + 3 * np.sin(2 * ph))) @ rx(np.radians(4 * np.sin(ph))) \
        @ ry(np.radians(6 * np.sin(ph + 0.3)))
    angles = {}
    for side, shift in (("r", 0.0), ("l", np.pi)):
        p = ph + shift
        angles.update({
            f"hip_flexion_{side}": 12 + 22 * np.sin(p),
            f"hip_adduction_{side}": 3 + 5 * np.sin(p + 1.0),
            f"hip_rotation_{side}": -2 + 7 * np.sin(p + 2.0),
            f"knee_flexion_{side}": 35 - 30 * np.cos(p),
            f"ankle_dorsiflexion_{side}": 2 + 9 * np.sin(p + 0.5),
            f"ankle_inversion_{side}": 3 + 5 * np.sin(p + 1.3)})
    return Subject(origin, axes, angles)


def test_subject_builder_places_joint_centres_as_defined() -> None:
    """The builder's own geometry: knee centre mid-epicondyles, ankle centre mid-malleoli, the
    heel and the metatarsal heads' midpoint on the foot's u axis line, segments rigid."""
    subject = walking_subject()
    seg, m = subject.segments(), subject.markers()
    for side, p in PREFIX.items():
        np.testing.assert_allclose(0.5 * (m[f"{p}FLE"] + m[f"{p}FME"]), seg[f"shank_{side}"][0],
                                   atol=1e-15)
        np.testing.assert_allclose(0.5 * (m[f"{p}FAL"] + m[f"{p}TAM"]), seg[f"foot_{side}"][0],
                                   atol=1e-15)
        heel_to_toes = 0.5 * (m[f"{p}FM1"] + m[f"{p}FM5"]) - m[f"{p}FCC"]
        u = seg[f"foot_{side}"][1][:, :, 0]
        np.testing.assert_allclose(np.cross(heel_to_toes, u), 0.0, atol=1e-15)
        np.testing.assert_allclose(np.linalg.norm(seg[f"shank_{side}"][0] - seg[f"thigh_{side}"][0],
                                                  axis=1), THIGH[side], atol=1e-14)
        np.testing.assert_allclose(np.linalg.norm(seg[f"foot_{side}"][0] - seg[f"shank_{side}"][0],
                                                  axis=1), SHANK[side], atol=1e-14)


# --- 1. segment frames ------------------------------------------------------------------------

def _check_frames(frames, rot: np.ndarray, origin: np.ndarray, right: np.ndarray) -> None:
    np.testing.assert_allclose(frames.origin, origin, atol=1e-12, rtol=0)
    np.testing.assert_allclose(frames.axes, rot, atol=1e-12, rtol=0)
    np.testing.assert_allclose(np.linalg.det(frames.axes), 1.0, atol=1e-12)
    w = frames.axes[:, :, 2]
    assert (np.einsum("fi,fi->f", w, right) > 0.99 * np.linalg.norm(right, axis=1)).all()


@pytest.mark.parametrize("side", ["r", "l"])
def test_segment_frames_recover_known_rotations_and_origins(side: str) -> None:
    rng = np.random.default_rng({"r": 11, "l": 12}[side])
    n, s = 7, SIGN[side]
    rot = random_rotations(rng, n)
    origin = rng.normal(scale=0.6, size=(n, 3))

    def at(local) -> np.ndarray:
        return origin + rot @ np.asarray(local, float)

    # the subject's right, from his ASIS (pelvis in the same orientation as the segment)
    r_asis, l_asis = at([0, 0, 0.121]), at([0, 0, -0.121])
    right = r_asis - l_asis
    # PSIS off the mid-sagittal plane (mid-PSIS at w = +0.01): still in the u-w plane
    pelvis = pelvis_frames(r_asis, l_asis, at([-0.152, 0, 0.05]), at([-0.152, 0, -0.03]))
    _check_frames(pelvis, rot, origin, right)

    knee = [0, -0.43, 0]
    lateral, medial = [0, -0.43, s * 0.047], [0, -0.43, -s * 0.047]
    thigh = thigh_frames(origin, at(lateral), at(medial), side)
    _check_frames(thigh, rot, origin, right)
    assert np.sign(thigh.local(at(lateral))[:, 2]).tolist() == [s] * n  # left: lateral at −w
    np.testing.assert_allclose(thigh.local(at(knee)), np.tile(knee, (n, 1)), atol=1e-12)

    lateral, medial = [0, -0.39, s * 0.034], [0, -0.39, -s * 0.034]
    shank = shank_frames(origin, at(lateral), at(medial), side)
    _check_frames(shank, rot, origin, right)
    assert np.sign(shank.local(at(lateral))[:, 2]).tolist() == [s] * n

    # heel and the metatarsal heads' midpoint on a line along u, the heads apart along w
    # (the first, medial, more anterior than the fifth)
    heel, first, fifth = [-0.06, -0.05, 0], [0.16, -0.05, -s * 0.038], [0.12, -0.05, s * 0.038]
    foot = foot_frames(origin, at(heel), at(first), at(fifth), side)
    _check_frames(foot, rot, origin, right)
    assert np.sign(foot.local(at(fifth))[:, 2]).tolist() == [s] * n


def test_frames_are_anatomical_for_a_standing_subject() -> None:
    """Standing in the lab (anterior +x, superior +z, right −y): the thigh frames' axes are
    x, z, −y on both sides from real-looking landmarks (lateral epicondyle at the side's own
    outside)."""
    up, fwd, right = np.array([0, 0, 1.0]), np.array([1.0, 0, 0]), np.array([0, -1.0, 0])
    hip = {"r": np.array([[0, -0.09, 0.9]]), "l": np.array([[0, 0.09, 0.9]])}
    for side in ("r", "l"):
        outside = right if side == "r" else -right
        knee = hip[side] - 0.42 * up
        frames = thigh_frames(hip[side], knee + 0.05 * outside, knee - 0.05 * outside, side)
        np.testing.assert_allclose(frames.axes[0], np.column_stack([fwd, up, right]), atol=1e-15)


# --- 2. Harrington -----------------------------------------------------------------------------

@pytest.mark.parametrize(("width", "depth"), [(0.236, 0.148), (0.21, 0.17), (0.275, 0.121)])
def test_harrington_hip_centre_follows_the_mm_regression(width: float, depth: float) -> None:
    for side in ("r", "l"):
        np.testing.assert_allclose(harrington_hip_centre(width, depth, side),
                                   harrington_mm(width, depth, side), atol=1e-12, rtol=0)


def test_harrington_hip_centre_worked_example() -> None:
    # PW = 236 mm, PD = 148 mm: x = −0.24·148 − 9.9 = −45.42, y = −0.30·236 − 10.9 = −81.7,
    # z = 0.33·236 + 7.3 = 85.18 (mm), + on the right
    np.testing.assert_allclose(harrington_hip_centre(0.236, 0.148, "r"),
                               [-0.04542, -0.0817, 0.08518], atol=1e-12, rtol=0)
    np.testing.assert_allclose(harrington_hip_centre(0.236, 0.148, "l"),
                               [-0.04542, -0.0817, -0.08518], atol=1e-12, rtol=0)


# --- 3. calibration round trip -----------------------------------------------------------------

@pytest.fixture(scope="module")
def walking(template):
    subject = walking_subject()
    trial = subject.trial(template.marker_labels)
    cal = calibrate(template, trial)
    return subject, trial, cal, yaml.safe_load(cal.text)


@pytest.fixture(scope="module")
def walking_solved(walking):
    _, trial, cal, _ = walking
    personal = parse_model(cal.text, "personal.yaml")
    run = solve_trial(personal, trial, SolveOptions(method="nrm-wls", dynamics=False))
    clinical = {a.name: a.clinical(run.result.theta[:, k]) for k, a in enumerate(personal.angles)}
    return personal, run, clinical


def test_trial_has_every_label_the_template_uses(template, walking) -> None:
    _, trial, _, _ = walking
    used = set(template.marker_labels) | set(template.landmarks.values())
    assert used <= set(trial.labels)
    assert len(used) == 28 and len(trial.labels) == 28


def test_calibration_measures_lengths_and_pelvis(walking) -> None:
    _, _, cal, _ = walking
    heel, first, fifth = (LOCAL["foot_r"][f"R_{k}"] for k in ("FCC", "FM1", "FM5"))
    foot = float(np.linalg.norm(0.5 * (first + fifth) - heel))
    expected = {"thigh_r": THIGH["r"], "shank_r": SHANK["r"], "foot_r": foot,
                "thigh_l": THIGH["l"], "shank_l": SHANK["l"], "foot_l": foot}
    assert set(cal.lengths) == set(expected)
    for name, length in expected.items():
        assert abs(cal.lengths[name] - length) < 1e-9, name
    assert abs(cal.pelvis_width - PELVIS_WIDTH) < 1e-9
    assert abs(cal.pelvis_depth - PELVIS_DEPTH) < 1e-9
    assert cal.frames == (0, 50) and cal.mass is None


def test_calibration_writes_every_marker_and_joint_centre(template, walking) -> None:
    _, _, _, doc = walking
    bodies = doc["bodies"]
    for tp in template.tracked_points:
        np.testing.assert_allclose(bodies[tp.body]["points"][tp.point], LOCAL[tp.body][tp.marker],
                                   atol=1e-9, rtol=0, err_msg=f"{tp.body}.{tp.point}")
    for side in ("r", "l"):
        np.testing.assert_allclose(bodies["pelvis"]["points"][f"HJC_{side}"],
                                   harrington_mm(PELVIS_WIDTH, PELVIS_DEPTH, side), atol=1e-9,
                                   rtol=0)
        thigh, shank = bodies[f"thigh_{side}"]["points"], bodies[f"shank_{side}"]["points"]
        np.testing.assert_allclose(thigh["HJC"], 0.0, atol=1e-12)
        np.testing.assert_allclose(thigh["KJC"], [0, -THIGH[side], 0], atol=1e-9, rtol=0)
        np.testing.assert_allclose(shank["KJC"], 0.0, atol=1e-12)
        np.testing.assert_allclose(shank["AJC"], [0, -SHANK[side], 0], atol=1e-9, rtol=0)
        np.testing.assert_allclose(bodies[f"foot_{side}"]["points"]["AJC"], 0.0, atol=1e-12)


def test_calibration_writes_the_joint_axes(walking) -> None:
    subject, _, _, doc = walking
    seg = subject.segments()
    for side in ("r", "l"):
        thigh, shank = (seg[f"{b}_{side}"][1][0] for b in ("thigh", "shank"))
        vectors = doc["bodies"][f"shank_{side}"]["vectors"]
        # the hinge: the thigh's w in the shank frame (off the shank's w by the torsion)
        hinge = shank.T @ thigh[:, 2]
        assert abs(hinge[0]) > 0.1  # the torsion makes this a non-trivial check
        np.testing.assert_allclose(vectors["knee_axis"], hinge, atol=1e-9, rtol=0)
        # the shank-fixed vector that is the thigh's u at zero flexion (⟂ to the hinge)
        anterior = ry(np.array([TORSION[side]]))[0].T @ [1.0, 0.0, 0.0]
        np.testing.assert_allclose(vectors["knee_anterior"], anterior, atol=1e-9, rtol=0)
        # the universal joint's foot-fixed arm is the foot's u (the inversion axis)
        arm = doc["bodies"][f"foot_{side}"]["vectors"]["ankle_arm"]
        np.testing.assert_allclose(arm, [1.0, 0.0, 0.0], atol=1e-9, rtol=0)


def test_calibration_writes_frame_poses_and_parses(walking) -> None:
    subject, _, cal, doc = walking
    seg = subject.segments()
    for body in BODIES:
        pose = doc["bodies"][body]["pose"]
        origin, axes = seg[body][0][0], seg[body][1][0]
        np.testing.assert_allclose(pose["r"], origin, atol=5.1e-7, rtol=0)
        for k, key in enumerate("uvw"):
            np.testing.assert_allclose(pose[key], axes[:, k], atol=1e-9, rtol=0)
        assert not {"mass", "com", "inertia"} & set(doc["bodies"][body])
    assert "subject" not in doc
    personal = parse_model(cal.text, "personal.yaml")
    assert [b.name for b in personal.bodies] == list(BODIES)
    assert not personal.has_inertia and personal.subject_mass is None


def test_calibration_uses_the_requested_frames(template, walking) -> None:
    subject, trial, _, _ = walking
    cal = calibrate(template, trial, frames=(17, 31))
    assert cal.frames == (17, 31)
    pelvis = yaml.safe_load(cal.text)["bodies"]["pelvis"]["pose"]
    np.testing.assert_allclose(pelvis["r"], subject.pelvis_origin[17], atol=5.1e-7, rtol=0)
    np.testing.assert_allclose(pelvis["u"], subject.pelvis_axes[17][:, 0], atol=1e-9, rtol=0)
    assert abs(cal.lengths["thigh_l"] - THIGH["l"]) < 1e-9


def test_personal_model_tracks_the_markers_exactly(walking_solved) -> None:
    _, run, _ = walking_solved
    assert run.result.converged.all()
    assert run.ed.mean() < 1e-6 and run.ed.max() < 1e-6


def test_personal_model_gives_the_imposed_knee_and_dorsiflexion(walking, walking_solved) -> None:
    subject = walking[0]
    _, _, clinical = walking_solved
    expected = subject.expected_clinical()
    for side in ("r", "l"):
        for name in ("knee_flexion", "ankle_dorsiflexion"):
            key = f"{name}_{side}"
            np.testing.assert_allclose(clinical[key], subject.angles[key], atol=1e-6, rtol=0,
                                       err_msg=key)
            np.testing.assert_allclose(expected[key], subject.angles[key], atol=1e-12)


def test_personal_model_gives_the_hip_angles(walking, walking_solved) -> None:
    subject = walking[0]
    _, _, clinical = walking_solved
    expected = subject.expected_clinical()
    seg = subject.segments()
    for side in ("r", "l"):
        f, a, r = (subject.angles[f"{n}_{side}"] for n in JOINT_ANGLES[:3])
        # adduction: exact, with its sign
        np.testing.assert_allclose(clinical[f"hip_adduction_{side}"], a, atol=1e-6, rtol=0)
        moving = np.abs(a) > 0.5
        assert (np.sign(clinical[f"hip_adduction_{side}"][moving]) == np.sign(a[moving])).all()
        # flexion and rotation: the dot-product angles of the constructed frames, which the
        # analytic asin(sin·cos(adduction)) matches, within cos(adduction) of the imposed ones
        pelvis, thigh = seg["pelvis"][1], seg[f"thigh_{side}"][1]
        s = SIGN[side]
        theta_f = np.degrees(np.arccos(np.einsum("fi,fi->f", pelvis[:, :, 0], thigh[:, :, 1])))
        theta_r = np.degrees(np.arccos(np.einsum("fi,fi->f", pelvis[:, :, 2], thigh[:, :, 0])))
        np.testing.assert_allclose(theta_f - 90, expected[f"hip_flexion_{side}"], atol=1e-9)
        np.testing.assert_allclose(s * (theta_r - 90), expected[f"hip_rotation_{side}"],
                                   atol=1e-9)
        for name, imposed in (("hip_flexion", f), ("hip_rotation", r)):
            key = f"{name}_{side}"
            np.testing.assert_allclose(clinical[key], expected[key], atol=1e-6, rtol=0,
                                       err_msg=key)
            # the cos(adduction) approximation: close to, but not the same as, the imposed angle
            assert np.abs(clinical[key] - imposed).max() < 1.0, key
        assert np.abs(expected[f"hip_flexion_{side}"] - f).max() > 0.05


def test_ankle_vectors_are_anatomical_when_the_calibration_frames_are_inverted(
        walking, walking_solved) -> None:
    """The foot's up vector and the inversion angle must not depend on the inversion held during
    the calibration frames (here 3° ± 5°): inversion is zero when the shank's w is ⟂ to the
    foot's v (the anatomical neutral), as dorsiflexion is zero when the shank's v is ⟂ to the
    foot's u (which does hold)."""
    subject, _, _, doc = walking
    _, _, clinical = walking_solved
    errors = {}
    for side in ("r", "l"):
        up = doc["bodies"][f"foot_{side}"]["vectors"]["ankle_up"]
        errors[f"ankle_up_{side}"] = float(np.abs(np.subtract(up, [0.0, 1.0, 0.0])).max())
        key = f"ankle_inversion_{side}"
        errors[key] = float(np.abs(clinical[key] - subject.angles[key]).max())
    assert max(errors.values()) < 1e-6, errors


# --- 4. clinical sign conventions ----------------------------------------------------------------

def pure_motion(name: str, side: str, value: float, n_static: int = 6,
                n_ramp: int = 10) -> Subject:
    """A still pelvis (tilted off the lab axes); static frames in the anatomical neutral, then
    one joint rotation on one side ramping to ``value`` (deg) at the last frame."""
    n = n_static + n_ramp
    ramp = np.concatenate([np.zeros(n_static), np.linspace(0.0, 1.0, n_ramp + 1)[1:]])
    pose = LAB @ rz(np.radians([5.0]))[0] @ rx(np.radians([3.0]))[0] @ ry(np.radians([-4.0]))[0]
    origin = np.tile([0.3, -0.1, 0.92], (n, 1))
    return Subject(origin, np.tile(pose, (n, 1, 1)), {f"{name}_{side}": value * ramp})


def _angle(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip(a @ b / np.linalg.norm(a) / np.linalg.norm(b),
                                              -1.0, 1.0))))


def physical_effect(subject: Subject, name: str, side: str) -> tuple[float, float]:
    """The motion as seen on the markers, first to last frame, in the (still) pelvis's
    anatomical directions: (signed component of the defining displacement, rotation in deg)."""
    m, seg = subject.markers(), subject.segments()
    p = PREFIX[side]
    pelvis = subject.pelvis_axes[0]
    anterior, superior = pelvis[:, 0], pelvis[:, 1]
    medial = -SIGN[side] * pelvis[:, 2]
    hip = seg[f"thigh_{side}"][0]
    knee = 0.5 * (m[f"{p}FLE"] + m[f"{p}FME"])
    ankle = 0.5 * (m[f"{p}FAL"] + m[f"{p}TAM"])
    toes = 0.5 * (m[f"{p}FM1"] + m[f"{p}FM5"])
    if name == "hip_flexion":        # the knee moves anteriorly
        return (knee[-1] - knee[0]) @ anterior, _angle(knee[0] - hip[0], knee[-1] - hip[-1])
    if name == "hip_adduction":      # the knee moves towards the midline
        return (knee[-1] - knee[0]) @ medial, _angle(knee[0] - hip[0], knee[-1] - hip[-1])
    if name == "hip_rotation":       # the thigh's anterior turns medially: the lateral
        # epicondyle comes forward, the knee centre stays
        assert np.linalg.norm(knee[-1] - knee[0]) < 1e-12
        line = m[f"{p}FLE"] - m[f"{p}FME"]
        return (m[f"{p}FLE"][-1] - m[f"{p}FLE"][0]) @ anterior, _angle(line[0], line[-1])
    if name == "knee_flexion":       # the ankle moves posteriorly
        return -(ankle[-1] - ankle[0]) @ anterior, _angle(ankle[0] - knee[0],
                                                          ankle[-1] - knee[-1])
    if name == "ankle_dorsiflexion":  # the toes go up
        return (toes[-1] - toes[0]) @ superior, _angle(toes[0] - m[f"{p}FCC"][0],
                                                       toes[-1] - m[f"{p}FCC"][-1])
    assert name == "ankle_inversion"  # the sole turns to face medially
    sole = np.cross(m[f"{p}FM1"] - m[f"{p}FCC"], m[f"{p}FM5"] - m[f"{p}FCC"])
    sole *= -np.sign(sole[0] @ superior)  # the plantar normal, inferior in the neutral
    return sole[-1] @ medial / np.linalg.norm(sole[-1]), _angle(sole[0], sole[-1])


MOTIONS = [("hip_flexion", 20.0), ("hip_adduction", 10.0), ("hip_rotation", 10.0),
           ("knee_flexion", 30.0), ("ankle_dorsiflexion", 10.0), ("ankle_inversion", 10.0)]


@pytest.mark.parametrize("side", ["r", "l"])
@pytest.mark.parametrize(("name", "value"), MOTIONS)
def test_clinical_angle_signs(template, name: str, value: float, side: str) -> None:
    subject = pure_motion(name, side, value)
    component, rotation = physical_effect(subject, name, side)
    assert component > 1e-3, component
    assert abs(rotation - value) < 1e-9
    trial = subject.trial(template.marker_labels)
    cal = calibrate(template, trial, frames=(0, 6))  # the static, neutral frames
    personal = parse_model(cal.text, "personal.yaml")
    run = solve_trial(personal, trial, SolveOptions(method="nrm-wls", dynamics=False))
    assert run.ed.mean() < 1e-6
    last = {a.name: float(a.clinical(run.result.theta[-1, k]))
            for k, a in enumerate(personal.angles)}
    target = f"{name}_{side}"
    assert last[target] > 0
    assert abs(last[target] - value) < 1e-6, last
    others = {k: v for k, v in last.items() if k != target}
    assert max(abs(v) for v in others.values()) < 1e-6, others
    first = [float(a.clinical(run.result.theta[0, k])) for k, a in enumerate(personal.angles)]
    assert max(abs(v) for v in first) < 1e-6  # neutral in the static frames


# --- 5. inertia with --mass ----------------------------------------------------------------------

@pytest.fixture(scope="module")
def walking_file(tmp_path_factory, template):
    path = tmp_path_factory.mktemp("calibrate") / "walk.trc"
    subject = walking_subject()
    trial = subject.trial(template.marker_labels)
    write_trial(path, list(trial.labels), trial.markers, trial.rate)
    return path


def test_cli_with_mass_writes_de_leva_inertia(walking_file: Path) -> None:
    mass = 73.5
    out = walking_file.parent / "subject.yaml"
    result = run_cli("calibrate", TEMPLATE, walking_file, "-o", out, "--mass", mass,
                     "--frames", "0:50")
    assert result.exit_code == 0, (result.output, result.exception)
    doc = yaml.safe_load(out.read_text())
    assert doc["subject"] == {"mass": mass}
    for body in BODIES:
        assert {"mass", "com", "inertia"} <= set(doc["bodies"][body]), body
    model = load_model(out)
    assert model.has_inertia and model.subject_mass == mass
    fractions = {"thigh": 0.1416, "shank": 0.0433, "foot": 0.0137}  # de Leva (1996), males
    for side in ("r", "l"):
        for segment, fraction in fractions.items():
            got = doc["bodies"][f"{segment}_{side}"]["mass"]
            assert abs(got - fraction * mass) < 5.1e-5, (segment, side, got)
        thigh = doc["bodies"][f"thigh_{side}"]
        # the thigh's CoM 40.95 % of the hip→knee length from the hip centre, along −v
        np.testing.assert_allclose(thigh["com"], [0, -0.4095 * THIGH[side], 0], atol=5.1e-6,
                                   rtol=0)
        # its radii of gyration 32.9 % (sagittal, transverse) and 14.9 % (long axis v)
        m = 0.1416 * mass
        np.testing.assert_allclose(
            thigh["inertia"], [m * (0.329 * THIGH[side]) ** 2, m * (0.149 * THIGH[side]) ** 2,
                               m * (0.329 * THIGH[side]) ** 2], rtol=1e-3)
        np.testing.assert_allclose(doc["bodies"][f"shank_{side}"]["com"],
                                   [0, -0.4459 * SHANK[side], 0], atol=5.1e-6, rtol=0)


def test_cli_without_mass_writes_no_inertia(walking_file: Path) -> None:
    out = walking_file.parent / "kinematic.yaml"
    result = run_cli("calibrate", TEMPLATE, walking_file, "-o", out)
    assert result.exit_code == 0, (result.output, result.exception)
    assert "no --mass" in result.stderr
    model = load_model(out)
    assert not model.has_inertia and model.subject_mass is None

"""Plug-in Gait's upper-body angles and segments (plugin_gait/upper.py).

Independent references: rotations built here from elementary ones with known angles, the
expected outputs derived by hand from Vicon's definitions (each output's Cardan sequence, the
segments it relates and its per-side signs), scipy's Euler angles for the Cardan
decomposition, mirror symmetry (Vicon's per-side signs read a mirrored motion alike), and
Vicon's own upper-body outputs in the shared Nexus trial HC030A05 (skipped without
../shared/data).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import ezc3d
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from fccgrb_cli.anatomy.frames import pelvis_frames
from fccgrb_cli.model import load_model
from fccgrb_cli.model.subject import Sided
from fccgrb_cli.plugin_gait.angles import pig_axes, progression_frame
from fccgrb_cli.plugin_gait.outputs import upper_body_missing
from fccgrb_cli.plugin_gait.upper import (
    MARKERS,
    UpperGeometry,
    cardan,
    output_names,
    segments,
    upper_angles,
)


def rot(axis: str, deg: float) -> np.ndarray:
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    return {"x": np.array([[1, 0, 0], [0, c, -s], [0, s, c]]),
            "y": np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]]),
            "z": np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])}[axis]


def seq(order: str, a: float, b: float, c: float) -> np.ndarray:
    return rot(order[0], a) @ rot(order[1], b) @ rot(order[2], c)


# Each segment's Plug-in Gait axes in a neutral posture (upright, arms hanging, progression
# along the laboratory's x): the thorax's y points right and its z down; the humerus's x points
# back (away from the forearm), its y right; the radius and hand as the humerus.
NEUTRAL = {"pelvis": np.eye(3), "thorax": rot("x", 180), "head": np.eye(3),
           **{f"{seg}_{s}": rot("z", 180) for s in "lr" for seg in ("humerus", "radius", "hand")}}


def angles(**changed: np.ndarray) -> dict[str, np.ndarray]:
    frames = {k: changed.get(k, v)[None].copy() for k, v in NEUTRAL.items()}
    return {k: v[0] for k, v in upper_angles(frames, np.eye(3)).items()}


@pytest.mark.parametrize("order", ["xyz", "xzy", "yxz", "yzx", "zxy", "zyx"])
def test_cardan_decomposes_each_sequence_as_scipy_does(order: str) -> None:
    rng = np.random.default_rng(3)
    prox = Rotation.random(20, random_state=4).as_matrix()
    rel = Rotation.from_euler(order.upper(), rng.uniform(-80, 80, (20, 3)), degrees=True)
    dist = prox @ rel.as_matrix()
    got = np.degrees(cardan(prox, dist, order))
    np.testing.assert_allclose(got, rel.as_euler(order.upper(), degrees=True), atol=1e-9)


def test_neutral_posture_reads_zero_everywhere() -> None:
    out = angles()
    assert set(out) == set(output_names())
    for name, value in out.items():
        np.testing.assert_allclose(value, 0.0, atol=1e-9, err_msg=name)


# Thorax, spine and neck: the upright segment turned by R_y(α) R_x(β) R_z(γ) (α about the
# left axis, β about the floating forward one, γ about the long one), as the pelvis's angles.
A, B, C = 20.0, 15.0, 30.0


def test_thorax_in_the_progression_frame() -> None:
    out = angles(thorax=seq("yxz", A, B, C) @ rot("x", 180))
    np.testing.assert_allclose(out["LThoraxAngles"], [A, B, -C], atol=1e-9)
    np.testing.assert_allclose(out["RThoraxAngles"], [A, -B, C], atol=1e-9)


def test_head_in_the_progression_frame() -> None:
    out = angles(head=seq("yxz", A, B, C))
    np.testing.assert_allclose(out["LHeadAngles"], [-A, B, -C], atol=1e-9)
    np.testing.assert_allclose(out["RHeadAngles"], [-A, -B, C], atol=1e-9)


def test_spine_is_the_pelvis_relative_to_the_thorax() -> None:
    out = angles(pelvis=seq("yxz", A, B, C))
    np.testing.assert_allclose(out["LSpineAngles"], [-A, B, -C], atol=1e-9)
    np.testing.assert_allclose(out["RSpineAngles"], [-A, -B, C], atol=1e-9)
    # the thorax turning instead, about its own axes
    out = angles(thorax=rot("x", 180) @ rot("y", 10))
    np.testing.assert_allclose(out["LSpineAngles"], [-10, 0, 0], atol=1e-9)


def test_neck_is_the_thorax_relative_to_the_head() -> None:
    out = angles(thorax=seq("yxz", A, B, C) @ rot("x", 180))
    np.testing.assert_allclose(out["LNeckAngles"], [-A, B, -C], atol=1e-9)
    np.testing.assert_allclose(out["RNeckAngles"], [-A, -B, C], atol=1e-9)
    out = angles(head=rot("y", 10))
    np.testing.assert_allclose(out["LNeckAngles"], [10, 0, 0], atol=1e-9)
    np.testing.assert_allclose(out["RHeadAngles"], [-10, 0, 0], atol=1e-9)


def test_shoulder_is_the_humerus_relative_to_the_thorax_in_x_y_z() -> None:
    # the humerus turned from neutral by R_x(α) R_y(β) R_z(γ) about its own axes
    turn = seq("xyz", A, B, C)
    out = angles(humerus_l=NEUTRAL["humerus_l"] @ turn, humerus_r=NEUTRAL["humerus_r"] @ turn)
    np.testing.assert_allclose(out["LShoulderAngles"], [B, -A, -C], atol=1e-9)
    np.testing.assert_allclose(out["RShoulderAngles"], [B, A, C], atol=1e-9)


def test_elbow_and_wrist_in_y_x_z() -> None:
    turn = seq("yxz", A, B, C)
    radius = {f"radius_{s}": NEUTRAL[f"radius_{s}"] @ turn for s in "lr"}
    out = angles(**radius, **{f"hand_{s}": radius[f"radius_{s}"] for s in "lr"})
    for side in "LR":
        np.testing.assert_allclose(out[f"{side}ElbowAngles"], [A, B, C], atol=1e-9)
    out = angles(**{f"hand_{s}": NEUTRAL[f"hand_{s}"] @ turn for s in "lr"})
    np.testing.assert_allclose(out["LWristAngles"], [A, -B, -C], atol=1e-9)
    np.testing.assert_allclose(out["RWristAngles"], [A, B, C], atol=1e-9)


def test_shoulder_continuity_turns_about_its_middle_angle() -> None:
    # An arm raised forward past 90° and on: the x–y–z sequence's middle angle (output X)
    # passes its ±90° limit (not on it: there the two other angles are indeterminate); the
    # outputs run on continuously as Vicon writes them.
    lift = np.linspace(1.0, 171.0, 35)
    humerus = np.stack([NEUTRAL["humerus_l"] @ rot("y", -a) for a in lift])
    frames = {k: np.repeat(v[None], len(lift), axis=0) for k, v in NEUTRAL.items()}
    frames["humerus_l"] = humerus
    out = upper_angles(frames, np.eye(3))["LShoulderAngles"]
    assert np.max(np.abs(np.diff(out, axis=0))) < 6.0
    np.testing.assert_allclose(out[:, 0], -lift, atol=1e-9)


GENERATED = {  # one side's arm (the left) and a thorax and head in the sagittal plane, metres
    "CLAV": [0.06, 0.0, 1.42], "C7": [-0.08, 0.0, 1.47], "STRN": [0.09, 0.0, 1.25],
    "T10": [-0.1, 0.0, 1.22], "LFHD": [0.08, 0.07, 1.66], "RFHD": [0.08, -0.07, 1.66],
    "LBHD": [-0.1, 0.07, 1.68], "RBHD": [-0.1, -0.07, 1.68],
    "LSHO": [-0.01, 0.19, 1.44], "LELB": [-0.04, 0.22, 1.15], "LWRA": [0.17, 0.2, 1.02],
    "LWRB": [0.16, 0.26, 1.05], "LFIN": [0.25, 0.24, 0.98],
}
GEOMETRY = UpperGeometry(0.007, 0.0, {"l": 0.05, "r": 0.05}, {"l": 0.08, "r": 0.08},
                         {"l": 0.06, "r": 0.06}, {"l": 0.03, "r": 0.03})


def mirrored_markers() -> dict[str, np.ndarray]:
    out = {k: np.array(v)[None] for k, v in GENERATED.items()}
    for k in [k for k in GENERATED if k.startswith("L") and k[1:] in
              ("SHO", "ELB", "WRA", "WRB", "FIN")]:
        out["R" + k[1:]] = out[k] * [1.0, -1.0, 1.0]
    return out


def test_mirrored_arms_read_alike_on_both_sides() -> None:
    axes, origins = segments(mirrored_markers(), GEOMETRY)
    axes["pelvis"] = np.eye(3)[None]
    out = upper_angles(axes, np.eye(3))
    for joint in ("Shoulder", "Elbow", "Wrist"):
        np.testing.assert_allclose(out[f"L{joint}Angles"], out[f"R{joint}Angles"], atol=1e-9,
                                   err_msg=joint)
    np.testing.assert_allclose(out["LThoraxAngles"], out["RThoraxAngles"], atol=1e-9)
    for name in ("shoulder", "elbow", "wrist"):
        np.testing.assert_allclose(origins[f"{name}_r"], origins[f"{name}_l"] * [1, -1, 1],
                                   atol=1e-12)


def test_segment_axes_follow_the_markers() -> None:
    m = mirrored_markers()
    axes, origins = segments(m, GEOMETRY)
    for name, value in axes.items():  # right-handed orthonormal
        np.testing.assert_allclose(value[0].T @ value[0], np.eye(3), atol=1e-12, err_msg=name)
        assert np.linalg.det(value[0]) == pytest.approx(1.0)
    thorax = axes["thorax"][0]
    assert thorax[2, 2] < -0.99 and thorax[0, 0] > 0.99 and thorax[1, 1] < -0.99
    # the joint centres sit at their offsets from their markers, the elbow's at right angles
    shoulder, elbow, wrist = (origins[f"{k}_l"][0] for k in ("shoulder", "elbow", "wrist"))
    assert np.linalg.norm(shoulder - m["LSHO"][0]) == pytest.approx(0.05 + 0.007)
    assert np.linalg.norm(elbow - m["LELB"][0]) == pytest.approx(0.04 + 0.007)
    assert (shoulder - elbow) @ (m["LELB"][0] - elbow) == pytest.approx(0.0, abs=1e-12)
    wri = 0.5 * (m["LWRA"][0] + m["LWRB"][0])
    assert np.linalg.norm(wrist - wri) == pytest.approx(0.03 + 0.007)
    humerus = axes["humerus_l"][0]
    np.testing.assert_allclose(humerus[:, 2], (shoulder - elbow) / np.linalg.norm(
        shoulder - elbow), atol=1e-12)
    np.testing.assert_allclose(axes["radius_l"][0][:, 1], humerus[:, 1], atol=1e-12)


WALK = Path(__file__).resolve().parents[2] / "shared" / "data" / "c3d" / "plugin_gait" / \
    "HC030A05.c3d"


@pytest.mark.skipif(not WALK.exists(), reason="shared Plug-in Gait data absent")
def test_construction_equals_vicons_upper_body_outputs_on_the_shared_trial() -> None:
    """HC030A05 holds Vicon's upper-body angles: built here from its markers with its
    PROCESSING measurements and the 14 mm marker diameter Vicon used (its PROCESSING says 10;
    its lower-body outputs need 14 too, test_plugin_gait.py), every one equals Vicon's."""
    c3d = ezc3d.c3d(str(WALK))
    point = c3d["parameters"]["POINT"]
    labels = [s.strip() for key in ("LABELS", "LABELS2") if key in point
              for s in point[key]["value"]]
    xyz = c3d["data"]["points"][:3]
    points = {label: xyz[:, k, :].T for k, label in enumerate(labels)}
    proc = {k: float(v["value"][0]) for k, v in c3d["parameters"]["PROCESSING"].items()
            if isinstance(v, dict) and "value" in v}
    geometry = UpperGeometry(0.007, proc["HeadOffset"], *(
        {s: proc[f"{s.upper()}{key}"] / 1e3 for s in "lr"}
        for key in ("ShoulderOffset", "ElbowWidth", "WristWidth", "HandThickness")))
    axes, _ = segments({k: points[k] / 1e3 for k in MARKERS}, geometry)
    pelvis = pelvis_frames(*(points[k] / 1e3 for k in ("RASI", "LASI", "SACR", "SACR")))
    lab = progression_frame(pelvis.origin, pelvis.axes[:, :, 0], np.array([0.0, 0.0, 1.0]))
    out = upper_angles({**axes, "pelvis": pig_axes(pelvis.axes)}, lab)
    for name in output_names():
        np.testing.assert_allclose(out[name], points[name], atol=2e-3, err_msg=name)


def test_a_full_body_trial_without_the_arms_measurements_is_told_why() -> None:
    """The template gives no arm measurements: a trial with every upper-body marker is told
    which ones the subject's files lack; one without them (a lower-body trial) is told
    nothing, and neither is one whose subject gives them."""
    template = load_model(Path(__file__).resolve().parents[1] / "configs" / "models" /
                          "plugin_gait.yaml")
    said = upper_body_missing(template, MARKERS)
    assert said is not None and "no upper-body angles" in said
    for key in ("LeftShoulderOffset", "RightElbowWidth", "LeftWristWidth",
                "RightHandThickness"):
        assert key in said
    assert upper_body_missing(template, MARKERS[:-1]) is None
    arms = {name: Sided(value, value) for name, value in (
        ("shoulder_offset", 0.05), ("elbow_width", 0.08), ("wrist_width", 0.06),
        ("hand_thickness", 0.03))}
    measured = replace(template, measurements=replace(template.measurements, **arms))
    assert upper_body_missing(measured, MARKERS) is None

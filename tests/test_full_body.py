"""The whole-body templates and their calibration (``fccgrb calibrate`` on
configs/models/full_body*.yaml).

A synthetic subject standing in the template's anatomical posture (tests/synthetic_body.py:
every angle at 90°, trunk markers placed so that the ISB construction gives the thorax's own
frame, acromion markers where Rab et al.'s rule puts the shoulder centres) is calibrated, and
every upper-body point must come back where the subject has it: the markers in their segments,
the glenohumeral, elbow and wrist centres, the cervicothoracic joint (midway between C7 and the
suprasternal notch), the joint arms; the masses are de Leva's fractions typed here. On the
Qualisys walking trial (skipped without ../shared/data) the calibrated model tracks the markers
within 10 mm.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml
from synthetic_body import ISB_TRUNK, full_body_text

from fccgrb_cli.anatomy.full_body import personalize
from fccgrb_cli.model import load_model, parse_model
from fccgrb_cli.pipeline.synth import synthesize
from fccgrb_cli.trial.record import Trial

ROOT = Path(__file__).resolve().parents[1]
QUALISYS = ROOT / ".." / "shared" / "data" / "c3d" / "Qualisys.c3d"
PIG = ROOT / ".." / "shared" / "data" / "c3d" / "plugin_gait"
MASS = 70.0
# de Leva (1996) Table 4, males: mass fractions, typed from the paper
DE_LEVA = {"thorax": 0.1596 + 0.1633, "head": 0.0694, "upper_arm": 0.0271, "forearm": 0.0162,
           "hand": 0.0061}


@pytest.fixture(scope="module")
def standing():
    """The synthetic subject, its static trial and the model calibrated from it."""
    truth = parse_model(full_body_text(static=True), "truth.yaml")
    s = synthesize(truth, duration=0.05, rate=100.0)
    trial = Trial("static.c3d", s.labels, s.markers, 100.0)
    template = load_model(ROOT / "configs" / "models" / "full_body.yaml")
    text = personalize(template, trial, mass=MASS).text
    return truth, yaml.safe_load(text), parse_model(text, "personal.yaml")


def _points(doc: dict, body: str) -> dict[str, np.ndarray]:
    return {k: np.array(v) for k, v in doc["bodies"][body]["points"].items()}


def test_trunk_markers_and_joints_come_back(standing) -> None:
    truth, doc, _ = standing
    thorax = _points(doc, "thorax")
    for name, local in ISB_TRUNK.items():
        np.testing.assert_allclose(thorax[name], local, atol=2e-6)
    truth_thorax = truth.body("thorax").points
    for s in "rl":
        np.testing.assert_allclose(thorax[f"GH_{s}"], truth_thorax[f"GH_{s}"].local, atol=2e-6)
    # the cervicothoracic joint midway between C7 and the suprasternal notch
    np.testing.assert_allclose(thorax["CJC"], [-0.065, 0.0, 0.0], atol=2e-6)


def test_arm_segments_come_back(standing) -> None:
    truth, doc, _ = standing
    for s, side in (("r", "R"), ("l", "L")):
        upper, fore, hand = (_points(doc, f"{seg}_{s}") for seg in ("upper_arm", "forearm",
                                                                   "hand"))
        for body, calibrated in ((f"upper_arm_{s}", upper), (f"forearm_{s}", fore),
                                 (f"hand_{s}", hand)):
            for name, point in truth.body(body).points.items():
                if name in calibrated:
                    np.testing.assert_allclose(calibrated[name], point.local, atol=2e-6,
                                               err_msg=f"{body}.{name}")
        np.testing.assert_allclose(upper["EJC"], [0, -0.29, 0], atol=2e-6)
        np.testing.assert_allclose(fore["WJC"], [0, -0.26, 0], atol=2e-6)
        vectors = doc["bodies"][f"forearm_{s}"]["vectors"]
        np.testing.assert_allclose(vectors["elbow_arm"], [0, 1, 0], atol=1e-8)
        np.testing.assert_allclose(vectors["pronation_ref"], [1, 0, 0], atol=1e-8)
        vectors = doc["bodies"][f"hand_{s}"]["vectors"]
        np.testing.assert_allclose(vectors["wrist_arm"], [1, 0, 0], atol=1e-8)
        np.testing.assert_allclose(vectors["wrist_up"], [0, 1, 0], atol=1e-8)
        assert f"{side}_HLE" in upper and f"{side}_HM2" in hand


def test_head_markers_come_back_about_their_centroid(standing) -> None:
    truth, doc, _ = standing
    head = _points(doc, "head")
    names = ("L_HDF", "R_HDF", "L_HDB", "R_HDB")
    true = np.array([truth.body("head").points[n].local for n in names])
    got = np.array([head[n] for n in names])
    np.testing.assert_allclose(got, true - true.mean(axis=0), atol=2e-6)


def test_masses_are_de_levas(standing) -> None:
    _, doc, personal = standing
    for body, fraction in DE_LEVA.items():
        names = [body] if body in ("thorax", "head") else [f"{body}_r", f"{body}_l"]
        for name in names:
            assert doc["bodies"][name]["mass"] == pytest.approx(fraction * MASS, rel=1e-5)
    total = sum(b.inertia.mass for b in personal.bodies)
    assert total == pytest.approx(MASS, rel=1e-5)  # de Leva's fractions add up to the body


@pytest.mark.skipif(not QUALISYS.exists(), reason="../shared/data not present")
def test_qualisys_walking_trial_is_tracked_within_10_mm() -> None:
    import fccgrb_cli as fc

    template = load_model(ROOT / "configs" / "models" / "full_body.yaml")
    trial = fc.read_trial(str(QUALISYS))
    personal = parse_model(personalize(template, trial, mass=67.0).text, "personal.yaml")
    run = fc.solve(personal, trial, method="nrm-wls", dynamics=False, events="none",
                   engine="compiled")
    assert run.summary()["mean ED mm"] <= 10.0
    assert run.summary()["failed"] == 0


def test_a_signed_joint_angle_reads_within_half_a_turn() -> None:
    """Elbow pronation is a signed angle: its solve may start a turn away, its clinical value
    is the same joint position, moved by whole turns to a mean in (−180°, 180°]."""
    from fccgrb_cli.model.elements import AngularCoordinate

    angle = AngularCoordinate("pronation", "a", "w", "b", "u", clinical_sign=1,
                              axis=("b", "v"))
    clinical = np.array([120.0, 130.0, 140.0])
    for turns in (-2, -1, 0, 1, 3):
        theta = np.radians(clinical + 90.0 + 360.0 * turns)
        np.testing.assert_allclose(angle.clinical(theta), clinical, atol=1e-9)
    cosine = AngularCoordinate("knee", "a", "v", "b", "u", clinical_sign=1)
    np.testing.assert_allclose(cosine.clinical(np.radians([100.0])), [10.0])


@pytest.mark.skipif(not PIG.exists(), reason="../shared/data not present")
def test_plugin_gait_full_body_calibrates_from_its_static_and_solves_walking() -> None:
    """The PiG full-body template on the shared child trials: calibrated from the static with
    the measurements Nexus stored in it (PROCESSING: knee and ankle widths, marker diameter,
    body mass), then every frame of a stretch of the walking trial solved, markers within
    10 mm."""
    import fccgrb_cli as fc
    from fccgrb_cli.anatomy.calibrate import Measurements
    from fccgrb_cli.trial.processing import processing_measurements

    static = PIG / "HC030A01.c3d"
    m = processing_measurements(static)
    widths = Measurements(knee_width=float(np.mean([m.knee_width.left, m.knee_width.right])),
                          ankle_width=float(np.mean([m.ankle_width.left,
                                                     m.ankle_width.right])),
                          marker_diameter=m.marker_diameter)
    template = load_model(ROOT / "configs" / "models" / "full_body_plugin_gait.yaml")
    personal = parse_model(personalize(template, fc.read_trial(str(static)), mass=m.body_mass,
                                       measurements=widths).text, "personal.yaml")
    walk = fc.read_trial(str(PIG / "HC030A05.c3d"))
    walk = Trial(walk.path, walk.labels, walk.markers[:40], walk.rate)
    run = fc.solve(personal, walk, method="nrm-wls", dynamics=False, events="none",
                   engine="compiled", max_iter=500)
    assert run.summary()["failed"] == 0
    assert run.summary()["mean ED mm"] <= 10.0

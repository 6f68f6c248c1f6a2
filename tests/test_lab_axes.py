"""The lab's axes: the vertical found from the file, gravity and the gait
following it, the choice and its reasons printed and stored.

The walking trial ``../shared/data/c3d/Qualisys.c3d`` (z up, walking +x) is carried into other
labs by ``lab_frames.rotated_c3d`` — a BTS-like y-up lab (``POINT:Y_SCREEN +Y``), a lab whose z
points down with the subject walking along −y — and must give the same clinical angles, moments
and spatiotemporal parameters with no option: a rotation of the whole capture changes nothing
the body does. Before this, the y-up copy moved the hip moments by up to 0.58 N·m/kg and the
step width from 0.121 to 0.081 m.
"""

from __future__ import annotations

from pathlib import Path

import ezc3d
import numpy as np
import pytest
from cli_helpers import one_error_line, run_cli
from lab_frames import X_UP, Y_UP, Z_DOWN_WALK_MINUS_Y, rotated_c3d

import fccgrb_cli as fc
from fccgrb_cli.anatomy.lab_axes import lab_axes
from fccgrb_cli.core.errors import InputError
from fccgrb_cli.trial.record import Trial

ROOT = Path(__file__).resolve().parents[1]
GAIT = ROOT.parent / "shared" / "data" / "c3d" / "Qualisys.c3d"
needs_gait = pytest.mark.skipif(not GAIT.exists(), reason=f"{GAIT} is absent (a user's clone)")
TEMPLATE = ROOT / "configs" / "models" / "lower_limb.yaml"


@pytest.fixture(scope="module")
def personal() -> fc.Model:
    return fc.calibrate(fc.load_model(TEMPLATE), fc.read_trial(GAIT), mass=67)


@pytest.fixture(scope="module")
def original(personal) -> fc.Run:
    return fc.solve(personal, fc.read_trial(GAIT), filter_cutoff=6)


def _tracked(model: fc.Model, trial: Trial) -> np.ndarray:
    return trial.select([tp.marker for tp in model.tracked_points])


@needs_gait
def test_the_rotated_copy_is_the_same_capture_to_ezc3d(tmp_path: Path):
    """The test helper itself: ezc3d's points and platform forces, moments and centres of
    pressure of the copy are R times the original's (the analogs are in the plate's frame)."""
    copy = rotated_c3d(GAIT, tmp_path / "x_up.c3d", X_UP)
    a = ezc3d.c3d(str(GAIT), extract_forceplat_data=True)
    b = ezc3d.c3d(str(copy), extract_forceplat_data=True)
    seen = np.isfinite(a["data"]["points"][:3]).all(axis=0) & \
        (a["data"]["meta_points"]["residuals"][0] >= 0)
    np.testing.assert_allclose(b["data"]["points"][:3][:, seen],
                               (X_UP @ a["data"]["points"][:3].reshape(3, -1)).reshape(
                                   a["data"]["points"][:3].shape)[:, seen], atol=1e-3)
    for pa, pb in zip(a["data"]["platform"], b["data"]["platform"], strict=True):
        for key in ("force", "moment", "center_of_pressure"):
            before, after = np.asarray(pa[key]), np.asarray(pb[key])
            loaded = np.abs(np.asarray(pa["force"])[2]) > 20  # the CoP is defined there
            np.testing.assert_allclose(after[:, loaded], (X_UP @ before)[:, loaded],
                                       rtol=1e-5, atol=1e-3)


@needs_gait
@pytest.mark.parametrize("rotation, screen, up, walking", [
    (Y_UP, ("+X", "+Y"), "+y", "+x"),
    (Z_DOWN_WALK_MINUS_Y, None, "-z", "-y"),
], ids=["y-up", "z-down"])
def test_a_rotated_lab_gives_the_same_clinical_answers_with_no_option(
        personal, original, tmp_path: Path, rotation, screen, up, walking):
    trial = fc.read_trial(rotated_c3d(GAIT, tmp_path / "lab.c3d", rotation, screen))
    run = fc.solve(personal, trial, filter_cutoff=6)
    assert run.axes.vertical == up and run.axes.chosen_by == "file"
    np.testing.assert_allclose(run.model.gravity, 9.81 * -rotation @ [0, 0, 1], atol=1e-12)
    assert np.argmax(np.abs(run.axes.forward)) == "xyz".index(walking[1])
    assert np.sign(run.axes.forward["xyz".index(walking[1])]) == (1 if walking[0] == "+" else -1)
    a, b = original.clinical, run.clinical
    assert np.abs(b.angles - a.angles).max() < 1e-6  # deg
    assert np.abs(b.moments_per_kg - a.moments_per_kg).max() < 1e-6  # N·m/kg
    for side in ("left", "right"):
        before, after = original.gait.cycles[side], run.gait.cycles[side]
        np.testing.assert_allclose(after.parameters, before.parameters, atol=1e-9)
        np.testing.assert_allclose(after.start, before.start, atol=1e-12)
    np.testing.assert_allclose(run.gait.forward, rotation @ original.gait.forward, atol=1e-9)
    # the residual force on the pelvis is the same vector, turned with the lab
    np.testing.assert_allclose(run.dynamics.inverse.residual_force,
                               original.dynamics.inverse.residual_force @ rotation.T,
                               atol=1e-6)


@needs_gait
def test_the_chosen_vertical_is_printed_and_stored(personal, tmp_path: Path):
    """`fccgrb solve` on a y-up copy: stderr names the vertical and why; the step width is the
    z-up trial's 0.121 m (0.081 when gravity stayed −z); the results file holds the axes."""
    model = tmp_path / "personal.yaml"
    model.write_text(personal.text, encoding="utf-8")
    trial = rotated_c3d(GAIT, tmp_path / "bts_like.c3d", Y_UP, ("+X", "+Y"))
    out = tmp_path / "r.h5"
    result = run_cli("solve", model, trial, "--filter-cutoff", "6", "-o", out)
    assert result.exit_code == 0, result.output
    note = next(line for line in result.stderr.splitlines() if "lab axes" in line)
    assert note.startswith("fccgrb: lab axes: vertical +y (force plates 1, 2")
    assert "POINT:Y_SCREEN +Y agrees" in note and "walking along +x" in note
    width = next(line for line in result.stdout.splitlines() if line.startswith("step width"))
    assert width.split()[-2:] == ["0.121", "0.111"]
    run = next(iter(fc.read_results(out).values()))
    assert run.axes.vertical == "+y" and run.axes.gravity == (0.0, -9.81, 0.0)
    assert "force plates 1, 2" in run.axes.why
    assert run.model.gravity == (0.0, -9.81, 0.0)


@needs_gait
def test_calibrate_in_a_rotated_lab_writes_the_same_subject(personal, tmp_path: Path):
    """The personal model from an x-up copy: the same local coordinates (to the file's 1 µm),
    poses in the copy's frame, gravity along −x; solving the z-up original with it turns the
    gravity back."""
    copy = fc.read_trial(rotated_c3d(GAIT, tmp_path / "x_up.c3d", X_UP))
    turned = fc.calibrate(fc.load_model(TEMPLATE), copy, mass=67)
    assert turned.gravity == (-9.81, 0.0, 0.0)
    for a, b in zip(personal.bodies, turned.bodies, strict=True):
        for name, point in a.points.items():
            np.testing.assert_allclose(b.points[name].local, point.local, atol=1.5e-6)
        np.testing.assert_allclose(b.pose.r, X_UP @ np.array(a.pose.r), atol=1.5e-6)
    axes = lab_axes(turned, fc.read_trial(GAIT), _tracked(turned, fc.read_trial(GAIT)))
    assert axes.vertical == "+z" and axes.gravity == (0.0, 0.0, -9.81)


@needs_gait
def test_plates_and_markers_that_disagree_are_an_error(personal):
    """Markers turned y-up over plates whose force still says +z: no silent choice."""
    trial = fc.read_trial(GAIT)
    turned = Trial(trial.path, trial.labels, trial.markers @ Y_UP.T, trial.rate)
    with pytest.raises(InputError, match=r"ambiguous: force plates 1, 2: .* along \+z; "
                                         r"markers: .* \+y; .* pass --vertical"):
        lab_axes(personal, turned, _tracked(personal, turned))


@needs_gait
def test_the_option_overrides_the_file_and_says_where_they_disagree(personal):
    trial = fc.read_trial(GAIT)
    axes = lab_axes(personal, trial, _tracked(personal, trial), "+y")
    assert axes.gravity == (0.0, -9.81, 0.0) and axes.chosen_by == "option"
    assert any("--vertical +y, but force plates 1, 2" in w for w in axes.warnings)
    assert any("--vertical +y, but markers" in w for w in axes.warnings)


@needs_gait
def test_markers_alone_tell_the_vertical_and_the_screen_alone_does_not(personal, tmp_path):
    """A TRC (no plates, no screen) in a y-up lab: the markers say +y. A file whose only cue is
    POINT:Y_SCREEN: gravity stays the model's, with a warning naming what was found."""
    trial = fc.read_trial(GAIT)
    trc = Trial(str(tmp_path / "walk.trc"), trial.labels, trial.markers @ Y_UP.T, trial.rate)
    axes = lab_axes(personal, trc, _tracked(personal, trc))
    assert axes.vertical == "+y" and axes.why.startswith("markers: the model's pose fitted")
    blank = tmp_path / "screen_only.c3d"
    c3d = ezc3d.c3d()
    c3d["parameters"]["POINT"]["RATE"]["value"] = [100.0]
    c3d["parameters"]["POINT"]["LABELS"]["value"] = ["M"]
    c3d.add_parameter("POINT", "Y_SCREEN", ["+Y"])
    c3d["data"]["points"] = np.ones((4, 1, 10))
    c3d.write(str(blank))
    empty = Trial(str(blank), ("M",), np.ones((10, 1, 3)), 100.0)
    nothing = np.full((10, len(personal.tracked_points), 3), np.nan)
    axes = lab_axes(personal, empty, nothing)
    assert axes.gravity == personal.gravity and axes.chosen_by == "model"
    assert len(axes.warnings) == 1 and "nothing tells the lab's vertical" in axes.warnings[0]
    assert "POINT:Y_SCREEN +Y" in axes.warnings[0]


def test_a_mechanism_keeps_its_own_frame(tmp_path: Path):
    """The five-bar's ground carries joints: its gravity is the model's whatever the markers
    do, and a --vertical against it is one error line."""
    model = ROOT / "configs" / "models" / "five_bar.yaml"
    trial = tmp_path / "t.c3d"
    assert run_cli("synth", model, "-o", trial, "--duration", "0.2").exit_code == 0
    loaded = fc.load_model(model)
    read = fc.read_trial(trial)
    turned = Trial(read.path, read.labels, read.markers @ Y_UP.T, read.rate)
    axes = lab_axes(loaded, turned, turned.markers)
    assert axes.chosen_by == "ground" and axes.gravity == loaded.gravity and not axes.warnings
    one_error_line(run_cli("solve", model, trial, "--vertical", "+y", "-o", tmp_path / "r.h5"),
                   "--vertical +y", "five_bar.yaml", "ties its bodies to the ground",
                   "joint", "expected --vertical auto or +z")
    assert not (tmp_path / "r.h5").exists()


# ---- a template without legs (an upper limb on a pelvis) -------------------------------------

UPPER = ROOT / "configs" / "models" / "upper_limb.yaml"


def _upper_static(path: Path, lean_deg: float) -> Path:
    """A still subject in the upper-limb template's own pose (z up, facing +x), leaning
    forward by ``lean_deg`` about the lab's y axis: every landmark and tracked marker where the
    template puts it (the acromion 40 mm above the shoulder centre), 30 frames with 0.5 mm
    noise, written as a z-up C3D (POINT:Y_SCREEN +Z, as Nexus writes)."""
    from fccgrb_cli.trial.c3d import write_markers

    model = fc.load_model(UPPER)
    where: dict[str, np.ndarray] = {}
    for body in model.bodies:
        pose = body.pose
        frame = np.column_stack([pose.u, pose.v, pose.w])
        for name, point in body.points.items():
            where[name] = np.asarray(pose.r) + frame @ np.asarray(point.local)
        if body.name == "thorax":
            where["ACRO_tip"] = np.asarray(pose.r) + frame @ (
                np.asarray(body.points["GH_r"].local) + np.array([0.0, 0.04, 0.0]))
    labels = sorted({*model.marker_labels, *model.landmarks.values()})
    a = np.radians(lean_deg)
    lean = np.array([[np.cos(a), 0.0, np.sin(a)], [0.0, 1.0, 0.0], [-np.sin(a), 0.0, np.cos(a)]])
    pivot = where["ASISr"] * [1, 0, 1]
    points = np.array([pivot + lean @ (where[label] - pivot) for label in labels])
    rng = np.random.default_rng(7)
    markers = points[None] + rng.normal(0.0, 5e-4, size=(30, *points.shape))
    write_markers(path, labels, markers, 100.0)
    c3d = ezc3d.c3d(str(path))
    c3d.add_parameter("POINT", "X_SCREEN", ["+X"])
    c3d.add_parameter("POINT", "Y_SCREEN", ["+Z"])
    c3d.write(str(path))
    return path


@pytest.mark.parametrize("lean, screen, vertical, expected_up", [
    (0.0, None, "auto", "+y"),         # the markers alone tell
    (35.0, ("+X", "+Y"), "auto", "+y"),  # leaning: the markers lean to +y, Y_SCREEN confirms
    (35.0, None, "auto", None),        # leaning, no screen axis: nothing tells (warned)
    (35.0, ("+X", "+Z"), "auto", None),  # the screen names another axis: nothing tells
    (35.0, None, "+y", "+y"),          # stated
], ids=["upright", "leaning-screen", "leaning-alone", "leaning-screen-disagrees", "stated"])
def test_an_upper_limb_calibrated_in_a_y_up_lab_gets_its_gravity(
        tmp_path: Path, lean, screen, vertical, expected_up):
    """The upper-limb template (no legs: the pelvis calibrated alone) from a still subject in
    a y-up copy of a z-up static: the personal model's gravity points down +y, whether the
    markers tell it alone or, leaning 35° (past the 25° a cue may be off an axis), with
    POINT:Y_SCREEN naming the axis they lean to; stated by --vertical; and where nothing tells,
    the template's −z stays with a warning. It used to stay −z in every case, silently."""
    from fccgrb_cli.anatomy.full_body import personalize
    from fccgrb_cli.model import parse_model

    static = _upper_static(tmp_path / "z_up.c3d", lean)
    copy = rotated_c3d(static, tmp_path / "y_up.c3d", Y_UP, screen)
    if screen is None:  # a lab whose software wrote no screen axes
        c3d = ezc3d.c3d(str(copy))
        for key in ("X_SCREEN", "Y_SCREEN"):
            c3d["parameters"]["POINT"][key]["value"] = [""]
        c3d.write(str(copy))
    result = personalize(fc.load_model(UPPER), fc.read_trial(copy), mass=70.0,
                         vertical=vertical)
    personal = parse_model(result.text, str(tmp_path / "personal.yaml"))
    if expected_up is None:
        np.testing.assert_allclose(personal.gravity, (0.0, 0.0, -9.81))
        assert any("nothing tells the lab's vertical" in w for w in result.axes.warnings)
    else:
        np.testing.assert_allclose(personal.gravity, (0.0, -9.81, 0.0), atol=1e-12)
        assert result.axes.vertical == expected_up
    assert result.text.splitlines()[2].startswith("# lab axes: vertical ")

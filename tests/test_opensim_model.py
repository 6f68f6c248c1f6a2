"""OpenSim model files read and converted: OpenSim's own synthetic markers recovered by the
forward kinematics of its own IK solution (an independent check of the joints' conventions, the
SimmSpline knee and the frames), both file layouts, and hostile files refused in one line."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fccgrb_cli.core.errors import InputError
from fccgrb_cli.model import load_model
from fccgrb_cli.model.osim.convert import body_poses, model_from_osim
from fccgrb_cli.model.osim.document import parse_osim, read_osim
from fccgrb_cli.system.compiled import Drive, compile_system
from fccgrb_cli.trial.record import read_trc
from tests.osim_text import knee_model

OPENSIM = Path(__file__).resolve().parents[2] / "shared" / "data" / "opensim"
IK_DIR = OPENSIM / "ik_gait2354_synthetic"
needs_data = pytest.mark.skipif(not IK_DIR.is_dir(), reason="../shared/data/opensim not here")


def read_mot(path: Path) -> tuple[list[str], np.ndarray, bool]:
    """Column names, rows and inDegrees of an OpenSim motion file (a few lines of numpy)."""
    lines = path.read_text().splitlines()
    end = next(k for k, line in enumerate(lines) if line.strip().lower() == "endheader")
    degrees = any(line.strip().lower() == "indegrees=yes" for line in lines[:end])
    names = lines[end + 1].split()
    rows = np.array([[float(v) for v in line.split()] for line in lines[end + 2:] if line.strip()])
    return names, rows, degrees or "SIMM Motion File" in "".join(lines[:end])


@needs_data
def test_forward_kinematics_of_opensims_solution_lands_on_its_synthetic_markers():
    osim = read_osim(IK_DIR / "subject01_simbody.osim")
    names, rows, degrees = read_mot(IK_DIR / "std_subject01_walk1_ik.mot")
    trial = read_trc(IK_DIR / "subject01_synthetic_marker_data.trc")
    motion = {c.name: c.motion for c in osim.coordinates}
    markers = {m.name: m for m in osim.markers}
    worst = 0.0
    for frame in range(0, len(rows), 6):
        values = {n: (np.radians(v) if degrees and motion[n] == "rotational" else v)
                  for n, v in zip(names[1:], rows[frame, 1:], strict=True)}
        pose = body_poses(osim, values)
        for k, label in enumerate(trial.labels):
            R, r = pose[markers[label].body]
            here = r + R @ np.asarray(markers[label].location)
            worst = max(worst, float(np.linalg.norm(here - trial.markers[frame, k])))
    # the .mot holds 4–6 significant digits: 0.1 mm is its rounding, a wrong axis order or
    # spline end condition is centimetres
    assert worst < 1e-4


@needs_data
def test_the_gait_model_converts_to_a_model_with_its_coordinates_and_markers(capsys):
    model = load_model(IK_DIR / "subject01_simbody.osim")
    assert "ignored ForceSet" in capsys.readouterr().err
    assert len(model.angles) == 23 and len(model.bodies) == 12
    assert model.angles[0].name == "pelvis_tilt" and model.angles[3].translational
    assert "R.Heel" in model.marker_labels and model.floating_bases == ()
    femur = model.body("femur_r").inertia
    assert femur.mass == 8.98403823 and femur.com == (0.0, -0.195031, 0.0)
    assert femur.tensor[0][0] == 0.17022071  # the file's inertia_xx
    system = compile_system(model, angles="coordinate", track=True)
    assert system.nq - system.topology_rank == 23
    phi = system.residual(system.pose(), Drive(ref=np.zeros((system.n_targets, 3))))
    assert np.abs(phi[system.kinds == 0]).max() < 1e-12


def test_both_layouts_give_the_same_bodies_and_frames():
    # the 4.x knee model and the same model written in the 3.x layout (joint inside its body)
    osim4 = parse_osim(knee_model().encode(), "knee4.osim")
    knee = osim4.joints[1]
    text3 = f"""<OpenSimDocument Version="30000"><Model name="knee">
<gravity>0 -9.80665 0</gravity><BodySet><objects><Body name="ground"/>
<Body name="thigh"><mass>8.0</mass><mass_center>0 -0.2 0.01</mass_center>
<inertia_xx>0.12</inertia_xx><inertia_yy>0.03</inertia_yy><inertia_zz>0.11</inertia_zz>
<inertia_xy>0.002</inertia_xy><inertia_xz>-0.001</inertia_xz><inertia_yz>0.004</inertia_yz>
<Joint><FreeJoint name="free"><parent_body>ground</parent_body>
<CoordinateSet><objects>{"".join(f'<Coordinate name="{n}"/>' for n in
                                   ("rx", "ry", "rz", "tx", "ty", "tz"))}</objects></CoordinateSet>
</FreeJoint></Joint></Body>
<Body name="shank"><mass>3.5</mass><Joint><PinJoint name="pin"><parent_body>thigh</parent_body>
<location_in_parent>0.1 -0.2 0.05</location_in_parent>
<orientation_in_parent>0.2 -0.1 0.3</orientation_in_parent>
<location>0 0.3 0</location><orientation>-0.1 0.2 0</orientation>
<CoordinateSet><objects><Coordinate name="knee"/></objects></CoordinateSet>
</PinJoint></Joint></Body></objects></BodySet>
<MarkerSet><objects><Marker name="S"><body>shank</body><location>0 1 0</location></Marker>
</objects></MarkerSet></Model></OpenSimDocument>"""
    osim3 = parse_osim(text3.encode(), "knee3.osim")
    assert osim3.bodies[0] == osim4.bodies[0]
    pin = osim3.joints[1]
    assert np.allclose(pin.parent.rotation, knee.parent.rotation)
    assert np.allclose(pin.child.translation, knee.child.translation)
    assert [c.motion for c in osim3.coordinates] == ["rotational"] * 3 + ["translational"] * 3 \
        + ["rotational"]
    assert pin.axes[0].axis == (0.0, 0.0, 1.0) and pin.axes[0].coordinate == "knee"


HOSTILE = {
    "a body named twice": (lambda t: t.replace('<Body name="shank">', '<Body name="thigh">'),
                           "body 'thigh' is named twice"),
    "a marker on a missing body": (lambda t: t.replace(
        "<socket_parent_frame>/bodyset/shank</socket_parent_frame><location>0.05",
        "<socket_parent_frame>/bodyset/tibia</socket_parent_frame><location>0.05"),
        "Marker[name=S1]: marker on '/bodyset/tibia'"),
    "a joint with an unknown parent": (lambda t: t.replace(
        "<socket_parent>/bodyset/thigh</socket_parent>",
        "<socket_parent>/bodyset/femur</socket_parent>"), "'/bodyset/femur' is neither"),
    "an unknown function type": (lambda t: t.replace("<SimmSpline", "<StepFunction", 1)
                                 .replace("</SimmSpline>", "</StepFunction>", 1),
                                 "unknown function type StepFunction"),
    "an unknown joint type": (lambda t: t.replace('<CustomJoint name="knee">',
                                                  '<EllipsoidJoint name="knee">')
                              .replace("</CustomJoint></objects>", "</EllipsoidJoint></objects>"),
                              "unknown joint type EllipsoidJoint"),
    "a non-finite number": (lambda t: t.replace("<mass>8.0</mass>", "<mass>nan</mass>"),
                            "Body[name=thigh]/mass: expected a finite number"),
    "a huge number": (lambda t: t.replace("<mass>8.0</mass>", "<mass>1e300</mass>"),
                      "expected a finite number of magnitude"),
    "an unrepresentable constraint": (lambda t: t.replace(
        "<ConstraintSet><objects>", '<ConstraintSet><objects><WeldConstraint name="w"/>'),
        "ConstraintSet/objects/WeldConstraint[name=w]: cannot represent a WeldConstraint"),
    "an unknown model element": (lambda t: t.replace(
        "<Ground name", '<MyController name="x"/><Ground name'),
        "MyController[name=x]: cannot represent a MyController"),
    "spline knots out of order": (lambda t: t.replace("-2 -1.2 -0.5", "-2 -0.2 -0.5"),
                                  "expected strictly increasing x values"),
    "a coupler on a missing coordinate": (lambda t: t.replace(
        "<ConstraintSet><objects>",
        "<ConstraintSet><objects><CoordinateCouplerConstraint name=\"c\">"
        "<coupled_coordinates_function><Constant><value>1</value></Constant>"
        "</coupled_coordinates_function><independent_coordinate_names>knee"
        "</independent_coordinate_names><dependent_coordinate_name>ghost"
        "</dependent_coordinate_name></CoordinateCouplerConstraint>"),
        "coordinate 'ghost' is not one of the model's"),
    "a DOCTYPE": (lambda t: t.replace('<?xml version="1.0" encoding="UTF-8" ?>',
                                      '<?xml version="1.0"?><!DOCTYPE x [<!ENTITY a "b">]>'),
                  "refused: a DOCTYPE"),
}


@pytest.mark.parametrize("case", sorted(HOSTILE))
def test_hostile_models_are_refused_in_one_line_naming_file_and_element(case, tmp_path):
    edit, message = HOSTILE[case]
    text = edit(knee_model())
    assert text != knee_model(), "the edit did not apply"
    path = tmp_path / "hostile.osim"
    path.write_text(text)
    with pytest.raises(InputError) as caught:
        load_model(path)
    line = str(caught.value)
    assert "\n" not in line and line.startswith(str(path)) and message in line, line


def test_a_good_generated_model_loads_with_one_note(tmp_path, capsys):
    path = tmp_path / "knee.osim"
    path.write_text(knee_model())
    model = load_model(path)
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "ignored ForceSet" in err
    assert [c.name for c in model.angles] == ["rx", "ry", "rz", "tx", "ty", "tz", "knee",
                                              "patella"]
    assert model_from_osim(read_osim(path)).bodies == model.bodies


def test_inertia_and_orientation_follow_opensims_conventions():
    # inertia: Ixx Iyy Izz Ixy Ixz Iyz; orientation: body-fixed X-Y-Z (scipy's intrinsic 'XYZ')
    from scipy.spatial.transform import Rotation

    from fccgrb_cli.model.osim.document import rotation_xyz

    thigh = parse_osim(knee_model().encode(), "knee.osim").bodies[0]
    assert thigh.inertia == ((0.12, 0.002, -0.001), (0.002, 0.03, 0.004), (-0.001, 0.004, 0.11))
    angles = (0.3, -0.7, 1.1)
    expected = Rotation.from_euler("XYZ", angles).as_matrix()
    assert np.allclose(rotation_xyz(angles), expected, atol=1e-14)


def test_check_refuses_a_hostile_model_in_one_line_and_writes_nothing(tmp_path):
    from cli_helpers import one_error_line, run_cli

    path = tmp_path / "hostile.osim"
    path.write_text(knee_model().replace("<mass>8.0</mass>", "<mass>-inf</mass>"))
    before = sorted(tmp_path.iterdir())
    one_error_line(run_cli("check", path), str(path),
                   "Model[name=knee]/BodySet/objects/Body[name=thigh]/mass")
    assert sorted(tmp_path.iterdir()) == before


@needs_data
def test_check_takes_opensims_gait_model():
    from cli_helpers import run_cli

    result = run_cli("check", IK_DIR / "subject01_simbody.osim")
    assert result.exit_code == 0, result.stderr
    # 23 coordinates, the two toes (no marker on them) held at their defaults in a solve
    assert "rank 146: 23 degrees of freedom, 2 of them held at their default values" \
        in result.stdout
    assert "MC Jacobian rank 167 of 167" in result.stdout
    assert "redundant equations: none" in result.stdout


def test_a_function_is_read_in_both_property_styles_and_never_assumed():
    # 3.x wraps a property (<function><SimmSpline>), 4.x names it (<SimmSpline name="function">)
    wrapped = knee_model().replace('<SimmSpline name="function">', "<function><SimmSpline>", 1)
    first = wrapped.index("<function><SimmSpline>")
    end = wrapped.index("</SimmSpline>", first) + len("</SimmSpline>")
    wrapped = wrapped[:end] + "</function>" + wrapped[end:]
    a = parse_osim(knee_model().encode(), "a.osim").joints[1].axes[3].function
    b = parse_osim(wrapped.encode(), "b.osim").joints[1].axes[3].function
    assert a == b and isinstance(a, type(b)) and a.terms(0.3)[0] != 0.0
    # a moving axis without a function is refused, not taken as linear
    start = knee_model().index('<SimmSpline name="function">')
    stop = knee_model().index("</SimmSpline>", start) + len("</SimmSpline>")
    bare = knee_model()[:start] + knee_model()[stop:]
    with pytest.raises(InputError, match="TransformAxis\\[name=translation1\\]: expected a "
                                         "function of knee"):
        parse_osim(bare.encode(), "bare.osim")


def test_a_4x_coordinates_motion_comes_from_the_transform_it_drives():
    """An OpenSim 4 CustomJoint's Coordinate states no motion_type: a coordinate that drives
    translation axes only is a translation (metres: exports and the degrees of a .mot leave
    it alone), one that drives a rotation axis a rotation, as OpenSim derives them."""
    import re

    from fccgrb_cli.model.osim.convert import parse_osim_model
    from tests.osim_text import knee_model

    stated = parse_osim_model(knee_model(), "knee.osim")
    text = re.sub(r"<motion_type>[^<]*</motion_type>", "", knee_model())
    derived = parse_osim_model(text, "knee.osim")
    kinds = {c.name: c.translational for c in derived.angles}
    assert kinds == {c.name: c.translational for c in stated.angles}
    assert kinds["tx"] and kinds["ty"] and kinds["tz"] and not kinds["rx"] and \
        not kinds["knee"]


def test_a_clamped_coordinate_outside_its_range_flags_its_frames():
    """OpenSim's IK keeps a clamped coordinate inside its range; a solve that lands outside it
    by more than 1° (another branch, swapped markers) has its frames flagged, naming the
    coordinate; inside it, or within the margin, nothing is."""
    import numpy as np

    from fccgrb_cli.model.osim.convert import parse_osim_model
    from fccgrb_cli.pipeline.assessment import clamped_range
    from tests.osim_text import knee_model

    text = knee_model().replace("<clamped>false</clamped>", "<clamped>true</clamped>", 1)
    model = parse_osim_model(text, "knee.osim")
    index = [k for k, a in enumerate(model.angles) if a.clamped]
    assert [model.angles[k].name for k in index] == ["rx"]  # the first coordinate: range ±3
    theta = np.zeros((4, len(model.angles)))
    theta[:, index[0]] = [0.0, 3.0 + np.radians(0.5), 3.0 + np.radians(2.0), -3.5]
    found = clamped_range(model, theta, index)
    assert found.frames.tolist() == [False, False, True, True]
    assert "rx" in found.detail and "outside its range" in found.detail


@pytest.mark.parametrize("held", [0, 2])
def test_check_counts_every_coordinate_and_says_which_a_solve_holds(tmp_path, held):
    # 8 coordinates (the free thigh's 6, the knee and the patella); with every marker moved onto
    # the thigh none sees the knee or the patella, which a solve then holds at their defaults
    from cli_helpers import run_cli

    text = knee_model()
    if held:
        head, markers = text.split("<MarkerSet>")
        text = head + "<MarkerSet>" + markers.replace("/bodyset/shank", "/bodyset/thigh")
    path = tmp_path / "knee.osim"
    path.write_text(text, encoding="utf-8")
    result = run_cli("check", path)
    assert result.exit_code == 0, result.stderr
    line = next(x for x in result.stdout.splitlines() if "topological equations" in x)
    assert ": 8 degrees of freedom" in line
    assert (f", {held} of them held at their default values" in line) == bool(held)

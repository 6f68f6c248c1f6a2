"""Plug-in Gait compatibility on the shared Nexus trials, to the targets below: calibrate
configs/models/plugin_gait.yaml from the static HC030A01 with no measurement typed (they come
from the C3D's PROCESSING group), solve the walking trial HC030A05 by mixed coordinates (the
default NRM-WLS), and compare every Plug-in Gait angle the run stores with the ones Vicon's
Plug-in Gait wrote into the same file (an independent reference): RMS over the trusted frames
≤ 1° for X (the sagittal components) and ≤ 2° for Y and Z, both sides.

Skipped without ../shared/data.
"""

from __future__ import annotations

from pathlib import Path

import ezc3d
import numpy as np
import pytest
import yaml
from cli_helpers import run_cli

from fccgrb_cli.plugin_gait import upper
from fccgrb_cli.plugin_gait.angles import output_names, pig_axes
from fccgrb_cli.results.runs import read_runs

ROOT = Path(__file__).resolve().parents[1]
TEMPLATE = ROOT / "configs" / "models" / "plugin_gait.yaml"
DATA = ROOT / ".." / "shared" / "data" / "c3d" / "plugin_gait"
STATIC, WALK = DATA / "HC030A01.c3d", DATA / "HC030A05.c3d"
pytestmark = pytest.mark.skipif(not WALK.exists(), reason="shared Plug-in Gait data absent")


def vicon(path: Path) -> tuple[dict[str, np.ndarray], dict[str, float]]:
    """Every point of a Nexus C3D (frames × 3, as stored) and its PROCESSING values."""
    c3d = ezc3d.c3d(str(path))
    point = c3d["parameters"]["POINT"]
    labels = [s.strip() for key in ("LABELS", "LABELS2") if key in point  # past 255: LABELS2
              for s in point[key]["value"]]
    xyz = c3d["data"]["points"][:3]
    proc = {k: float(v["value"][0]) for k, v in c3d["parameters"]["PROCESSING"].items()
            if isinstance(v, dict) and "value" in v}
    return {label: xyz[:, k, :].T for k, label in enumerate(labels)}, proc


@pytest.fixture(scope="module")
def solved(tmp_path_factory):
    folder = tmp_path_factory.mktemp("pig")
    personal, results = folder / "personal.yaml", folder / "walk.h5"
    out = run_cli("calibrate", TEMPLATE, STATIC, "-o", personal)
    assert out.exit_code == 0, out.output + out.stderr
    out = run_cli("solve", personal, WALK, "-o", results)
    assert out.exit_code == 0, out.output + out.stderr
    (run,) = read_runs(results).values()
    return personal, run


def test_calibration_takes_the_measurements_from_processing(solved):
    """The personalized model's subject section holds the file's own values (mm → m, rad →
    deg) and names the PROCESSING group; the static foot offsets it computed equal the ones
    Vicon wrote there (foot flat, the default)."""
    personal, _ = solved
    subject = yaml.safe_load(personal.read_text())["subject"]
    _, proc = vicon(STATIC)
    assert subject["mass"] == pytest.approx(proc["Bodymass"])
    for key, vicon_key in (("knee_width", "KneeWidth"), ("ankle_width", "AnkleWidth"),
                           ("leg_length", "LegLength")):
        assert subject[key]["left"] == pytest.approx(proc["L" + vicon_key] / 1e3)
        assert subject[key]["right"] == pytest.approx(proc["R" + vicon_key] / 1e3)
    assert subject["thigh_rotation"]["right"] == pytest.approx(
        np.degrees(proc["RThighRotation"]))
    assert subject["tibial_torsion"]["left"] == pytest.approx(np.degrees(proc["LTibialTorsion"]))
    assert "HC030A01.c3d PROCESSING" in subject["source"]
    for side in ("left", "right"):
        key = side[0].upper()
        assert subject["static_plantar_flexion"][side] == pytest.approx(
            np.degrees(proc[key + "StaticPlantFlex"]), abs=0.01)
        assert subject["static_rotation_offset"][side] == pytest.approx(
            np.degrees(proc[key + "StaticRotOff"]), abs=0.01)


def test_walking_angles_match_vicons(solved):
    _, run = solved
    points, _ = vicon(WALK)
    pig = run.plugin_gait
    assert run.trusted.all()
    assert set(pig.angles) == {*output_names(), *upper.output_names()}
    for name in output_names():  # this file holds no upper-body outputs of Vicon's
        ours, theirs = pig.angles[name], points[name]
        error = (ours - theirs + 180.0) % 360.0 - 180.0  # Vicon's angles run on past ±180
        rms = np.sqrt(np.mean(error ** 2, axis=0))
        assert rms[0] <= 1.0, (name, rms)
        assert rms[1] <= 2.0 and rms[2] <= 2.0, (name, rms)


def test_full_body_trial_gives_the_upper_bodys_angles_from_its_markers(solved):
    """The walking trial carries Plug-in Gait's full-body markers and its PROCESSING the arms'
    measurements: the calibration keeps them (mm → m) and the run stores the upper body's
    angles, equal to Plug-in Gait's construction applied here to the file's markers (read with
    ezc3d, mm) with those measurements, the spine from the run's solved pelvis."""
    personal, run = solved
    subject = yaml.safe_load(personal.read_text())["subject"]
    points, proc = vicon(WALK)
    _, static = vicon(STATIC)
    for key, vicon_key in (("shoulder_offset", "ShoulderOffset"), ("elbow_width", "ElbowWidth"),
                           ("wrist_width", "WristWidth"), ("hand_thickness", "HandThickness")):
        for side in ("left", "right"):
            assert subject[key][side] == pytest.approx(static[side[0].upper() + vicon_key] / 1e3)
    geometry = upper.UpperGeometry(
        subject["marker_diameter"] / 2, 0.0,
        *({s: proc[f"{s.upper()}{key}"] / 1e3 for s in "lr"}
          for key in ("ShoulderOffset", "ElbowWidth", "WristWidth", "HandThickness")))
    markers = {k: np.where(points[k] == 0, np.nan, points[k] / 1e3) for k in upper.MARKERS}
    axes, _ = upper.segments(markers, geometry)
    pelvis = np.stack([np.column_stack([run.q[f"pelvis.{e}.{c}"] for c in "xyz"])
                       for e in "uvw"], axis=2)
    expected = upper.upper_angles({**axes, "pelvis": pig_axes(pelvis)},
                                  run.plugin_gait.progression)
    for name in upper.output_names():
        np.testing.assert_allclose(run.plugin_gait.angles[name], expected[name], atol=1e-6,
                                   err_msg=name)
        # Vicon's, computed with a 14 mm marker diameter where PROCESSING says 10 (measured
        # worst: shoulder Z 1.17, elbow X 1.03 deg; 0 with 14 mm, test_plugin_gait_upper.py)
        error = (expected[name] - points[name] + 180.0) % 360.0 - 180.0
        assert np.sqrt(np.mean(error ** 2, axis=0)).max() <= 1.3, name


# Per joint: RMS bounds for X, Y, Z (N·mm/kg) and the power (W/kg), over both sides
# (measured, worst side: hip 24 / 11.3 / 3.4 and 0.052, knee 11.1 / 13.3 / 3.8 and 0.054,
# ankle 7.1 / 7.0 / 4.3 and 0.037).
KINETICS = {"Hip": (28.0, 13.0, 5.0, 0.06), "Knee": (13.0, 15.0, 5.0, 0.06),
            "Ankle": (9.0, 8.0, 5.0, 0.045)}


def test_walking_kinetics_match_vicons(solved):
    """Moments in N·mm/kg and powers in W/kg beside Vicon's, both sides, over the frames where
    Vicon wrote them, within ``KINETICS`` (with de Leva's inertia in place of Plug-in Gait's the
    hip's X was 72 and its power 0.16; N·m/kg for N·mm/kg would be 1000 times off)."""
    _, run = solved
    points, _ = vicon(WALK)
    pig = run.plugin_gait
    assert len(pig.moments) == len(pig.powers) == 6
    for name, ours in {**pig.moments, **pig.powers}.items():
        theirs = points[name]
        ok = np.isfinite(ours).all(axis=1) & np.isfinite(theirs).all(axis=1) \
            & np.any(theirs != 0, axis=1)
        rms = np.sqrt(np.mean((ours[ok] - theirs[ok]) ** 2, axis=0))
        *moment, power = KINETICS[next(j for j in KINETICS if j in name)]
        if name.endswith("Power"):
            assert rms[2] <= power, (name, rms)
        else:
            assert np.all(rms <= moment), (name, rms)


def test_plugin_gait_c3d_export_reads_back_in_plugin_gaits_layout(solved, tmp_path):
    """ezc3d reads the export: every output a 3-component point under its Plug-in Gait name,
    the run's values (float32), listed in POINT:ANGLES / MOMENTS / POWERS with Nexus's units;
    Vicon's own points of those names replaced, the markers, first frame and events kept."""
    personal, run = solved
    results = personal.parent / "walk.h5"
    target = tmp_path / "walk_pig.c3d"
    out = run_cli("export", results, "--format", "c3d", "--convention", "plugin-gait",
                  "-o", target)
    assert out.exit_code == 0, out.stderr
    assert "36 points of the trial with Plug-in Gait's names replaced" in out.stderr
    original, back = ezc3d.c3d(str(WALK)), ezc3d.c3d(str(target))
    point = back["parameters"]["POINT"]
    labels = [s.strip() for key in ("LABELS", "LABELS2") if key in point
              for s in point[key]["value"]]
    xyz = back["data"]["points"][:3]
    pig = run.plugin_gait
    for kind, group, unit in (("angles", "ANGLES", "deg"), ("moments", "MOMENTS", "Nmm"),
                              ("powers", "POWERS", "W")):
        assert point[f"{group[:-1]}_UNITS"]["value"] == [unit]
        listed = list(point[group]["value"])
        for name, values in pig.kinds()[kind].items():
            assert labels.count(name) == 1 and name in listed
            stored = xyz[:, labels.index(name), :].T
            np.testing.assert_allclose(stored, values, rtol=1e-6, atol=1e-3)
    assert len(pig.angles) == 24 and len(pig.moments) == 6 and len(pig.powers) == 6
    theirs, _ = vicon(WALK)
    for name in ("LKneeAngles", "RHipAngles", "LKneeMoment", "RAnklePower"):  # Vicon's units
        stored, k = xyz[:, labels.index(name), :].T, 2 if name.endswith("Power") else 0
        ok = np.isfinite(theirs[name]).all(axis=1) & np.any(theirs[name] != 0, axis=1)
        peak = np.abs(theirs[name][ok, k]).max()
        assert 0.5 * peak <= np.abs(stored[ok, k]).max() <= 2.0 * peak, name
    np.testing.assert_array_equal(xyz[:, labels.index("LASI"), :].T, theirs["LASI"])
    assert back["header"]["points"]["first_frame"] == original["header"]["points"]["first_frame"]
    np.testing.assert_array_equal(np.asarray(back["parameters"]["EVENT"]["TIMES"]["value"]),
                                  np.asarray(original["parameters"]["EVENT"]["TIMES"]["value"]))


def storage(path: Path) -> tuple[list[str], np.ndarray]:
    lines = path.read_text(encoding="utf-8").splitlines()
    end = lines.index("endheader")
    rows = np.array([[float(v) for v in line.split("\t")] for line in lines[end + 2:]])
    return lines[end + 1].split("\t"), rows


def test_opensim_mot_on_the_trials_clock(solved, tmp_path):
    """OpenSim's names, the time column from the trial's first frame ((286 − 1) / 100 s, its
    TRIAL:ACTUAL_START_FIELD), Plug-in Gait's angles under OpenSim's signs: this child walks
    with the pelvis tilted forward (PiG's tilt +), which OpenSim counts negative."""
    personal, run = solved
    target = tmp_path / "walk.mot"
    out = run_cli("export", personal.parent / "walk.h5", "--format", "mot", "--convention",
                  "opensim", "-o", target)
    assert out.exit_code == 0, out.stderr
    labels, rows = storage(target)
    start = ezc3d.c3d(str(WALK))["parameters"]["TRIAL"]["ACTUAL_START_FIELD"]["value"][0]
    np.testing.assert_allclose(rows[:, 0], (start - 1) / 100 + np.arange(len(rows)) / 100)
    column = {name: rows[:, k] for k, name in enumerate(labels)}
    a = run.plugin_gait.angles
    np.testing.assert_allclose(column["hip_flexion_r"], a["RHipAngles"][:, 0], atol=1e-8)
    np.testing.assert_allclose(column["knee_angle_l"], a["LKneeAngles"][:, 0], atol=1e-8)
    np.testing.assert_allclose(column["ankle_angle_r"], a["RAnkleAngles"][:, 0], atol=1e-8)
    assert column["pelvis_tilt"].mean() < -10 < 10 < a["LPelvisAngles"][:, 0].mean()


def test_opensim_rebuilds_the_solved_pelvis_and_thighs_from_the_mot(solved, tmp_path):
    """OpenSim reads the .mot (its own TimeSeriesTable: every column, the trial's clock, in
    degrees), and an OpenSim model with the pelvis's and hips' custom joints as OpenSim's gait
    models define them (pelvis: rotations about Z, X, Y of ground, then the translations; hips:
    Z, X, Y on the right, Z, −X, −Y on the left), driven by what it read, puts the pelvis and
    both thighs where the solve did (their axes in OpenSim's ground: X progression, Y up, Z
    right)."""
    osim = pytest.importorskip("opensim")
    personal, run = solved
    target = tmp_path / "walk.mot"
    run_cli("export", personal.parent / "walk.h5", "--format", "mot", "--convention",
            "opensim", "-o", target)
    ours, rows = storage(target)
    table = osim.TimeSeriesTable(str(target))
    labels = ["time", *table.getColumnLabels()]
    assert labels == ours and table.getTableMetaDataAsString("inDegrees") == "yes"
    np.testing.assert_allclose(np.array(table.getIndependentColumn()), rows[:, 0], atol=1e-9)
    rows = np.column_stack([rows[:, 0], *(table.getDependentColumn(name).to_numpy()
                                          for name in labels[1:])])
    model = osim.Model()

    def body(name: str, parent, coordinates: list[str], axes: list[tuple]) -> osim.Body:
        b = osim.Body(name, 1.0, osim.Vec3(0), osim.Inertia(0.1, 0.1, 0.1))
        transform = osim.SpatialTransform()
        slots = (transform.upd_rotation1, transform.upd_rotation2, transform.upd_rotation3,
                 transform.upd_translation1, transform.upd_translation2,
                 transform.upd_translation3)
        for k, slot in enumerate(slots):
            axis = slot()
            if k < len(coordinates):
                axis.setCoordinateNames(osim.ArrayStr(coordinates[k], 1))
                axis.set_axis(osim.Vec3(*axes[k]))
                axis.set_function(osim.LinearFunction())
            else:  # an unused translation
                axis.set_axis(osim.Vec3(*np.eye(3)[k - 3]))
                axis.set_function(osim.Constant(0))
        zero = osim.Vec3(0)
        joint = osim.CustomJoint(f"{name}_joint", parent, zero, zero, b, zero, zero, transform)
        model.addBody(b)
        model.addJoint(joint)
        return b

    pelvis = body("pelvis", model.getGround(), ["pelvis_tilt", "pelvis_list",
                                                "pelvis_rotation", "pelvis_tx", "pelvis_ty",
                                                "pelvis_tz"],
                  [(0, 0, 1), (1, 0, 0), (0, 1, 0), (1, 0, 0), (0, 1, 0), (0, 0, 1)])
    thighs = {s: body(f"femur_{s}", pelvis, [f"hip_flexion_{s}", f"hip_adduction_{s}",
                                             f"hip_rotation_{s}"],
                      [(0, 0, 1), (sign, 0, 0), (0, sign, 0)])
              for s, sign in (("r", 1), ("l", -1))}
    state = model.initSystem()
    x, left, up = run.plugin_gait.progression.T
    ground = np.stack([x, up, -left])  # rows: OpenSim's X, Y, Z in the laboratory
    bodies = {"pelvis": pelvis, "thigh_r": thighs["r"], "thigh_l": thighs["l"]}
    q = run.q
    for frame in range(0, len(rows), 20):
        for k, name in enumerate(labels[1:], start=1):
            if not name.startswith(("pelvis", "hip")):
                continue  # the knees and ankles have no bodies in this model
            value = rows[frame, k]
            model.getCoordinateSet().get(name).setValue(
                state, value if name in ("pelvis_tx", "pelvis_ty", "pelvis_tz")
                else np.radians(value), False)
        model.realizePosition(state)
        for name, b in bodies.items():
            R = b.getTransformInGround(state).R()
            got = np.array([[R.get(i, j) for j in range(3)] for i in range(3)])
            solved_axes = np.column_stack([q[f"{name}.{e}.{c}"][frame] for e in "uvw"
                                           for c in "xyz"]).reshape(3, 3).T
            np.testing.assert_allclose(got, ground @ solved_axes, atol=1e-6, err_msg=name)


def test_calibration_sources_in_order_and_missing_measurements(tmp_path):
    """A .vsk over the static's PROCESSING group, typed widths over both; without any source
    (a TRC has no PROCESSING group) one error lists the Vicon keys missing."""
    from cli_helpers import one_error_line

    from fccgrb_cli.trial.record import read_trial, write_trial

    vsk = tmp_path / "child.vsk"
    vsk.write_text('<KinematicModel><Parameters>'
                   '<StaticParameter NAME="LeftKneeWidth" VALUE="90"/>'
                   '<StaticParameter NAME="RightKneeWidth" VALUE="92"/>'
                   '<StaticParameter NAME="LeftAnkleWidth" VALUE="63"/>'
                   '</Parameters></KinematicModel>', encoding="utf-8")
    personal = tmp_path / "p.yaml"
    out = run_cli("calibrate", TEMPLATE, STATIC, "--subject", vsk, "--ankle-width", "60,58",
                  "-o", personal)
    assert out.exit_code == 0, out.stderr
    subject = yaml.safe_load(personal.read_text())["subject"]
    assert subject["knee_width"] == pytest.approx({"left": 0.090, "right": 0.092})
    assert subject["ankle_width"] == pytest.approx({"left": 0.060, "right": 0.058})
    assert subject["leg_length"]["left"] == pytest.approx(0.830)  # still PROCESSING's
    assert "child.vsk" in subject["source"] and "the command line" in subject["source"]
    static = read_trial(STATIC)
    trc = tmp_path / "static.trc"
    write_trial(trc, list(static.labels), static.markers, static.rate)
    one_error_line(run_cli("calibrate", TEMPLATE, trc, "-o", tmp_path / "q.yaml"),
                   "expected the subject measurements LLegLength, RLegLength, LKneeWidth")
    one_error_line(run_cli("calibrate", TEMPLATE, STATIC, "--subject", tmp_path / "s.txt",
                           "-o", tmp_path / "q.yaml"), "expected a subject file ending in")


def test_joint_powers_equal_the_models_generalized_forces_times_rates(solved):
    """Power is the same whichever way a joint's rotation is counted: the Newton–Euler moment
    at a hip or an ankle times the segments' relative angular velocity (Plug-in Gait's power,
    × body mass) equals Σ τ_k θ̇_k over that joint's angles, τ_k the classical model's
    generalized forces from its multipliers (an independent inverse dynamics): measured 1e-15
    of the peak at the ankles, 4e-5 at the hips (the thigh's balance takes the knee's load
    through its sliding joint and the pelvis's drivers; least squares). The knee's slide does
    work too (force × slide rate), so only hips and ankles are compared."""
    _, run = solved
    mass = run.model.subject_mass
    names = run.result.angle_names
    tau = run.dynamics.inverse.joint_moments
    rate = run.dynamics.kinematics.theta_d
    for side, s in (("L", "l"), ("R", "r")):
        for joint, angles, tol in (
                ("Hip", ("hip_flexion", "hip_adduction", "hip_rotation"), 1e-4),
                ("Ankle", ("ankle_dorsiflexion", "ankle_rotation"), 1e-9)):
            k = [names.index(f"{a}_{s}") for a in angles]
            theirs = (tau[:, k] * rate[:, k]).sum(axis=1)
            ours = run.plugin_gait.powers[f"{side}{joint}Power"][:, 2] * mass
            scale = np.abs(theirs).max()
            error = np.abs(ours - theirs).max() / scale
            assert error <= tol, (side + joint, error)

"""Vicon's files as Vicon writes them: the shared Nexus 1.4 lower-body session (PSIS markers and
no SACR, no marker diameter in PROCESSING) calibrated and solved with nothing typed, and the
other layouts Vicon's software writes, made here by rewriting copies of the shared files with
ezc3d (EVENT:TIMES as 2N values, an angle written in degrees, ``Marker Diameter`` spelt with a
space, a Workstation ``.mp`` subject file), read as the file means them.

Independent references: Vicon's own Plug-in Gait outputs in the same files (the ``...V``
points, the static foot offsets Nexus wrote into PROCESSING), the values written into the
rewritten copies here, and the chord geometry (the knee marker lies (knee width + marker
diameter) / 2 from the knee centre). Skipped without ../shared/data.
"""

from __future__ import annotations

from pathlib import Path

import ezc3d
import numpy as np
import pytest
import yaml
from cli_helpers import one_error_line, run_cli

from fccgrb_cli.core.errors import InputError
from fccgrb_cli.results.runs import read_runs

ROOT = Path(__file__).resolve().parents[1]
TEMPLATES = ROOT / "configs" / "models"
PIG = TEMPLATES / "plugin_gait.yaml"
NEXUS = ROOT / ".." / "shared" / "data" / "c3d" / "plugin_gait" / "btk_lowerbody_3fp"
STATIC, WALK = NEXUS / "PiG_Calibration3_FF.c3d", NEXUS / "PiG_Motion3_FF.c3d"
CHILD = ROOT / ".." / "shared" / "data" / "c3d" / "plugin_gait" / "HC030A01.c3d"
needs_nexus = pytest.mark.skipif(not WALK.exists(), reason="shared Nexus trials absent")
needs_child = pytest.mark.skipif(not CHILD.exists(), reason="shared Plug-in Gait data absent")


def points_of(path: Path) -> dict[str, np.ndarray]:
    """Every point of a C3D by label (frames × 3, as stored)."""
    c3d = ezc3d.c3d(str(path))
    point = c3d["parameters"]["POINT"]
    labels = [s.strip() for key in ("LABELS", "LABELS2") if key in point
              for s in point[key]["value"]]
    xyz = c3d["data"]["points"][:3]
    return {label: xyz[:, k, :].T for k, label in enumerate(labels)}


def processing_of(path: Path) -> dict[str, float]:
    group = ezc3d.c3d(str(path))["parameters"]["PROCESSING"]
    return {k: float(v["value"][0]) for k, v in group.items()
            if isinstance(v, dict) and "value" in v}


def rewritten(source: Path, target: Path, processing: dict[str, float | None] | None = None,
              times: np.ndarray | None = None) -> Path:
    """A copy of ``source`` with PROCESSING entries replaced (None: removed) and EVENT:TIMES
    replaced by ``times``."""
    c3d = ezc3d.c3d(str(source))
    group = c3d["parameters"]["PROCESSING"]
    for key, value in (processing or {}).items():
        if key in group:
            del group[key]
        if value is not None:
            c3d.add_parameter("PROCESSING", key, [float(value)])
    if times is not None:
        c3d["parameters"]["EVENT"]["TIMES"]["value"] = times
    c3d.write(str(target))
    return target


def calibrated(static: Path, target: Path, *args: object) -> tuple[dict, str]:
    out = run_cli("calibrate", PIG, static, "-o", target, *args)
    assert out.exit_code == 0, out.output + out.stderr
    return yaml.safe_load(target.read_text(encoding="utf-8")), out.stderr


# --- the shared Nexus 1.4 session, nothing typed ----------------------------------------------

@pytest.fixture(scope="module")
def nexus_run(tmp_path_factory):
    folder = tmp_path_factory.mktemp("nexus")
    personal, results = folder / "personal.yaml", folder / "walk.h5"
    model, stderr = calibrated(STATIC, personal)
    out = run_cli("solve", personal, WALK, "-o", results)
    assert out.exit_code == 0, out.output + out.stderr
    (run,) = read_runs(results).values()
    return model, stderr, run, results, out.stdout


@needs_nexus
def test_nexus_static_calibrates_with_nothing_typed(nexus_run):
    """No SACR (the PSIS midpoint stands for it) and no marker diameter (14 mm, Plug-in
    Gait's): one warning line each; the foot offsets the calibration computes equal the ones
    Nexus wrote into the same static's PROCESSING (foot flat) to 0.01°, so the pelvis, hips,
    knees and ankles it built are Vicon's."""
    model, stderr, _, _, _ = nexus_run
    warnings = stderr.splitlines()
    assert sum("no marker SACR: mid(LPSI,RPSI) stands for it" in w for w in warnings) == 1
    assert sum("no marker diameter" in w and "14 mm" in w for w in warnings) == 1
    subject = model["subject"]
    assert subject["marker_diameter"] == pytest.approx(0.014)
    assert subject["mass"] == pytest.approx(74.0)
    proc = processing_of(STATIC)
    for side in ("left", "right"):
        key = side[0].upper()
        assert subject["static_plantar_flexion"][side] == pytest.approx(
            np.degrees(proc[key + "StaticPlantFlex"]), abs=0.01)
        assert subject["static_rotation_offset"][side] == pytest.approx(
            np.degrees(proc[key + "StaticRotOff"]), abs=0.01)


@needs_nexus
def test_nexus_static_without_foot_flat_matches_its_own_processing(tmp_path):
    """The session processed with foot flat off: its static's offsets, computed here with
    --no-foot-flat, equal the ones Nexus wrote (to 0.01°)."""
    static = NEXUS / "PiG_Calibration3_noFF.c3d"
    model, _ = calibrated(static, tmp_path / "p.yaml", "--no-foot-flat")
    proc = processing_of(static)
    for side in ("left", "right"):
        key = side[0].upper()
        assert model["subject"]["static_plantar_flexion"][side] == pytest.approx(
            np.degrees(proc[key + "StaticPlantFlex"]), abs=0.01)


@needs_nexus
def test_foot_flat_option_read_from_the_offsets_the_static_records(tmp_path):
    """With no --foot-flat/--no-foot-flat, the option is the one whose static offsets equal
    the ones the subject's sources record: the session processed with foot flat off (its
    PROCESSING's offsets) calibrates without it, said in one warning, and its offsets equal
    Nexus's; the foot-flat session calibrates with it, saying nothing."""
    static = NEXUS / "PiG_Calibration3_noFF.c3d"
    model, stderr = calibrated(static, tmp_path / "p.yaml")
    assert sum("foot not flat: the static foot offsets" in w
               for w in stderr.splitlines()) == 1
    proc = processing_of(static)
    for side in ("left", "right"):
        key = side[0].upper()
        assert model["subject"]["static_plantar_flexion"][side] == pytest.approx(
            np.degrees(proc[key + "StaticPlantFlex"]), abs=0.01)
        assert model["subject"]["static_rotation_offset"][side] == pytest.approx(
            np.degrees(proc[key + "StaticRotOff"]), abs=0.01)
    _, stderr = calibrated(STATIC, tmp_path / "ff.yaml")
    assert "foot offsets" not in stderr and "foot not flat" not in stderr


@needs_nexus
def test_recorded_offsets_matching_neither_option_keep_foot_flat_and_say_so(tmp_path):
    """Recorded offsets 1° off both options' (another static's, say): foot flat, the default,
    with one warning giving how far they lie from either."""
    proc = processing_of(STATIC)
    shifted = {key: proc[key] + np.radians(1.0) for key in (
        "LStaticPlantFlex", "RStaticPlantFlex", "LStaticRotOff", "RStaticRotOff")}
    static = rewritten(STATIC, tmp_path / "static.c3d", shifted)
    model, stderr = calibrated(static, tmp_path / "p.yaml")
    said = [w for w in stderr.splitlines() if "differ from this static's by up to" in w]
    assert len(said) == 1 and "with foot flat (used)" in said[0]
    assert model["subject"]["static_plantar_flexion"]["left"] == pytest.approx(
        np.degrees(proc["LStaticPlantFlex"]), abs=0.01)


@needs_nexus
def test_nexus_walking_angles_match_vicons(nexus_run):
    """Every Plug-in Gait angle of the walking trial beside Vicon's (``LHipAnglesV`` ...):
    RMS over the trusted frames ≤ 1° in X and ≤ 2° in Y and Z (measured: ≤ 0.24° X, ≤ 1.3°
    Y/Z, the right ankle's rotation the largest)."""
    _, _, run, _, _ = nexus_run
    theirs = points_of(WALK)
    pig = run.plugin_gait
    assert run.trusted.all() and len(pig.angles) == 10
    for name, ours in pig.angles.items():
        error = (ours - theirs[name + "V"] + 180.0) % 360.0 - 180.0
        rms = np.sqrt(np.mean(error[run.trusted] ** 2, axis=0))
        assert rms[0] <= 1.0 and rms[1] <= 2.0 and rms[2] <= 2.0, (name, rms)


@needs_nexus
def test_nexus_calibration_writes_plug_in_gaits_inertia(nexus_run):
    """The personalized model's segment inertia is Plug-in Gait's table for the 74 kg subject:
    thigh, shank and foot 10 %, 4.65 %, 1.45 % of the body mass, centres of mass 0.567 of the
    way from the distal end (knee, ankle, toe marker) to the proximal joint centre (0.5 for the
    foot), radii of gyration 0.540, 0.528, 0.690 of that length about the transverse axes and
    nothing about the long one; the pelvis 14.2 %."""
    model, _, _, _, _ = nexus_run
    bodies = model["bodies"]
    assert bodies["pelvis"]["mass"] == pytest.approx(0.142 * 74.0, rel=1e-5)
    for name, ends, (fraction, com, gyration) in (
            ("thigh_l", ("KJC", "HJC"), (0.1, 0.567, 0.540)),
            ("shank_r", ("AJC", "KJC"), (0.0465, 0.567, 0.528)),
            ("foot_l", ("LTOE", "AJC"), (0.0145, 0.5, 0.690))):
        body = bodies[name]
        distal, proximal = (np.array(body["points"][k]) for k in ends)
        length = np.linalg.norm(proximal - distal)
        assert body["mass"] == pytest.approx(fraction * 74.0, rel=1e-5), name
        np.testing.assert_allclose(body["com"], distal + com * (proximal - distal), atol=1e-5)
        moments, axes = np.linalg.eigh(np.array(body["inertia"]))
        expected = fraction * 74.0 * (gyration * length) ** 2
        np.testing.assert_allclose(moments, [0.0, expected, expected], rtol=1e-5, atol=1e-9)
        assert abs(axes[:, 0] @ (proximal - distal)) / length == pytest.approx(1.0, abs=1e-6)


def kinetics_rms(run, theirs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """RMS difference of every moment (X, Y, Z; N·mm/kg) and power (Z; W/kg) the run stores
    to Vicon's of the same name, over the frames where Vicon wrote it."""
    pig = run.plugin_gait
    out = {}
    for name, ours in {**pig.moments, **pig.powers}.items():
        ok = np.isfinite(theirs[name]).all(axis=1) & np.isfinite(ours).all(axis=1)
        out[name] = np.sqrt(np.mean((ours[ok] - theirs[name][ok]) ** 2, axis=0))
    return out


# Per joint: RMS bounds for X, Y, Z (N·mm/kg) and the power (W/kg) on the Nexus walking trial,
# over both sides (measured, worst side: hip 26 / 16 / 5 and 0.077, knee 14 / 9 / 6 and 0.070,
# ankle 12 / 3 / 7 and 0.050).
NEXUS_KINETICS = {"Hip": (30.0, 18.0, 8.0, 0.09), "Knee": (16.0, 11.0, 8.0, 0.08),
                  "Ankle": (14.0, 4.0, 8.0, 0.06)}


@needs_nexus
def test_nexus_walking_kinetics_match_vicons(nexus_run):
    """Every Plug-in Gait moment and power of the walking trial beside Vicon's, both sides,
    within ``NEXUS_KINETICS`` (with de Leva's inertia in place of Plug-in Gait's the hip's X
    was 97 and its power 0.27; with the knee moment taken about the tibia's static origin
    instead of the thigh's knee centre the knee's X was 17). The plates' loads equal Vicon's to
    0.1 N; what remains lives mostly in the frames about foot off (docs/plugin-gait.md)."""
    _, _, run, _, _ = nexus_run
    rms = kinetics_rms(run, points_of(WALK))
    assert len(rms) == 12
    for name, value in rms.items():
        joint = next(j for j in NEXUS_KINETICS if j in name)
        *moment, power = NEXUS_KINETICS[joint]
        if name.endswith("Power"):
            assert value[2] <= power, (name, value)
        else:
            assert np.all(value <= moment), (name, value)


@needs_nexus
def test_events_and_exports_on_the_trials_clock(nexus_run, tmp_path):
    """The events `solve` prints are the C3D's EVENT:TIMES as written (60 min + s: the
    capture's clock), and the .mot's time column counts on the same clock from the first
    frame, (first frame − 1) / rate, which its header names."""
    _, _, _, results, stdout = nexus_run
    rows = [line.split() for line in stdout.splitlines()
            if line.split()[:2] in (["left", "strike"], ["right", "strike"], ["left", "off"],
                                    ["right", "off"])]
    printed = np.array([float(r[2]) for r in rows])
    c3d = ezc3d.c3d(str(WALK))
    times = np.asarray(c3d["parameters"]["EVENT"]["TIMES"]["value"])
    np.testing.assert_allclose(printed, np.sort(60.0 * times[0] + times[1]), atol=6e-4)
    assert "trial file's clock, its first frame at 7.240 s" in stdout
    target = tmp_path / "walk.mot"
    out = run_cli("export", results, "--format", "mot", "-o", target)
    assert out.exit_code == 0, out.stderr
    lines = target.read_text(encoding="utf-8").splitlines()
    end = lines.index("endheader")
    assert "clock=the trial file's, first frame at 7.24 s" in lines[:end]
    first = float(lines[end + 2].split("\t")[0])
    start = ezc3d.c3d(str(WALK))["parameters"]["TRIAL"]["ACTUAL_START_FIELD"]["value"][0]
    assert first == pytest.approx((start - 1) / 100.0)
    assert first <= printed.min() and printed.max() <= first + 2.93


# --- SACR or the PSIS midpoint ----------------------------------------------------------------

def _trial(labels: tuple[str, ...], gaps: dict[str, slice]):
    from fccgrb_cli.trial.record import Trial

    markers = np.random.default_rng(0).normal(size=(10, len(labels), 3))
    for label, frames in gaps.items():
        markers[frames, labels.index(label)] = np.nan
    return Trial("t.c3d", labels, markers, 100.0)


@pytest.mark.parametrize("labels,gaps,expected", [
    (("LPSI", "RPSI"), {}, {"SACR": "mid(LPSI,RPSI)"}),             # no SACR: the midpoint
    (("SACR", "LPSI", "RPSI"), {"SACR": slice(2, 5)}, {}),          # SACR with gaps: SACR
    (("SACR", "LPSI", "RPSI"), {"SACR": slice(None)}, {"SACR": "mid(LPSI,RPSI)"}),  # empty
    (("LPSI",), {}, {}),                                            # one PSIS: nothing
    (("LPSI", "RPSI"), {"RPSI": slice(None)}, {}),                  # an empty PSIS: nothing
    (("Sub:LPSI", "Sub:RPSI"), {}, {"SACR": "mid(LPSI,RPSI)"}),     # subject prefixes
])
def test_sacrum_or_the_psis_midpoint_by_what_the_trial_holds(labels, gaps, expected):
    from fccgrb_cli.trial.stand_ins import stand_ins

    assert stand_ins(_trial(labels, gaps), {"SACR", "RASI"}) == expected
    assert stand_ins(_trial(labels, gaps), {"RASI"}) == {}  # only for markers the caller reads


def test_the_stand_in_is_the_psis_midpoint_frame_by_frame():
    """The pelvis marker a model reads is (LPSI + RPSI) / 2 in every frame, gaps where either
    PSIS has one; a map's own SACR wins over the stand-in."""
    from fccgrb_cli.model import load_model
    from fccgrb_cli.trial.virtual import resolved

    model = load_model(PIG)
    trial = _trial(("LPSI", "RPSI", "RASI"), {"RPSI": slice(3, 4)})
    out, mapping = resolved(model, trial, {}, {"SACR"})
    got = out.select([mapping["SACR"]])[:, 0]
    want = 0.5 * (trial.markers[:, 0] + trial.markers[:, 1])
    np.testing.assert_array_equal(got, want)
    assert np.isnan(got[3]).all() and len(out.warnings) == 1
    _, mapping = resolved(model, trial, {"SACR": "RASI"}, {"SACR"})
    assert mapping["SACR"] == "RASI"


# --- EVENT:TIMES in either layout -------------------------------------------------------------

@needs_nexus
def test_event_times_as_2n_values_read_as_the_2_by_n_array(tmp_path):
    """Nexus 1.4 writes EVENT:TIMES as 2N values (minutes, seconds pairs); the events read
    from that copy equal the ones from the 2 × N original, and equal 60 min + s less the
    first frame's time, as written."""
    from fccgrb_cli.gait.events import c3d_events
    from fccgrb_cli.trial.record import read_trial

    c3d = ezc3d.c3d(str(WALK))
    times = np.asarray(c3d["parameters"]["EVENT"]["TIMES"]["value"])
    assert times.shape == (2, 12)
    flat = rewritten(WALK, tmp_path / "flat.c3d", times=times.T.ravel())
    assert np.asarray(ezc3d.c3d(str(flat))["parameters"]["EVENT"]["TIMES"]["value"]).shape \
        == (24,)
    trial = read_trial(WALK)
    original = c3d_events(WALK, trial.n_frames, trial.rate)
    again = c3d_events(flat, trial.n_frames, trial.rate)
    np.testing.assert_array_equal(again.time, original.time)
    assert again.side == original.side and again.kind == original.kind
    start = (c3d["header"]["points"]["first_frame"]) / trial.rate  # first_frame from 0 here
    written = np.sort(60.0 * times[0] + times[1] - start)
    np.testing.assert_allclose(original.time, written, atol=1e-9)
    broken = rewritten(WALK, tmp_path / "broken.c3d", times=times.T.ravel()[:23])
    with pytest.raises(InputError, match=r"broken\.c3d: EVENT:TIMES: expected 2 × 12 values"):
        c3d_events(broken, trial.n_frames, trial.rate)


# --- PROCESSING read by what it means ---------------------------------------------------------

@needs_nexus
def test_workstation_processing_spellings_and_degrees(tmp_path):
    """A Workstation static: ``Marker Diameter`` spelt with a space, the left static
    plantarflexion in degrees (12.7) beside a right one in radians: calibrates, the diameter
    read (10 mm, not the default), the degrees said in one warning; the offsets are computed
    again (the same as from the untouched file)."""
    static = rewritten(STATIC, tmp_path / "ws.c3d",
                       {"Marker Diameter": 10.0, "LStaticPlantFlex": 12.7})
    model, stderr = calibrated(static, tmp_path / "ws.yaml")
    assert model["subject"]["marker_diameter"] == pytest.approx(0.010)
    assert "no marker diameter" not in stderr
    degrees = [w for w in stderr.splitlines() if "read as degrees" in w]
    assert len(degrees) == 1 and "LStaticPlantFlex 12.7" in degrees[0]
    reference, _ = calibrated(rewritten(STATIC, tmp_path / "ref.c3d",
                                        {"MarkerDiameter": 10.0}), tmp_path / "ref.yaml")
    assert model["subject"]["static_plantar_flexion"] == reference["subject"][
        "static_plantar_flexion"]
    assert model["bodies"]["thigh_l"]["points"] == reference["bodies"]["thigh_l"]["points"]


@pytest.mark.parametrize("key", ["MarkerDiameter", "Marker Diameter", "MARKER_DIAMETER",
                                 "marker-diameter", "markerdiameter"])
def test_spellings_read_alike(key):
    from fccgrb_cli.model.subject import from_vicon

    def fail(*args):
        raise AssertionError(args)

    m = from_vicon({key: 12.5, "L Knee Width": 101.0}, "here", fail)
    assert m.marker_diameter == pytest.approx(0.0125)
    assert m.knee_width.left == pytest.approx(0.101)


@pytest.mark.parametrize("key,value,expected", [
    ("RTibialTorsion", 20.0, np.radians(20.0)),   # degrees: only they make it plausible
    ("RTibialTorsion", -0.3, -0.3),               # radians, as written
    ("RStaticRotOff", -12.0, np.radians(-12.0)),  # a derived value in degrees
    ("RStaticRotOff", 400.0, None),               # a derived value no unit explains: left out
])
def test_angles_read_by_their_size(key, value, expected):
    from fccgrb_cli.model.subject import from_vicon

    def fail(*args):
        raise InputError(str(args))

    m = from_vicon({key: value}, "here", fail)
    field = "tibial_torsion" if "Torsion" in key else "static_rotation_offset"
    got = getattr(m, field).right
    if expected is None:
        assert got is None and "left out" in m.notes[0]
    else:
        assert got == pytest.approx(expected)
        assert len(m.notes) == (0 if abs(value) < np.pi / 2 else 1)


def test_a_torsion_no_unit_explains_is_refused():
    from fccgrb_cli.model.subject import from_vicon

    def fail(key, expected, got):
        raise InputError(f"{key}: expected {expected}, got {got:g}")

    with pytest.raises(InputError, match="RTibialTorsion: expected"):
        from_vicon({"RTibialTorsion": 120.0}, "here", fail)


# --- .mp subject files ------------------------------------------------------------------------

MP = """{* Vicon Workstation subject parameters *}
$Bodymass = 61.5
$Height = 1702
$LeftLegLength = 881
$RightLegLength = 879
$LKneeWidth = 98
$RKneeWidth = 99.5
$LeftAnkleWidth = 66
$RightAnkleWidth = 67
$MarkerDiameter = 16
$RightTibialTorsion = 0.21

$InterAsisDistance = 0
"""


def test_mp_file_read_in_si(tmp_path):
    from fccgrb_cli.trial.subject_files import read_measurements

    path = tmp_path / "subject.mp"
    path.write_text(MP, encoding="utf-8")
    m = read_measurements(path)
    assert m.body_mass == pytest.approx(61.5) and m.height == pytest.approx(1.702)
    assert (m.leg_length.left, m.leg_length.right) == pytest.approx((0.881, 0.879))
    assert (m.knee_width.left, m.knee_width.right) == pytest.approx((0.098, 0.0995))
    assert (m.ankle_width.left, m.ankle_width.right) == pytest.approx((0.066, 0.067))
    assert m.marker_diameter == pytest.approx(0.016)
    assert m.tibial_torsion.right == pytest.approx(0.21) and m.tibial_torsion.left is None
    assert m.inter_asis_distance is None  # Vicon's 0: not measured


@pytest.mark.parametrize("text,fragment", [
    ("$LKneeWidth = wide\n", "line 1: $LKneeWidth: expected a number, got 'wide'"),
    ("\n$Bodymass = -4\n", "$Bodymass: expected 0.5–400 kg, got -4"),
])
def test_mp_file_bad_values_name_file_and_key(tmp_path, text, fragment):
    from fccgrb_cli.trial.mp import mp_measurements

    path = tmp_path / "bad.mp"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(InputError, match=r"bad\.mp") as caught:
        mp_measurements(path)
    assert fragment in str(caught.value)


@needs_nexus
def test_mp_file_over_processing_in_calibrate(tmp_path):
    mp = tmp_path / "subject.mp"
    mp.write_text(MP, encoding="utf-8")
    model, stderr = calibrated(STATIC, tmp_path / "p.yaml", "--subject", mp)
    subject = model["subject"]
    assert subject["knee_width"] == pytest.approx({"left": 0.098, "right": 0.0995})
    assert subject["marker_diameter"] == pytest.approx(0.016) and subject["mass"] == 61.5
    assert "subject.mp" in subject["source"] and "no marker diameter" not in stderr
    one_error_line(run_cli("calibrate", PIG, STATIC, "--subject", tmp_path / "none.mp", "-o",
                           tmp_path / "q.yaml"), "none.mp: subject file not found")


# --- every template reads the same measurements the same way ---------------------------------

@needs_child
def test_full_body_template_takes_widths_and_mass_from_processing(tmp_path):
    """The full-body Plug-in Gait template on a Nexus full-body static: the knee and ankle
    widths of its PROCESSING group (rewritten to 105 and 55 mm both sides, marker 14 mm) put
    the knee and ankle markers (105 + 14) / 2 and (55 + 14) / 2 mm from the centres, and its
    Bodymass gives the segments' masses (summing to it), with nothing typed."""
    static = rewritten(CHILD, tmp_path / "fb.c3d", {
        "LKneeWidth": 105.0, "RKneeWidth": 105.0, "LAnkleWidth": 55.0, "RAnkleWidth": 55.0,
        "MarkerDiameter": 14.0, "Bodymass": 63.0})
    target = tmp_path / "fb.yaml"
    out = run_cli("calibrate", TEMPLATES / "full_body_plugin_gait.yaml", static, "-o", target)
    assert out.exit_code == 0, out.stderr
    assert "no --mass" not in out.stderr and "average adult" not in out.stderr
    bodies = yaml.safe_load(target.read_text(encoding="utf-8"))["bodies"]
    for s, side in (("r", "R"), ("l", "L")):
        thigh, shank = bodies[f"thigh_{s}"]["points"], bodies[f"shank_{s}"]["points"]
        knee = np.subtract(thigh[f"{side}KNE"], thigh["KJC"])
        ankle = np.subtract(shank[f"{side}ANK"], shank["AJC"])
        assert np.linalg.norm(knee) == pytest.approx(0.5 * (0.105 + 0.014), abs=2e-6)
        assert np.linalg.norm(ankle) == pytest.approx(0.5 * (0.055 + 0.014), abs=2e-6)
    assert sum(b.get("mass", 0.0) for b in bodies.values()) == pytest.approx(63.0, rel=1e-4)


@needs_child
def test_unequal_sides_averaged_and_said(tmp_path):
    """A one-width template given L/R widths 102/104 mm (the child's own): their mean, said
    in one warning line per width."""
    target = tmp_path / "fb.yaml"
    out = run_cli("calibrate", TEMPLATES / "full_body_plugin_gait.yaml", CHILD, "-o", target)
    assert out.exit_code == 0, out.stderr
    lines = out.stderr.splitlines()
    assert sum("LKneeWidth 102 mm and RKneeWidth 104 mm" in w and "mean 103 mm" in w
               for w in lines) == 1
    thigh = yaml.safe_load(target.read_text(encoding="utf-8"))["bodies"]["thigh_r"]["points"]
    proc = processing_of(CHILD)
    assert np.linalg.norm(np.subtract(thigh["RKNE"], thigh["KJC"])) == pytest.approx(
        0.5e-3 * (103.0 + proc["MarkerDiameter"]), abs=2e-6)

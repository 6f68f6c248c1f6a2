"""OpenSim's tool setups: opensim-core's IK and ID setups and task sets (../shared/data/opensim,
never copied) read to what their text says, relative paths resolved against the setup's folder
as OpenSim does; hostile setups refused in one line naming the file and the element."""

from __future__ import annotations

from pathlib import Path

import pytest

from fccgrb_cli.core.errors import InputError
from fccgrb_cli.opensim.setups import (
    CoordinateTask,
    MarkerTask,
    read_id_setup,
    read_ik_setup,
    read_task_set,
)

OPENSIM = Path(__file__).resolve().parents[2] / "shared" / "data" / "opensim"
IK = OPENSIM / "ik_gait2354_synthetic"
ID = OPENSIM / "id_gait2392"
needs_data = pytest.mark.skipif(not OPENSIM.is_dir(), reason="../shared/data/opensim absent")


@needs_data
def test_ik_setup_as_written():
    setup = read_ik_setup(IK / "subject01_Setup_InverseKinematics.xml")
    assert setup.name == "subject01"
    assert setup.model_file == IK / "subject01_simbody.osim"
    assert setup.marker_file == IK / "subject01_synthetic_marker_data.trc"
    assert setup.coordinate_file is None  # <coordinate_file> </coordinate_file>
    assert setup.time_range == (0.4, 1.6)
    assert setup.accuracy == 1e-5 and setup.constraint_weight == 10.0
    assert setup.output_motion_file == IK / "subject01_walk1_ik_test.mot"
    assert setup.tasks.source == str(IK / "gait2354_IK_Tasks_uniform.xml")
    assert len(setup.tasks.markers) == 31 and setup.tasks.coordinates == ()
    assert set(setup.tasks.marker_weights().values()) == {1.0}


@needs_data
def test_weighted_task_set_as_written():
    tasks = read_task_set(IK / "gait2354_IK_Tasks.xml")
    assert len(tasks.markers) == 31 and all(t.apply for t in tasks.markers)
    weights = tasks.marker_weights()
    assert weights["Sternum"] == 1.0 and weights["R.Acromium"] == 0.75
    assert weights["Top.Head"] == 0.5 and weights["R.ASIS"] == 2.0
    assert weights["V.Sacral"] == 10.0
    assert tasks.coordinates[0] == CoordinateTask("subtalar_angle_r", True, 1000.0,
                                                  "default_value", None)
    assert [t.name for t in tasks.coordinates] == ["subtalar_angle_r", "mtp_angle_r",
                                                   "subtalar_angle_l", "mtp_angle_l"]


@needs_data
def test_id_setups_as_written():
    setup = read_id_setup(ID / "subject01_Setup_InverseDynamics.xml")
    assert setup.model_file == ID / "subject01.osim"
    assert setup.coordinates_file == ID / "subject01_walk1_ik.mot"
    assert setup.external_loads_file == ID / "subject01_walk1_grf.xml"
    assert setup.time_range == (0.5, 1.6) and setup.lowpass_cutoff == 6.0
    assert setup.coordinates_in_degrees is True and setup.forces_to_exclude == ("muscles",)
    # outputs go to results_directory (Results), itself beside the setup
    assert setup.output_gen_force_file == ID / "Results" / "subject01_InverseDynamics"
    arm = read_id_setup(ID / "arm26_Setup_InverseDynamics.xml")
    assert arm.external_loads_file is None and arm.time_range == (0.0, 1.0)
    assert arm.coordinates_file == ID / "arm26_InverseKinematics.mot"
    assert arm.output_gen_force_file == ID / "Results" / "arm26_InverseDynamics.sto"


IK_SETUP = """<?xml version="1.0" encoding="UTF-8"?>
<OpenSimDocument Version="40000">
  <InverseKinematicsTool name="walk">
    <model_file>models/subject.osim</model_file>
    <marker_file>{marker}</marker_file>
    <time_range>{time}</time_range>
    <accuracy>{accuracy}</accuracy>
    <constraint_weight>Inf</constraint_weight>
    <results_directory>out</results_directory>
    <output_motion_file>ik.mot</output_motion_file>
    <IKTaskSet name="inline">
      <objects>
        <IKMarkerTask name="RASI"><apply>true</apply><weight>{weight}</weight></IKMarkerTask>
        <IKMarkerTask name="LASI"><apply>{apply}</apply><weight>2</weight></IKMarkerTask>
        <IKCoordinateTask name="knee_angle_r"><apply>true</apply><weight>5</weight>
          <value_type>{kind}</value_type><value>15</value></IKCoordinateTask>{more}
      </objects>
    </IKTaskSet>{extra}
  </InverseKinematicsTool>
</OpenSimDocument>
"""
DEFAULTS = {"marker": "/data/walk.trc", "time": "0.5 1.5", "accuracy": "1e-6", "weight": "3",
            "apply": "false", "kind": "manual_value", "more": "", "extra": ""}


def _setup(tmp_path: Path, **changes: str) -> Path:
    path = tmp_path / "setup.xml"
    path.write_text(IK_SETUP.format(**(DEFAULTS | changes)))
    return path


def test_inline_tasks_and_paths(tmp_path):
    setup = read_ik_setup(_setup(tmp_path))
    assert setup.model_file == tmp_path / "models" / "subject.osim"
    assert setup.marker_file == Path("/data/walk.trc")  # absolute: kept
    # the IK tool writes its motion beside the setup, not in results_directory (the ID tool's
    # forces go there): as OpenSim 4.6 does
    assert setup.output_motion_file == tmp_path / "ik.mot"
    assert setup.constraint_weight is None  # Infinity: constraints kept exactly
    assert setup.tasks.markers == (MarkerTask("RASI", True, 3.0), MarkerTask("LASI", False, 2.0))
    assert setup.tasks.marker_weights() == {"RASI": 3.0}
    assert setup.tasks.coordinates == (CoordinateTask("knee_angle_r", True, 5.0, "manual_value",
                                                      15.0),)
    assert read_task_set(setup.source) == setup.tasks


HOSTILE = {
    "unknown property": ({"extra": "<solver>fast</solver>"},
                         "OpenSimDocument/InverseKinematicsTool[name=walk]/solver: expected a "
                         "property of InverseKinematicsTool"),
    "time range of one": ({"time": "0.5"}, "time_range: expected 2 numbers, got 1"),
    "time backwards": ({"time": "1.5 0.5"}, "time_range: expected a start time before the end "
                                            "time, got 1.5 0.5"),
    "nan time": ({"time": "nan 1"}, "time_range: expected a finite number"),
    "huge accuracy": ({"accuracy": "1e400"}, "accuracy: expected a finite number"),
    "zero accuracy": ({"accuracy": "0"}, "accuracy: expected a positive accuracy"),
    "accuracy above 1": ({"accuracy": "2"}, "accuracy: expected a positive accuracy of at most 1"),
    "negative weight": ({"weight": "-1"}, "IKMarkerTask[name=RASI]/weight: expected a weight of "
                                          "at least 0, got -1"),
    "weight word": ({"weight": "heavy"}, "IKMarkerTask[name=RASI]/weight: expected a number"),
    "apply word": ({"apply": "yes"}, "IKMarkerTask[name=LASI]/apply: expected true or false"),
    "value type": ({"kind": "guess"}, "IKCoordinateTask[name=knee_angle_r]/value_type: expected "
                                      "one of default_value, manual_value, from_file"),
    "unknown task": ({"more": "<IKOrientationTask name='pelvis'/>"},
                     "objects/IKOrientationTask[name=pelvis]: expected an IKMarkerTask or "
                     "IKCoordinateTask"),
    "task twice": ({"more": "<IKMarkerTask name='RASI'/>"},
                   "expected each IKMarkerTask named once, got 'RASI' again"),
    "nameless task": ({"more": "<IKMarkerTask/>"}, "expected a name='…' attribute"),
    "entity": ({"more": "&lol;"}, "not well-formed XML"),
}


@pytest.mark.parametrize("case", sorted(HOSTILE))
def test_hostile_setups_refused_in_one_line(tmp_path, case):
    changes, message = HOSTILE[case]
    path = _setup(tmp_path, **changes)
    with pytest.raises(InputError) as error:
        read_ik_setup(path)
    text = str(error.value)
    assert text.startswith(f"{path}: ") and "\n" not in text and message in text, text


def test_an_id_setup_is_not_an_ik_setup(tmp_path):
    path = tmp_path / "id.xml"
    path.write_text("<OpenSimDocument><InverseDynamicsTool><coordinates_file>a.mot"
                    "</coordinates_file></InverseDynamicsTool></OpenSimDocument>")
    with pytest.raises(InputError, match=r"InverseDynamicsTool/coordinates_file: expected a "
                                         r"property of InverseKinematicsTool"):
        read_ik_setup(path)
    with pytest.raises(InputError, match=r"Model: expected an OpenSim setup"):
        (tmp_path / "m.osim").write_text("<Model/>")
        read_id_setup(tmp_path / "m.osim")


def test_doctype_refused(tmp_path):
    path = tmp_path / "laughs.xml"
    path.write_text('<?xml version="1.0"?><!DOCTYPE lolz [<!ENTITY lol "lol">]>'
                    "<OpenSimDocument><InverseKinematicsTool/></OpenSimDocument>")
    with pytest.raises(InputError, match="refused: a DOCTYPE declaration"):
        read_ik_setup(path)


TASKS = """<IKTaskSet name="t"><objects>
  <IKMarkerTask name="P1"><apply>true</apply><weight>2</weight></IKMarkerTask>
  <IKMarkerTask name="P2"><apply>false</apply><weight>1</weight></IKMarkerTask>
  <IKMarkerTask name="P3"><apply>true</apply><weight>0.5</weight></IKMarkerTask>
  <IKMarkerTask name="Head"><apply>true</apply><weight>1</weight></IKMarkerTask>
</objects></IKTaskSet>"""
PENDULUM = Path(__file__).resolve().parents[1] / "configs" / "models" / "pendulum.yaml"
PENDULUM_TRIAL = Path(__file__).resolve().parents[1] / "sample_data" / "pendulum.c3d"


def test_task_weights_reach_the_tracked_points(tmp_path):
    from fccgrb_cli.model import load_model
    from fccgrb_cli.pipeline.options import SolveOptions, prepared

    path = tmp_path / "tasks.xml"
    path.write_text(TASKS)
    options = SolveOptions.from_mapping({"tasks": str(path), "tracking_weight": 0.01})
    assert options.tasks == (("P1", 2.0), ("P3", 0.5), ("Head", 1.0))
    assert SolveOptions.from_json(options.to_json()) == options  # kept in the results as pairs
    model = prepared(load_model(PENDULUM), options)
    assert [(tp.marker, tp.weight) for tp in model.tracked_points] == [("P1", 0.02),
                                                                       ("P3", 0.005)]
    with pytest.raises(InputError, match="--tasks: expected marker tasks naming markers of"):
        prepared(load_model(PENDULUM), SolveOptions(tasks=(("Head", 1.0),)))
    with pytest.raises(InputError, match=r"tasks: expected an IK task set file or \[marker, "
                                         r"weight\] pairs with weights above 0"):
        SolveOptions.from_mapping({"tasks": [["P1", -1]]})


def test_cli_solves_with_a_task_set(tmp_path):
    from cli_helpers import one_error_line, run_cli

    import fccgrb_cli as fc

    path = tmp_path / "tasks.xml"
    path.write_text(TASKS)
    out = tmp_path / "out.h5"
    result = run_cli("solve", PENDULUM, PENDULUM_TRIAL, "--tasks", path, "--no-dynamics",
                     "-o", out)
    assert result.exit_code == 0, result.stderr
    (run,) = fc.read_results(out).values()
    assert run.labels == ("P1", "P3")
    broken = tmp_path / "broken.xml"
    broken.write_text(TASKS.replace("<weight>2</weight>", "<weight>-2</weight>"))
    one_error_line(run_cli("solve", PENDULUM, PENDULUM_TRIAL, "--tasks", broken, "-o",
                           tmp_path / "no.h5"),
                   "broken.xml: IKTaskSet[name=t]/objects/IKMarkerTask[name=P1]/weight: "
                   "expected a weight of at least 0, got -2")
    assert not (tmp_path / "no.h5").exists()


@pytest.mark.parametrize("cutoff, expected", [("-1", None), ("-1.0", None), ("", None),
                                              ("6", 6.0), ("12.5", 12.5)])
def test_id_cutoff_negative_is_no_filter(tmp_path, cutoff, expected):
    path = tmp_path / "id.xml"
    path.write_text("<OpenSimDocument><InverseDynamicsTool name='x'>"
                    f"<lowpass_cutoff_frequency_for_coordinates>{cutoff}"
                    "</lowpass_cutoff_frequency_for_coordinates><coordinates_in_degrees>false"
                    "</coordinates_in_degrees></InverseDynamicsTool></OpenSimDocument>")
    setup = read_id_setup(path)
    assert setup.lowpass_cutoff == expected and setup.coordinates_in_degrees is False
    assert setup.time_range is None and setup.external_loads_file is None


def test_coordinate_tasks_of_dominant_weight_become_holds(tmp_path):
    """A coordinate task weighing at least 10 × the heaviest marker holds its coordinate (at
    the model's default or its manual value, in the file's unit); a lighter one, or one from a
    coordinates file, is left out with a note naming it."""
    from fccgrb_cli.opensim.setups import read_task_set

    def task(name: str, weight: float, kind: str = "default_value", value: str = "") -> str:
        return (f'<IKCoordinateTask name="{name}"><apply>true</apply><weight>{weight}</weight>'
                f"<value_type>{kind}</value_type>{value}</IKCoordinateTask>")

    marker = '<IKMarkerTask name="M"><apply>true</apply><weight>20</weight></IKMarkerTask>'
    tasks = [task("a", 1000), task("b", 100), task("c", 300, "manual_value", "<value>5</value>"),
             task("d", 5000, "from_file")]
    path = tmp_path / "tasks.xml"
    path.write_text(f'<OpenSimDocument Version="40000"><IKTaskSet name="t"><objects>{marker}'
                    f'{"".join(tasks)}</objects></IKTaskSet></OpenSimDocument>')
    holds, notes = read_task_set(path).holds()
    assert holds == ("a=default", "c=5")
    assert len(notes) == 1 and "b (weight 100" in notes[0] and "d (its value from" in notes[0]


IK = Path(__file__).resolve().parents[2] / "shared" / "data" / "opensim" / \
    "ik_gait2354_synthetic"


@pytest.mark.skipif(not IK.is_dir(), reason="../shared/data/opensim not here")
def test_a_held_coordinate_keeps_its_value_in_every_frame():
    """--hold NAME=VALUE (degrees) fixes the coordinate through the solve (a constraint row, met
    as the method meets the topology: within 1e-4 rad by nrm-wls), NAME=default at the
    model's default; the others still fit the markers."""
    import numpy as np

    import fccgrb_cli as fc

    model = fc.load_model(IK / "subject01_simbody.osim")
    trial = fc.read_trial(IK / "subject01_synthetic_marker_data.trc")
    run = fc.solve(model, trial, dynamics=False, hold=("subtalar_angle_r=5", "mtp_angle_l=default"))
    names = list(run.result.angle_names)
    assert np.allclose(run.result.theta[:, names.index("subtalar_angle_r")], np.radians(5.0),
                       atol=1e-4)
    default = next(c.default for c in model.angles if c.name == "mtp_angle_l")
    assert np.allclose(run.result.theta[:, names.index("mtp_angle_l")], default, atol=1e-4)
    free = np.degrees(run.result.theta[:, names.index("subtalar_angle_l")])
    assert np.ptp(free) > 0.5  # not held: it moves
    assert run.result.converged.all()
    with pytest.raises(InputError, match="--hold nope=1: expected a coordinate of"):
        fc.solve(model, trial, dynamics=False, hold=("nope=1",))

"""OpenSim external loads: opensim-core's id_gait2392 ExternalLoads file and its .mot read into
the bodies it names, the forces equal to the file's columns; the free torque a couple (its
moment the same about every point); hostile load files refused in one line naming the element;
and a load set driving fccgrb's inverse dynamics (``--loads``), checked by the power it puts into
the joints against the power of the force and torque computed from the motion alone."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from cli_helpers import one_error_line, run_cli

import fccgrb_cli as fc
from fccgrb_cli.core.errors import InputError
from fccgrb_cli.dynamics.loads import ExternalLoad
from fccgrb_cli.model.elements import PlateAssignment
from fccgrb_cli.opensim.loads import external_loads, read_external_loads
from fccgrb_cli.opensim.storage import read_storage, write_storage
from fccgrb_cli.pipeline.options import SolveOptions, prepared
from fccgrb_cli.pipeline.solve import points_along
from fccgrb_cli.system import compile_system

ROOT = Path(__file__).resolve().parents[1]
OPENSIM = ROOT.parent / "shared" / "data" / "opensim"
GRF = OPENSIM / "id_gait2392" / "subject01_walk1_grf.xml"
needs_data = pytest.mark.skipif(not GRF.is_file(), reason="../shared/data/opensim absent")


@needs_data
def test_gait2392_forces_go_to_the_bodies_named():
    loads = read_external_loads(GRF)
    assert [(f.name, f.body) for f in loads.forces] == [("RightForce", "calcn_r"),
                                                        ("LeftForce", "calcn_l")]
    assert loads.datafile == GRF.parent / "subject01_walk1_grf.mot"
    assert loads.kinematics_file is None and loads.bodies == ("calcn_r", "calcn_l")


@needs_data
def test_gait2392_columns_and_vertical_sum_equal_the_file():
    loads = read_external_loads(GRF)
    table = read_storage(GRF.parent / "subject01_walk1_grf.mot")
    right, left = loads.body_loads()
    for load, prefix in ((right, ""), (left, "l_")):
        for k, axis in enumerate("xyz"):
            for got, column in ((load.force, f"{prefix}ground_force_v{axis}"),
                                (load.point, f"{prefix}ground_force_p{axis}"),
                                (load.torque, f"{prefix}ground_torque_{axis}")):
                np.testing.assert_array_equal(got[:, k], table.column(column))
    vertical = right.force[:, 1] + left.force[:, 1]
    np.testing.assert_allclose(vertical, table.column("ground_force_vy")
                               + table.column("l_ground_force_vy"), rtol=0, atol=0)
    # a subject of ~72 kg walking: the two feet together carry about the body weight on average
    assert 600.0 < vertical.mean() < 800.0
    assert vertical.max() > 1.1 * vertical.mean()  # the loading peaks of walking


@needs_data
def test_resampled_at_a_trials_frames():
    loads = read_external_loads(GRF)
    table = read_storage(GRF.parent / "subject01_walk1_grf.mot")
    time = 0.5 + np.arange(67) / 60.0  # the synthetic trial's 60 Hz over 0.5–1.6 s
    right, left = external_loads(loads, time, ["pelvis", "calcn_r", "calcn_l"])
    assert right.body == "calcn_r" and right.force.shape == (67, 3)
    row = int(np.argmin(np.abs(table.time - time[30])))
    assert abs(table.time[row] - time[30]) < 1e-3  # a row of the file at that frame
    step = np.abs(np.diff(table.column("l_ground_force_vy"))).max()
    assert abs(left.force[30, 1] - table.column("l_ground_force_vy")[row]) <= step
    with pytest.raises(InputError, match=r"applied_to_body: expected a body of the model"):
        external_loads(loads, time, ["pelvis", "calcn_r"])
    with pytest.raises(InputError, match=r"ExternalForce RightForce: expected data over the "
                                         r"trial's 14\.5–16 s, got 0–15\.0133 s"):
        external_loads(loads, 14.5 + np.arange(3) * 0.75, ["calcn_r", "calcn_l"])


def _moment_about_reference(load: ExternalLoad, pose: np.ndarray) -> np.ndarray:
    """The moment about the body's reference point r of the generalized forces Q on x = [r, u,
    v, w] (virtual work: δW = Q_r·δr + δθ·Σ e × Q_e, so M = Σ e × Q_e)."""
    q = load.generalized(pose, 0).reshape(4, 3)
    frame = pose.reshape(4, 3)
    return sum(np.cross(frame[k], q[k]) for k in (1, 2, 3))


def test_free_torque_is_a_couple_and_the_force_acts_at_its_point():
    rng = np.random.default_rng(5)
    rotation = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    rotation *= np.sign(np.linalg.det(rotation))
    r = np.array([0.3, 1.0, -0.2])
    pose = np.concatenate([r, *rotation.T])
    f, torque = np.array([[10.0, 700.0, -40.0]]), np.array([[0.5, 3.0, -0.2]])
    for p in (np.array([[0.35, 0.0, -0.1]]), np.array([[2.0, -1.0, 3.0]])):
        load = ExternalLoad("plate", "calcn_r", f, p, torque)
        moment = _moment_about_reference(load, pose)
        np.testing.assert_allclose(moment, np.cross(p[0] - r, f[0]) + torque[0], atol=1e-12)
        couple = ExternalLoad("plate", "calcn_r", 0 * f, p, torque)
        np.testing.assert_allclose(_moment_about_reference(couple, pose), torque[0], atol=1e-12)


XML = """<?xml version="1.0" encoding="UTF-8" ?>
<OpenSimDocument Version="40000">
  <ExternalLoads name="loads">
    <objects>
      <ExternalForce name="Tip">
        <applied_to_body>{body}</applied_to_body>
        <force_expressed_in_body>{frame}</force_expressed_in_body>
        <point_expressed_in_body>ground</point_expressed_in_body>
        <force_identifier>tip_force_v</force_identifier>
        <point_identifier>{point_id}</point_identifier>
        <torque_identifier>tip_torque_</torque_identifier>
      </ExternalForce>{more}
    </objects>
    <datafile>{datafile}</datafile>
  </ExternalLoads>
</OpenSimDocument>
"""
COLUMNS = [f"tip_force_v{a}" for a in "xyz"] + [f"tip_force_p{a}" for a in "xyz"] + \
    [f"tip_torque_{a}" for a in "xyz"]


def _load_files(folder: Path, time, force, point, torque, **xml) -> Path:
    write_storage(folder / "tip.mot", COLUMNS, time, np.column_stack([force, point, torque]),
                  False, title="tip")
    fields = {"body": "link2", "frame": "ground", "point_id": "tip_force_p", "more": "",
              "datafile": "tip.mot"} | xml
    path = folder / "tip.xml"
    path.write_text(XML.format(**fields))
    return path


HOSTILE = {
    "body frame": ({"frame": "calcn_r"}, "ExternalForce[name=Tip]/force_expressed_in_body: "
                                         "expected ground"),
    "no point": ({"point_id": ""}, "ExternalForce[name=Tip]/point_identifier: expected the "
                                "point's column prefix"),
    "columns": ({"point_id": "tip_force_"}, "ExternalForce[name=Tip]/point_identifier: expected 3 "
                                         "columns of"),
    "no body": ({"body": ""}, "applied_to_body: expected the name of the body"),
    "unknown element": ({"more": "<PrescribedForce name='x'/>"},
                        "objects/PrescribedForce[name=x]: expected an ExternalForce"),
    "unknown field": ({"more": "<ExternalForce name='B'><mass>1</mass></ExternalForce>"},
                      "ExternalForce[name=B]/mass: expected one of"),
    "twice": ({"more": "<ExternalForce name='Tip'><applied_to_body>a</applied_to_body>"
                       "<force_identifier>tip_force_v</force_identifier><point_identifier>"
                       "tip_force_p</point_identifier></ExternalForce>"},
              "expected each ExternalForce named once, got 'Tip' more than once"),
    "no datafile": ({"datafile": ""}, "ExternalLoads[name=loads]/datafile: expected the "
                                      "storage file"),
    "missing datafile": ({"datafile": "none.mot"}, "none.mot: storage file not found"),
    "name with a slash": ({"more": "<ExternalForce name='a/b'/>"},
                          "ExternalForce[name=a/b]: the name='…' attribute: expected a name "
                          "without '/'"),
    "no name": ({"more": "<ExternalForce><applied_to_body>B</applied_to_body></ExternalForce>"},
                "objects/ExternalForce: the name='…' attribute: expected a non-empty name"),
    "flag": ({"more": "<ExternalForce name='B'><appliesForce>sometimes</appliesForce>"
                      "</ExternalForce>"}, "appliesForce: expected true or false"),
}


@pytest.mark.parametrize("case", sorted(HOSTILE))
def test_hostile_load_files_refused_in_one_line(tmp_path, case):
    xml, message = HOSTILE[case]
    time = np.arange(5) / 100.0
    path = _load_files(tmp_path, time, np.ones((5, 3)), np.zeros((5, 3)), np.zeros((5, 3)),
                       **xml)
    with pytest.raises(InputError) as error:
        read_external_loads(path)
    assert "\n" not in str(error.value) and message in str(error.value)
    assert str(error.value).startswith(str(tmp_path))


def test_disabled_forces_are_left_out(tmp_path):
    time = np.arange(5) / 100.0
    more = ("<ExternalForce name='Off'><appliesForce>false</appliesForce><applied_to_body>x"
            "</applied_to_body></ExternalForce><ExternalForce name='Old'><isDisabled>true"
            "</isDisabled></ExternalForce>")
    path = _load_files(tmp_path, time, np.ones((5, 3)), np.zeros((5, 3)), np.zeros((5, 3)),
                       more=more)
    assert [f.name for f in read_external_loads(path).forces] == ["Tip"]


PENDULUM = ROOT / "configs" / "models" / "pendulum.yaml"
PENDULUM_TRIAL = ROOT / "sample_data" / "pendulum.c3d"


def test_load_set_drives_the_inverse_dynamics(tmp_path):
    """A force f at link2's tip and a torque n on link2 change the joint moments by Δτ with
    Σ Δτ_k θ̇_k = −(f · v_tip + n · ω₂): the joints deliver less power by what the load
    delivers. v_tip and ω₂ come from the tip's and link2's points differenced over time, not
    from the dynamics."""
    model = fc.load_model(PENDULUM)
    trial = fc.read_trial(PENDULUM_TRIAL)
    bare = fc.solve(model, trial, dynamics=True)
    kin = bare.dynamics.kinematics
    system = compile_system(model)
    points = points_along(system, kin.q, [("link2", "P3"), ("link2", "C"), ("link2", "P2")])
    tip = points[:, 0]
    time = trial.start + trial.time
    f = np.array([3.0, -2.0, 5.0])
    n = np.array([0.4, -0.1, 0.2])
    path = _load_files(tmp_path, time, np.tile(f, (len(time), 1)), tip,
                       np.tile(n, (len(time), 1)))
    loaded = fc.solve(model, trial, dynamics=True, loads=str(path))
    assert any("external loads from" in note and "Tip → link2" in note for note in loaded.notes)
    (load,) = loaded.dynamics.loads
    np.testing.assert_allclose(load.force, np.tile(f, (len(time), 1)))
    np.testing.assert_allclose(load.point, tip, atol=1e-12)
    delta = loaded.dynamics.inverse.joint_moments - bare.dynamics.inverse.joint_moments
    power = np.einsum("fk,fk->f", delta, kin.theta_d)
    rate = trial.rate
    velocity = np.gradient(points, 1.0 / rate, axis=0)
    arms = points[:, [0, 2]] - points[:, [1]]                 # tip and P2 from the elbow C
    spins = velocity[:, [0, 2]] - velocity[:, [1]]
    omega = np.array([np.linalg.lstsq(np.vstack([_cross_matrix(-a) for a in arm]),
                                      spin.ravel(), rcond=None)[0]
                      for arm, spin in zip(arms, spins, strict=True)])
    load_power = velocity[:, 0] @ f + omega @ n
    inner = slice(2, -2)  # central differences at the ends are one-sided
    scale = np.abs(load_power[inner]).max()
    np.testing.assert_allclose(power[inner], -load_power[inner], atol=2e-3 * scale)


def _cross_matrix(a: np.ndarray) -> np.ndarray:
    """ã with ã b = a × b."""
    return np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])


def test_plate_assignment_replaces_the_models():
    model = fc.load_model(PENDULUM)
    options = SolveOptions.from_mapping({"plates": "2=link2, 1=link1"})
    assert prepared(model, options).force_plates == (PlateAssignment(2, "link2"),
                                                    PlateAssignment(1, "link1"))
    for pairs, message in (("1=foot", "--plate: expected a body of the model (link1, link2), "
                                      "got 'foot'"),
                           ("1=link1,1=link2", "expected each plate assigned once, got plate 1"),
                           ("0=link1", "expected a plate number 1, 2, … before '=', got '0'"),
                           ("link1", "expected PLATE=BODY (e.g. 1=calcn_r), got 'link1'")):
        with pytest.raises(InputError, match=re.escape(message)):
            prepared(model, SolveOptions.from_mapping({"plates": pairs}))


@pytest.mark.parametrize("args, fragments", [
    (("--plate", "1=link1", "--plate", "3=hand"), ("--plate: expected a body of the model",
                                                   "got 'hand'")),
    (("--loads", "{bad}"), ("tip.xml: OpenSimDocument/ExternalLoads[name=loads]/objects/"
                            "ExternalForce[name=Tip]/force_expressed_in_body: expected ground",)),
    (("--loads", "{missing}"), ("nothing.xml: XML file not found",)),
    (("--loads", "{bad}", "--plate", "1=link1"), ("--plate: expected the trial's plates "
                                                  "assigned or an OpenSim load set",)),
])
def test_cli_refuses_bad_loads_and_plates_writing_nothing(tmp_path, args, fragments):
    time = np.arange(5) / 100.0
    bad = _load_files(tmp_path, time, np.ones((5, 3)), np.zeros((5, 3)), np.zeros((5, 3)),
                      frame="link1")
    out = tmp_path / "out.h5"
    args = [a.format(bad=bad, missing=tmp_path / "nothing.xml") for a in args]
    result = run_cli("solve", PENDULUM, PENDULUM_TRIAL, *args, "-o", out)
    one_error_line(result, *fragments)
    assert not out.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["tip.mot", "tip.xml"]


def test_loads_are_taken_at_the_trials_clock(tmp_path):
    """A TRC starting at 0.4 s reads the load file's rows at 0.4 s onwards: a force whose x is
    the time itself comes out equal to each frame's time on the file's clock."""
    from fccgrb_cli.opensim.loads import trial_loads
    from fccgrb_cli.trial.record import Trial

    model = fc.load_model(PENDULUM)
    trial = Trial("walk.trc", ("P1",), np.zeros((30, 1, 3)), 60.0, start=0.4)
    time = np.arange(0, 241) / 120.0  # 0–2 s at 120 Hz
    force = np.column_stack([time, np.ones_like(time), np.zeros_like(time)])
    path = _load_files(tmp_path, time, force, np.zeros((241, 3)), np.zeros((241, 3)))
    (load,), notes = trial_loads(path, model, trial)
    np.testing.assert_allclose(load.force[:, 0], 0.4 + np.arange(30) / 60.0, rtol=0, atol=1e-12)
    assert notes[0].startswith(f"external loads from {path} (tip.mot): Tip → link2")


def test_a_3x_files_defaults_block_is_ignored_as_opensim_ignores_it(tmp_path):
    """OpenSim 2.x/3.x documents carry a ``<defaults>`` block of default objects (controls,
    actuators) after the set's data: OpenSim ignores it, and so does the reader."""
    time = np.arange(5) / 100.0
    path = _load_files(tmp_path, time, np.ones((5, 3)), np.zeros((5, 3)), np.zeros((5, 3)))
    text = path.read_text().replace("</ExternalLoads>", "<defaults><ControlLinear name="
                                    "'default'><kp>100</kp></ControlLinear></defaults>"
                                    "</ExternalLoads>")
    path.write_text(text)
    assert [f.name for f in read_external_loads(path).forces] == ["Tip"]

"""benchmarks/peers.py: fccgrb's CNO-SQP against OpenSim's inverse kinematics on the same markers.

OpenSim's IK with unit marker weights minimizes the same sum of squared marker distances over
the same configuration space as CNO-SQP with the TC objective (docs/formulation.md §3), by different
code (Simbody's assembler over joint coordinates): reaching the same optimum is the independent
check that fccgrb's CNO solves the right problem. The OpenSim model itself is checked against
the YAML (neutral pose, marker placement) and against the prescribed motion at P0. The angles
are compared through body poses (acos(s1·s2), Eq. 10); that function is checked against
fccgrb's own ``angles_at`` and the synthesized trial's prescribed angles without OpenSim.
Timings are the benchmark's business, never asserted here.
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest

from fccgrb_cli.model import load_model
from fccgrb_cli.pipeline.synth import synthesize
from fccgrb_cli.signals.artefact import perturb
from fccgrb_cli.system import compile_system

ROOT = Path(__file__).resolve().parents[1]
FRAMES = 20


def _load_peers() -> ModuleType:
    spec = importlib.util.spec_from_file_location("peers", ROOT / "benchmarks" / "peers.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules["peers"] = module  # dataclasses resolve their module while the class is built
    spec.loader.exec_module(module)
    return module


peers = _load_peers()


@pytest.fixture(scope="module")
def five_bar():
    model = load_model(ROOT / "configs" / "models" / "five_bar.yaml")
    return model, compile_system(model, angles="coordinate", track=True), synthesize(model)


def _markers(truth, level_mm: float) -> np.ndarray:
    return perturb(truth.markers, truth.labels, truth.rate, level_mm * 1e-3, seed=0)[:FRAMES]


def test_angles_from_poses_are_fccgrb_angles(five_bar):
    """On fccgrb's own solution at P7.5 (NRM-WLS: bodies slightly off rigid, every angle away
    from its prescribed value), the angles and points from the body poses are fccgrb's; on the
    synthesized motion they are the prescribed angles."""
    model, system, truth = five_bar
    solved = peers.run_fccgrb("nrm-wls", system, truth.result.time[:FRAMES],
                              _markers(truth, 7.5))
    q = peers.solve_nrm(system, truth.result.time[:FRAMES], _markers(truth, 7.5),
                        peers.NrmSettings(1e-3, 1e-10, engine="compiled")).q
    poses = peers.poses_from_q(system, q)
    np.testing.assert_array_equal(poses, solved.poses)
    expected = np.array([system.angles_at(row) for row in q])
    assert np.abs(expected - truth.result.theta[:FRAMES]).max() > 0.01
    np.testing.assert_allclose(peers.angles_from_poses(model, poses), expected, atol=1e-12)
    which = [(tp.body, tp.point) for tp in model.tracked_points]
    np.testing.assert_allclose(peers.points_from_poses(model, poses),
                               [system.point_positions(row, which) for row in q], atol=1e-14)
    prescribed = peers.angles_from_poses(model, peers.poses_from_q(truth.system, truth.result.q))
    np.testing.assert_allclose(prescribed, truth.result.theta, atol=1e-9)


def test_marker_fit_by_hand(five_bar):
    """The fit is the mean distance over markers: one marker moved 3 mm off a model point at
    the neutral pose gives 3/9 mm."""
    model, system, _ = five_bar
    poses = peers.poses_from_q(system, system.layout.pose_q(model))
    markers = peers.points_from_poses(model, poses)
    markers[4, 1] += 3e-3
    assert peers.marker_fit(model, poses, markers) == pytest.approx(3e-3 / 9, rel=1e-12)


@pytest.fixture(scope="module")
def opensim_five_bar(five_bar):
    osim = pytest.importorskip("opensim")
    model = five_bar[0]
    return osim, peers.build_opensim_model(osim, model)


def _ik(opensim_five_bar, five_bar, level_mm: float, accuracy: float):
    osim, osim_model = opensim_five_bar
    model, _, truth = five_bar
    markers = _markers(truth, level_mm)
    time_s = truth.result.time[:FRAMES]
    table = peers.marker_table(osim, truth.labels, time_s, markers, truth.rate)
    solved, errors = peers.run_opensim(osim, osim_model, model, table, time_s, accuracy)
    return markers, solved, errors


def test_opensim_model_is_the_yaml(opensim_five_bar, five_bar):
    """Every OpenSim coordinate at zero leaves each body at its YAML pose, with its mass and
    inertia; OpenSim's markers sit at the YAML's points."""
    osim, osim_model = opensim_five_bar
    model, system, _ = five_bar
    state = osim_model.initSystem()
    osim_model.realizePosition(state)
    np.testing.assert_allclose(peers.opensim_poses(osim, osim_model, model, state),
                               peers.poses_from_q(system, system.layout.pose_q(model)),
                               atol=1e-14)
    assert osim_model.getNumCoordinates() == len(model.angles)
    for joint in model.joints:
        # at the neutral pose (every body aligned with the ground) a body vector's local
        # components are its global ones: a pin turns about its frames' Z = s_i = s_j, a
        # universal about the parent frame's X = s_i, then the child's Y = s_j
        built = osim_model.getJointSet().get(joint.name)
        frames = []
        for frame in (built.getParentFrame(), built.getChildFrame()):
            R = frame.getTransformInGround(state).R().asMat33()
            frames.append(np.array([[R.get(i, k) for k in range(3)] for i in range(3)]))
        np.testing.assert_allclose(frames[0], frames[1], atol=1e-14)
        if joint.type in ("revolute", "universal"):
            bi, bj = joint.bodies
            owner_i = model.ground if bi == "ground" else model.body(bi)
            s_i = owner_i.vectors[joint.axes[0]].local
            s_j = model.body(bj).vectors[joint.axes[1]].local
            columns = (2, 2) if joint.type == "revolute" else (0, 1)
            np.testing.assert_allclose(frames[0][:, columns[0]], s_i, atol=1e-14)
            np.testing.assert_allclose(frames[0][:, columns[1]], s_j, atol=1e-14)
    for b in model.bodies:
        body = osim_model.getBodySet().get(b.name)
        moments = body.getInertia().getMoments()
        assert body.getMass() == b.inertia.mass
        assert [moments.get(i) for i in range(3)] == list(np.diag(b.inertia.tensor))
    markers = osim_model.getMarkerSet()
    for tp in model.tracked_points:
        where = markers.get(tp.marker).getLocationInGround(state)
        expected = peers.points_from_poses(model, peers.opensim_poses(
            osim, osim_model, model, state))[model.marker_labels.index(tp.marker)]
        np.testing.assert_allclose([where.get(i) for i in range(3)], expected, atol=1e-14)


def test_opensim_reproduces_the_prescribed_motion(opensim_five_bar, five_bar):
    """At P0 (exact markers) OpenSim's IK on the built model returns the prescribed angles:
    the OpenSim model spans fccgrb's configuration space (a swapped universal arm or a wrong
    pin axis could not fit the markers). Over 300 frames the largest angle error measured was
    5.6e-7°; its own marker errors equal the distances from the poses."""
    model, _, truth = five_bar
    markers, solved, _ = _ik(opensim_five_bar, five_bar, 0.0, 1e-10)
    theta = peers.angles_from_poses(model, solved.poses)
    assert np.degrees(np.abs(theta - truth.result.theta[:FRAMES]).max()) < 1e-5
    assert peers.marker_fit(model, solved.poses, markers).max() < 1e-8
    markers7, solved7, errors7 = _ik(opensim_five_bar, five_bar, 7.5, 1e-10)
    distances = np.linalg.norm(peers.points_from_poses(model, solved7.poses) - markers7, axis=-1)
    assert distances.mean() > 1e-3
    np.testing.assert_allclose(errors7, distances, atol=1e-12)


def test_cno_sqp_reaches_opensims_optimum(opensim_five_bar, five_bar):
    """At P7.5 CNO-SQP (TC objective) and OpenSim's IK (accuracy 1e-10) land on the same
    optimum: angles within 1e-4° (measured over 300 frames: 1.1e-6° with the
    structured SQP, 3.1e-6° with scipy's SLSQP; 1.6e-7–3e-7° on these 20 frames: the spread the
    stopping tests leave on a flat objective; OpenSim's default accuracy 1e-5 is 0.14° off) and
    the per-frame mean fit within 1e-6 mm (measured 1.5e-7 mm). NRM-WLS, which lets the joints
    give a little (weight 1e-3), fits the markers closer and sits measurably apart (2.5e-3°)."""
    model, system, truth = five_bar
    markers, opensim, _ = _ik(opensim_five_bar, five_bar, 7.5, 1e-10)
    time_s = truth.result.time[:FRAMES]
    cno = peers.run_fccgrb("cno-sqp", system, time_s, markers)
    nrm = peers.run_fccgrb("nrm-wls", system, time_s, markers)
    reference = peers.angles_from_poses(model, opensim.poses)
    fit = peers.marker_fit(model, opensim.poses, markers)
    assert 4e-3 < fit.mean() < 5e-3
    assert np.degrees(np.abs(peers.angles_from_poses(model, cno.poses) - reference).max()) < 1e-4
    np.testing.assert_allclose(peers.marker_fit(model, cno.poses, markers), fit, rtol=0,
                               atol=1e-9)
    assert np.degrees(np.abs(peers.angles_from_poses(model, nrm.poses) - reference).max()) > 5e-4
    assert (peers.marker_fit(model, nrm.poses, markers) < fit).all()


def test_without_opensim_prints_fccgrb_rows(monkeypatch, capsys):
    """OpenSim missing: one line says so, fccgrb's rows still come, no exception."""
    monkeypatch.setitem(sys.modules, "opensim", None)
    monkeypatch.setattr(sys, "argv", ["peers.py", "--frames", "3", "--repeat", "1", "--no-gait",
                                      "--no-cli"])
    peers.main()
    out = capsys.readouterr().out
    assert "opensim: not installed" in out
    assert "biorbd: " in out
    for level in ("P0", "P7.5", "P30"):
        for method in ("nrm-wls", "cno-sqp"):
            assert any(line.startswith(level) and f"fccgrb {method}" in line
                       for line in out.splitlines())
    assert not any(line.startswith("P") and "OpenSim" in line for line in out.splitlines())


def test_the_default_command_lines_figures(tmp_path):
    """The command line's row reads ms/frame from a real ``fccgrb solve`` summary (the per-frame
    solve, so a fraction of the process's wall time) and the kernels' load from its stderr."""
    trial = tmp_path / "five_bar.c3d"
    model = ROOT / "configs" / "models" / "five_bar.yaml"
    assert peers.subprocess.run([peers.shutil.which("fccgrb"), "synth", str(model), "-o",
                                 str(trial), "--duration", "0.4"]).returncode == 0
    case = peers.Case("P30", load_model(model), np.zeros(40), np.zeros((40, 9, 3)), (), 100.0,
                      (str(model), str(trial), "--perturb", "30"))
    run = peers.run_cli(case, "nrm-wls", tmp_path)
    assert 0.0 < 40 * run.ms_per_frame * 1e-3 < run.wall_s
    assert 0.0 <= run.kernels_s < run.wall_s
    row = peers.cli_rows(case, 1, tmp_path, reference=10.0)[0].split()
    assert row[:3] == ["P30", "fccgrb", "nrm-wls"]
    assert float(row[4]) == pytest.approx(10.0 / float(row[3]), rel=0.01)


@pytest.fixture(scope="module")
def gait(tmp_path_factory):
    if not peers.GAIT_TRIAL.exists():
        pytest.skip(f"{peers.GAIT_TRIAL} not found")
    case = peers.gait_case(tmp_path_factory.mktemp("gait"))
    return peers.Case(case.name, case.model, case.time_s[:FRAMES], case.markers[:FRAMES],
                      case.labels, case.rate, case.cli)


def test_opensim_gait_model_reaches_cno_sqps_optimum(gait):
    """The lower limb (a FreeJoint pelvis, ball hips, pin knees, universal ankles) built in
    OpenSim from the calibrated YAML: its IK at accuracy 1e-10 and CNO-SQP on the walking
    trial's markers reach the same optimum (every clinical angle within 1e-4°, the summed
    squared marker distances within 1e-9 relative): the same configuration space. Built from
    the pose's transported frames alone, without each body's own joint axis (benchmarks/
    peers.py ``_exact``), OpenSim's knees turned about axes up to 3.2° off fccgrb's and the
    angles differed by up to 1.8°."""
    osim = pytest.importorskip("opensim")
    osim_model = peers.build_opensim_model(osim, gait.model)
    table = peers.marker_table(osim, gait.labels, gait.time_s, gait.markers, gait.rate)
    opensim, _ = peers.run_opensim(osim, osim_model, gait.model, table, gait.time_s, 1e-10)
    system = compile_system(gait.model, angles="coordinate", track=True)
    cno = peers.run_fccgrb("cno-sqp", system, gait.time_s, gait.markers)

    def squared(poses):
        return np.sum((peers.points_from_poses(gait.model, poses) - gait.markers) ** 2,
                      axis=(-1, -2))

    np.testing.assert_allclose(squared(opensim.poses), squared(cno.poses), rtol=1e-9)
    gap = peers.angles_from_poses(gait.model, opensim.poses) - peers.angles_from_poses(
        gait.model, cno.poses)
    assert np.degrees(np.abs(gap).max()) < 1e-4

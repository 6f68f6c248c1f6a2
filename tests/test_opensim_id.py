"""Inverse dynamics of imported models, coordinates in: the power balance Σ τ θ̇ + P_loads =
d(T + V)/dt on a generated model with and without an external load (an independent closed check
of every term), OpenSim's low-pass against its defining properties, and OpenSim's own ID
regressions within OpenSim's 2.0 N·m (N): arm26 through the API, gait2392 with its two plates'
ground reactions through ``fccgrb solve --coordinates`` and ``fccgrb export --format sto`` as an
OpenSim user runs them."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

import fccgrb_cli as fc
from fccgrb_cli.cli.main import main
from fccgrb_cli.dynamics.loads import ExternalLoad
from fccgrb_cli.dynamics.mass import gravity_forces, mass_matrix
from fccgrb_cli.dynamics.moving import coordinate_forces, forces_from_coordinates
from fccgrb_cli.model import load_model
from fccgrb_cli.model.osim.convert import parse_osim_model
from fccgrb_cli.opensim.storage import read_storage as fc_storage
from fccgrb_cli.pipeline.coordinates import coordinates_run
from fccgrb_cli.pipeline.options import SolveOptions
from fccgrb_cli.signals.opensim_lowpass import lowpass_padded
from fccgrb_cli.solvers.engine import numba_available
from fccgrb_cli.system.compiled import compile_system
from fccgrb_cli.system.moving_pose import pose_from_coordinates
from tests.osim_text import knee_model
from tests.test_moving_joints import random_model_text

ID_DIR = Path(__file__).resolve().parents[2] / "shared" / "data" / "opensim" / "id_gait2392"
TOLERANCE = 2.0  # N·m: OpenSim's own, RMS per column


@pytest.mark.parametrize(("seed", "loaded"), [(None, False), (None, True), (1, True), (2, True),
                                             (5, False)])
def test_coordinate_forces_balance_the_power_of_the_motion(seed, loaded):
    """``seed`` None: the knee model; a number: a generated model (random transforms, splines,
    polynomials, and a coupler: tests/test_moving_joints.py), whose coupled coordinate's force
    counts in the balance like any other's."""
    text = knee_model() if seed is None else random_model_text(seed)
    system = compile_system(parse_osim_model(text, "knee.osim"), angles="coordinate")
    nb = system.layout.n_body_q
    M, g = mass_matrix(system.model), gravity_forces(system.model)
    rng = np.random.default_rng(7)
    n = len(system.model.angles)
    amplitude, frequency, phase = rng.uniform(0.1, 0.5, n), rng.uniform(0.5, 2.0, n), \
        rng.uniform(0, 2 * np.pi, n)

    def theta(t: float, order: int = 0) -> np.ndarray:
        w = 2 * np.pi * frequency
        return amplitude * w**order * np.sin(w * t + phase + order * np.pi / 2) + \
            (system.functions.defaults if order == 0 else 0.0)

    def x(t: float) -> np.ndarray:
        return pose_from_coordinates(system, theta(t))[:nb]

    def energy(t: float, h: float = 1e-5) -> float:
        xd = (x(t + h) - x(t - h)) / (2 * h)
        return 0.5 * xd @ M @ xd - g @ x(t)

    body = system.model.bodies[-1].name
    at = system.layout.x_offset(body) + np.arange(12)
    local = rng.normal(size=3) * 0.1
    force, moment = rng.normal(size=3) * 50.0, rng.normal(size=3) * 5.0

    def load_power(t: float, h: float = 1e-5) -> float:
        """f · (velocity of the body point under it) + n · ω, by differences of the pose."""
        def frame(s: float) -> np.ndarray:
            return x(s)[at].reshape(4, 3)

        def point(s: float) -> np.ndarray:
            r, u, v, w = frame(s)
            return r + local[0] * u + local[1] * v + local[2] * w

        axes = np.column_stack(frame(t)[1:])
        rate = (np.column_stack(frame(t + h)[1:]) - np.column_stack(frame(t - h)[1:])) / (2 * h)
        spin = rate @ axes.T  # ω× = Ṙ Rᵀ
        omega = np.array([spin[2, 1], spin[0, 2], spin[1, 0]])
        return force @ (point(t + h) - point(t - h)) / (2 * h) + moment @ omega

    for t in (0.1, 0.37, 0.8):
        loads = []
        if loaded:
            r, u, v, w = x(t)[at].reshape(4, 3)
            where = r + local[0] * u + local[1] * v + local[2] * w
            loads = [ExternalLoad("push", body, force[None], where[None], moment[None])]
        tau = coordinate_forces(system, theta(t)[None], theta(t, 1)[None], theta(t, 2)[None],
                                loads)[0]
        h = 1e-4  # central differences: truncation h²·E‴/6 ~ 1e-5 W here
        power = (energy(t + h) - energy(t - h)) / (2 * h)
        supplied = load_power(t) if loaded else 0.0
        assert tau @ theta(t, 1) + supplied == pytest.approx(power, rel=1e-5, abs=1e-5)
        assert np.abs(tau).max() > 1.0  # the check is not of zeros
        if loaded:
            assert abs(supplied) > 1.0  # and the load does work


@pytest.mark.skipif(not numba_available(), reason="numba is not installed")
@pytest.mark.parametrize("seed", [None, 0, 3, 4])
def test_the_compiled_inverse_is_the_numpy_one(seed):
    """``coordinate_inverse`` through the compiled kernels (the rates, the multipliers, the
    coordinates' forces and the misfit; the poses of every frame at once) gives the numpy
    reference's frame-by-frame numbers, on the knee and on generated models (random transforms,
    splines, a coupler) with two loads on two bodies, over frames that move the coordinates far
    from their defaults; a frame with a NaN rate is left NaN and changes no other frame."""
    from fccgrb_cli.dynamics.moving import _same_rows, coordinate_inverse

    text = knee_model() if seed is None else random_model_text(seed)
    model = parse_osim_model(text, "model.osim")
    system = compile_system(model, angles="coordinate")
    tracking = compile_system(model, angles="coordinate", track=True)
    assert _same_rows(system, tracking)  # the kernels run (else the numpy path, twice)
    rng = np.random.default_rng(11 if seed is None else seed)
    n, k = 40, len(model.angles)
    t = np.linspace(0, 1, n)[:, None]
    amplitude, rate = rng.uniform(0.1, 0.6, k), rng.uniform(1.0, 3.0, k)
    theta = system.functions.defaults + amplitude * np.sin(rate * t)
    theta_d = amplitude * rate * np.cos(rate * t)
    theta_dd = -amplitude * rate**2 * np.sin(rate * t)
    theta_dd[17, 0] = np.nan
    loads = [ExternalLoad(f"load{j}", body.name, rng.normal(size=(n, 3)) * 40.0,
                          rng.normal(size=(n, 3)) * 0.3, rng.normal(size=(n, 3)) * 4.0)
             for j, body in enumerate(model.bodies[-2:])]
    (q, qd, qdd), reference = coordinate_inverse(system, theta, theta_d, theta_dd, loads)
    (q2, qd2, qdd2), compiled = coordinate_inverse(system, theta, theta_d, theta_dd, loads,
                                                   kernels=tracking)
    assert np.allclose(q2, q, rtol=0, atol=1e-12)
    ok = np.ones(n, dtype=bool)
    ok[17] = False
    for name in ("lam", "joint_moments", "kinetic", "potential", "external_power"):
        ours, theirs = getattr(compiled, name)[ok], getattr(reference, name)[ok]
        scale = max(1.0, float(np.abs(theirs).max()))
        assert np.allclose(ours, theirs, rtol=0, atol=1e-9 * scale), name
    assert np.allclose(qd2[ok], qd[ok], rtol=0, atol=1e-10)
    assert np.allclose(qdd2[ok], qdd[ok], rtol=0, atol=1e-9)
    assert np.all(compiled.residual[ok] < 1e-8)
    assert np.isnan(compiled.joint_moments[17]).all() and np.isnan(compiled.lam[17]).all()
    assert np.abs(reference.joint_moments[ok]).max() > 1.0
    assert np.abs(reference.external_power[ok]).max() > 1.0


@pytest.mark.parametrize("seed", [None, 1, 2])
def test_poses_of_many_frames_are_those_of_each(seed):
    """``pose_from_coordinates`` of frames × n_θ (every joint's transform evaluated on all frames
    at once from the functions' polynomial pieces) equals it frame by frame (the rows' own
    transform terms), inside and outside the splines' points."""
    text = knee_model() if seed is None else random_model_text(seed)
    system = compile_system(parse_osim_model(text, "model.osim"), angles="coordinate")
    rng = np.random.default_rng(5)
    theta = system.functions.defaults + rng.uniform(-2.5, 2.5, (30, len(system.model.angles)))
    many = pose_from_coordinates(system, theta)
    each = np.array([pose_from_coordinates(system, row) for row in theta])
    assert many.shape == each.shape == (30, system.nq)
    assert np.allclose(many, each, rtol=0, atol=1e-13)
    assert np.ptp(many[:, :system.layout.n_body_q], axis=0).max() > 0.1


def test_opensims_lowpass_keeps_lines_and_halves_its_cutoff():
    """OpenSim's padded third-order filter run forward and backward: over the trial's rows a
    straight line passes unchanged (zero phase, unit gain at DC, padding that keeps value and
    slope; the start's transient dies out within the padding), a sine at the
    cutoff leaves at half its amplitude (−3 dB per pass) and one at a tenth of it whole."""
    rate, cutoff = 100.0, 6.0
    time = np.arange(400) / rate
    line = 0.3 + 2.0 * time
    stamps, out = lowpass_padded(time, line[:, None], cutoff)
    assert len(stamps) == len(time) + 2 * 200 and np.allclose(np.diff(stamps), 1 / rate)
    trial = slice(200, 600)
    assert np.allclose(stamps[trial], time)
    assert np.allclose(out[trial, 0], line, atol=1e-6)
    assert not np.allclose(out[:20, 0], 0.3 + 2.0 * stamps[:20], atol=1e-3)  # the transient
    middle = slice(300, 500)  # the trial's middle, in the padded rows
    for frequency, gain in ((cutoff, 0.5), (cutoff / 10, 1.0)):
        sine = np.sin(2 * np.pi * frequency * time)
        filtered = lowpass_padded(time, sine[:, None], cutoff)[1][middle, 0]
        assert np.abs(filtered).max() == pytest.approx(gain, abs=0.01)


def read_storage(path: Path) -> tuple[list[str], np.ndarray]:
    lines = path.read_text().splitlines()
    end = next(k for k, line in enumerate(lines) if line.strip() == "endheader")
    rows = np.array([[float(v) for v in line.split()] for line in lines[end + 2:] if line.strip()])
    return lines[end + 1].split(), rows


@pytest.mark.skipif(not ID_DIR.is_dir(), reason="../shared/data/opensim not here")
def test_opensims_arm26_inverse_dynamics_within_its_tolerance():
    model = load_model(ID_DIR / "arm26.osim")
    system = compile_system(model, angles="coordinate")
    names, rows = read_storage(ID_DIR / "arm26_InverseKinematics.mot")  # degrees (its setup)
    time = rows[:, 0]
    order = [c.name for c in model.angles]
    theta = np.column_stack([np.radians(rows[:, names.index(n)]) for n in order])
    tau, smooth, rate, _ = forces_from_coordinates(system, time, theta, cutoff=6.0)
    # the rates are those of the filtered coordinates (a check of the spline, not of OpenSim)
    assert np.allclose(rate[1:-1], np.gradient(smooth, time, axis=0)[1:-1], atol=0.05)
    columns, reference = read_storage(ID_DIR / "std_arm26_InverseDynamics.sto")
    assert np.allclose(reference[:, 0], time, atol=1e-6)
    for k, name in enumerate(order):
        expected = reference[:, columns.index(f"{name}_moment")]
        rms = float(np.sqrt(np.mean((tau[:, k] - expected) ** 2)))
        assert rms < TOLERANCE, (name, rms)
        assert rms < 0.1 * np.abs(expected).max()  # far inside: 0.04 N·m of 2.8 N·m


@pytest.mark.skipif(not ID_DIR.is_dir(), reason="../shared/data/opensim not here")
def test_opensims_gait2392_inverse_dynamics_through_the_command(tmp_path):
    """OpenSim's ID regression as its setup runs it (subject01_Setup_InverseDynamics.xml:
    coordinates low-passed at 6 Hz, the two plates' ground reactions on calcn_r and calcn_l),
    typed as an OpenSim user would; every generalized force within OpenSim's 2.0 (N·m or N) RMS
    over the rows both files have, and far inside it."""
    results, table = tmp_path / "id.h5", tmp_path / "id.sto"
    runner = CliRunner()
    out = runner.invoke(main, ["solve", str(ID_DIR / "subject01.osim"),
                               "--coordinates", str(ID_DIR / "subject01_walk1_ik.mot"),
                               "--loads", str(ID_DIR / "subject01_walk1_grf.xml"),
                               "--filter-cutoff", "6", "-o", str(results)])
    assert out.exit_code == 0, out.output
    out = runner.invoke(main, ["export", str(results), "--format", "sto", "-o", str(table)])
    assert out.exit_code == 0, out.output
    columns, ours = read_storage(table)
    names, reference = read_storage(ID_DIR / "std_subject01_InverseDynamics.sto")
    rows = [(i, j) for i, t in enumerate(reference[:, 0])
            for j in np.flatnonzero(np.abs(ours[:, 0] - t) < 1e-5)]
    assert len(rows) > 60  # 0.5–1.6 s at 60 Hz
    mine, theirs = (np.array([k for k, _ in rows]), np.array([k for _, k in rows]))
    assert set(names[1:]) <= set(columns)
    worst = 0.0
    for name in names[1:]:
        expected = reference[mine, names.index(name)]
        rms = float(np.sqrt(np.mean((ours[theirs, columns.index(name)] - expected) ** 2)))
        assert rms < TOLERANCE, (name, rms)
        if np.ptp(expected) > 5.0:  # a force that matters: within 5 % of its range
            assert rms < 0.05 * np.ptp(expected), (name, rms)
        worst = max(worst, rms)
    assert worst > 0.0  # the comparison saw our numbers


IK_DIR = ID_DIR.parent / "ik_gait2354_synthetic"


@pytest.mark.skipif(not IK_DIR.is_dir(), reason="../shared/data/opensim not here")
def test_a_solved_trials_forces_are_those_of_its_coordinates():
    """The markers solved (IK) then the inverse dynamics in one ``solve``, against the inverse
    dynamics of OpenSim's own IK answer for the same synthetic markers given as coordinates:
    the two coordinate sets agree to 0.01°, so the forces agree to far within 1 % of each
    one's range (a dropped rate, a stretch misplaced, the loads' or the filter's wiring would
    not). OpenSim's file prints its times with 3 decimals: they are taken on their grid, said
    in a note (through the rounded times the accelerations err by tens of newtons)."""
    model = load_model(IK_DIR / "subject01_simbody.osim")
    run = fc.solve(model, fc.read_trial(IK_DIR / "subject01_synthetic_marker_data.trc"),
                   filter_cutoff=6.0)
    assert any("no external loads" in w for w in run.warnings)
    given = coordinates_run(model, fc_storage(IK_DIR / "std_subject01_walk1_ik.mot"),
                            SolveOptions(filter_cutoff=6.0))
    assert any("times rounded in the file" in note for note in given.notes)
    assert np.allclose(run.result.time + run.start_time,
                       given.result.time + given.start_time, atol=1e-9)
    ours, theirs = run.dynamics.inverse.joint_moments, given.dynamics.inverse.joint_moments
    for k, name in enumerate(run.result.angle_names):
        j = given.result.angle_names.index(name)
        rms = float(np.sqrt(np.mean((ours[:, k] - theirs[:, j]) ** 2)))
        assert rms <= 0.01 * np.ptp(theirs[:, j]) + 1e-3, (name, rms)
    assert np.ptp(theirs[:, given.result.angle_names.index("pelvis_ty")]) > 100.0

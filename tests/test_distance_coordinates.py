"""Distance coordinates end to end: d = (r_Q − r_P)·s drives and solves the slides of prismatic,
cylindrical and parallel joints, which no angle can drive (docs/formulation.md §9: g(d) = d).

Two models: ``configs/models/slider.yaml`` (a carriage on a vertical prismatic slide, a pendulum
hinged to it: one distance, one angle) and, written here, a sleeve on a tilted cylindrical joint
carrying a block on a parallel joint (four distances, two angles). Each is synthesized by
``fccgrb synth`` and solved at P0 by NRM-WLS, CNO-SQP and the marker-driven AD baseline, which
must recover the synthesized truth. The dynamics are checked against physics, not against the
package: the slide's joint force against a closed form derived below from Newton's second law
along the slide, and power balance Σ τ_k θ̇_k + external power = d(T + V)/dt on every model.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from cli_helpers import runner

import fccgrb_cli as fc
from fccgrb_cli.cli.main import main
from fccgrb_cli.dynamics import inverse_dynamics
from fccgrb_cli.model import parse_model
from fccgrb_cli.pipeline.synth import synthesize
from fccgrb_cli.trial.truth import read_truth, truth_path

SLIDER = Path(__file__).resolve().parents[1] / "configs" / "models" / "slider.yaml"
DURATION, RATE = 1.0, 100.0
METHODS = ("nrm-wls", "cno-sqp", "ad")

# The sleeve's frame at the neutral pose: w along the tilted axis g, u ⟂ g in the xz plane. The
# block's offset dx passes through zero: no angle's bounds or warnings may touch a distance.
SLEEVE_BLOCK = """\
name: sleeve_block
units: {angle: deg}
gravity: [0, 0, -9.81]
ground:
  points: {O: [0, 0, 0]}
  vectors: {g: [0.6, 0, 0.8]}
bodies:
  sleeve:
    mass: 1.2
    inertia: [0.004, 0.005, 0.003]
    points: {C: [0, 0, 0], S1: [0.06, 0, 0.05], S2: [0, 0.07, -0.04], S3: [-0.05, -0.03, 0.02]}
    pose: {r: [0.3, 0, 0.4], u: [0.8, 0, -0.6], v: [0, 1, 0], w: [0.6, 0, 0.8]}
  block:
    mass: 0.7
    com: [0.01, -0.02, 0.015]
    inertia: [[0.002, 0.0002, 0], [0.0002, 0.003, -0.0001], [0, -0.0001, 0.0025]]
    points: {B: [0, 0, 0], K1: [0.05, 0.02, 0], K2: [-0.03, 0.06, 0.01], K3: [0, -0.04, 0.05]}
    pose: {r: [0.556, 0.2, 0.68], u: [0.8, 0, -0.6], v: [0, 1, 0], w: [0.6, 0, 0.8]}
joints:
  - {name: rod, type: cylindrical, bodies: [ground, sleeve], points: [O, C], axes: [g, w]}
  - {name: float, type: parallel, bodies: [sleeve, block], axes: [w, w]}
angles:
  - {name: spin, vectors: [ground.y, sleeve.u],
     motion: {mean: 90, terms: [{amplitude: 40, frequency: 0.8}]}}
  - {name: turn, vectors: [sleeve.u, block.v],
     motion: {mean: 90, terms: [{amplitude: 30, frequency: 1.1, phase: 50}]}}
distances:
  - {name: along, points: [ground.O, sleeve.C], axis: ground.g,
     motion: {mean: 0.5, terms: [{amplitude: 0.15, frequency: 0.6, phase: 20}]}}
  - {name: dx, points: [sleeve.C, block.B], axis: sleeve.u,
     motion: {mean: 0.02, terms: [{amplitude: 0.05, frequency: 0.9}]}}
  - {name: dy, points: [sleeve.C, block.B], axis: sleeve.v,
     motion: {mean: 0.2, terms: [{amplitude: 0.04, frequency: 1.3, phase: 80}]}}
  - {name: dz, points: [sleeve.C, block.B], axis: sleeve.w,
     motion: {mean: 0.3, terms: [{amplitude: 0.06, frequency: 0.7, phase: 140}]}}
tracking:
  points:
    - {marker: S1, point: sleeve.S1}
    - {marker: S2, point: sleeve.S2}
    - {marker: S3, point: sleeve.S3}
    - {marker: K1, point: block.K1}
    - {marker: K2, point: block.K2}
    - {marker: K3, point: block.K3}
"""


def model_file(name: str, folder: Path) -> Path:
    if name == "slider":
        return SLIDER
    path = folder / f"{name}.yaml"
    path.write_text(SLEEVE_BLOCK, encoding="utf-8")
    return path


@pytest.fixture(scope="module", params=["slider", "sleeve_block"])
def trial(request, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """A model file and the trial ``fccgrb synth`` wrote for it (truth beside it)."""
    folder = tmp_path_factory.mktemp(request.param)
    model = model_file(request.param, folder)
    out = folder / "trial.c3d"
    result = runner().invoke(main, ["synth", str(model), "-o", str(out), "--duration",
                                    str(DURATION), "--rate", str(RATE)])
    assert result.exit_code == 0, result.output
    assert "distances " in result.output  # the synth line reports distances apart (mm)
    return model, out


@pytest.fixture(scope="module")
def runs(trial: tuple[Path, Path]) -> dict[str, fc.Run]:
    model, path = trial
    loaded, read = fc.load_model(model), fc.read_trial(path)
    return {method: fc.solve(loaded, read, method=method) for method in METHODS}


def test_check_counts_distances_as_degrees_of_freedom(trial: tuple[Path, Path]) -> None:
    model, _ = trial
    result = runner().invoke(main, ["check", str(model)])
    assert result.exit_code == 0, result.output
    expected = ("angular coordinates 1, distance coordinates 1" if model == SLIDER
                else "angular coordinates 2, distance coordinates 4")
    assert expected in result.output


@pytest.mark.parametrize("method", METHODS)
def test_every_method_recovers_the_truth_at_p0(runs: dict[str, fc.Run], trial, method: str
                                               ) -> None:
    """Angles to 1e-6 rad and distances to 1 µm: the C3D's 32-bit floats (mm) are the only
    error between the synthesized markers and those solved."""
    run = runs[method]
    truth = read_truth(truth_path(trial[1]))
    assert run.result.converged.all() and run.result.trusted.all()
    assert not [m for m in run.result.messages if "deg of 0 or 180" in m]
    units = np.array(run.angles.units)
    kinds = [a.kind for a in run.model.angles]
    assert units.tolist() == ["m" if k == "distance" else "rad" for k in kinds]
    assert "m" in units and "rad" in units
    error = np.abs(run.angles.values - truth.theta)
    assert error[:, units == "rad"].max() < 1e-6
    assert error[:, units == "m"].max() < 1e-6
    # The truth moves the slides by centimetres: the comparison is not vacuous.
    assert np.ptp(truth.theta[:, units == "m"], axis=0).min() > 0.05
    row = run.summary()
    assert row["max |dθ| deg"] < 1e-4 and row["max |dd| mm"] < 1e-3
    assert run.moments.units == tuple("N" if u == "m" else "N·m" for u in units)


def test_results_file_labels_each_column(runs: dict[str, fc.Run], tmp_path: Path) -> None:
    import h5py

    run = runs["nrm-wls"]
    path = tmp_path / "r.h5"
    fc.write_results(run, path)
    units = list(run.angles.units)
    with h5py.File(path, "r") as h5:
        g = h5[f"runs/{run.name}"]
        assert [str(u) for u in g["theta"].attrs["units"]] == units
        assert [str(u) for u in g["theta_dd"].attrs["units"]] == [u + "/s²" for u in units]
        assert [str(u) for u in g["joint_moments"].attrs["units"]] == [
            "N" if u == "m" else "N·m" for u in units]


def exact(model_text: str, rate: float = 500.0, duration: float = 1.0):
    """The synthesized motion (exact θ̇*, θ̈*) and its inverse dynamics."""
    model = parse_model(model_text, "model.yaml")
    s = synthesize(model, duration=duration, rate=rate)
    r = s.result
    return model, r, inverse_dynamics(s.system, r)


@pytest.mark.parametrize("source", ["slider", "sleeve_block"])
def test_power_balance(source: str) -> None:
    """Σ τ_k θ̇_k (N·m × rad/s for angles, N × m/s for distances) = d(T + V)/dt: no external
    load here. A distance's force with the wrong sign, or its row's −g′ dropped, breaks it."""
    text = SLIDER.read_text(encoding="utf-8") if source == "slider" else SLEEVE_BLOCK
    _, r, inv = exact(text)
    assert not np.abs(inv.external_power).any()
    power = (inv.joint_moments * r.theta_d).sum(axis=1)
    energy = inv.kinetic + inv.potential
    dt = r.time[1] - r.time[0]
    dE = (energy[:-4] - 8 * energy[1:-3] + 8 * energy[3:-1] - energy[4:]) / (12 * dt)
    scale = np.abs(power).max()
    assert np.abs(power[2:-2] - dE).max() < 1e-6 * scale
    # Each distance's own power is a real share of the balance.
    distance = np.array([a.kind == "distance" for a in parse_model(text, "m").angles])
    share = np.abs(inv.joint_moments[:, distance] * r.theta_d[:, distance]).max()
    assert share > 0.1 * scale


def test_slide_force_is_newtons_second_law() -> None:
    """The carriage (m₁) slides along ground z at height d; the pendulum's CoM (m₂) hangs
    l = 0.25 m below the hinge, which rides at height d. With w = Ry(φ) z the pendulum's axis
    and θ the angle between the carriage's u and w, cos θ = sin φ, so z_G2 = d − l sin θ.
    The prismatic joint's reactions have no component along z, so along z the slide force F and
    gravity move both masses: F = m₁(d̈ + g) + m₂(z̈_G2 + g), with
    z̈_G2 = d̈ − l (cos θ θ̈ − sin θ θ̇²)."""
    model, r, inv = exact(SLIDER.read_text(encoding="utf-8"))
    names = [a.name for a in model.angles]
    k_swing, k_lift = names.index("swing"), names.index("lift")
    th, thd, thdd = r.theta[:, k_swing], r.theta_d[:, k_swing], r.theta_dd[:, k_swing]
    d_dd = r.theta_dd[:, k_lift]
    m1, m2 = model.body("carriage").inertia.mass, model.body("pendulum").inertia.mass
    g, length = 9.81, 0.25
    z_dd = d_dd - length * (np.cos(th) * thdd - np.sin(th) * thd**2)
    force = m1 * (d_dd + g) + m2 * (z_dd + g)
    assert np.abs(inv.joint_moments[:, k_lift] - force).max() < 1e-9 * np.abs(force).max()
    assert np.ptp(force) > 5.0  # the motion, not only the weight, loads the slide


def test_pipeline_slide_force_follows_the_closed_form(runs: dict[str, fc.Run], trial) -> None:
    """The same force through the whole pipeline (solved d, θ, differenced rates)."""
    if trial[0] != SLIDER:
        pytest.skip("the closed form is the slider's")
    run = runs["nrm-wls"]
    m = run.model
    theta = run.angles
    th, lift = theta["swing"], theta["lift"]
    dt = 1.0 / run.rate
    inner = slice(3, -3)
    thd = np.gradient(th, dt)
    thdd = np.gradient(thd, dt)
    ddd = np.gradient(np.gradient(lift, dt), dt)
    m1, m2 = m.body("carriage").inertia.mass, m.body("pendulum").inertia.mass
    force = m1 * (ddd + 9.81) + m2 * (ddd - 0.25 * (np.cos(th) * thdd - np.sin(th) * thd**2)
                                      + 9.81)
    solved = run.moments["lift"]
    assert np.abs(solved - force)[inner].max() < 0.02 * np.abs(force).max()


def test_mixed_coordinates_hold_the_distances(runs: dict[str, fc.Run]) -> None:
    """In the MC solution q ends with the coordinates: the distances there equal the points'
    offsets along the axes, computed here from the solved body coordinates."""
    run = runs["cno-sqp"]
    model = run.model
    q = run.q
    for k, coord in enumerate(model.angles):
        if coord.kind != "distance":
            continue

        for f in (0, len(run.result.time) // 2):
            def frame(body: str, f: int = f) -> np.ndarray:
                """Rows r, u, v, w of a body (the ground: origin and identity)."""
                if body == "ground":
                    return np.vstack([np.zeros(3), np.eye(3)])
                return np.array([[q[f"{body}.{x}.{axis}"][f] for axis in "xyz"]
                                 for x in "ruvw"])

            def place(body: str, local: tuple, is_point: bool) -> np.ndarray:
                return np.array([1.0 if is_point else 0.0, *local]) @ frame(body)

            table = {b.name: b for b in model.bodies}
            points = model.ground.points if coord.body1 == "ground" else \
                table[coord.body1].points
            vectors = model.ground.vectors if coord.body1 == "ground" else \
                table[coord.body1].vectors
            other = model.ground.points if coord.body2 == "ground" else table[coord.body2].points
            offset = (place(coord.body2, other[coord.point2].local, True)
                      - place(coord.body1, points[coord.point1].local, True))
            axis = place(coord.body1, vectors[coord.axis].local, False)
            assert abs(offset @ axis - run.angles.values[f, k]) < 1e-9


def test_summary_keeps_metres_out_of_degrees(runs: dict[str, fc.Run]) -> None:
    """With the truth's distances moved by 0.5 m, the summary's max |dd| reads 500 mm and its
    max |dθ| (angles only) stays what the angles alone give."""
    from dataclasses import replace

    run = runs["nrm-wls"]
    distance = np.array(run.angles.units) == "m"
    moved = run.truth_theta + np.where(distance, 0.5, 0.0)
    row = replace(run, truth_theta=moved).summary()
    angle_error = np.abs(run.angles.values - run.truth_theta)[:, ~distance].max()
    assert row["max |dθ| deg"] == pytest.approx(np.degrees(angle_error), rel=1e-9)
    assert row["max |dd| mm"] == pytest.approx(500.0, abs=1e-3)


def test_summary_keeps_newtons_out_of_newton_metres(runs: dict[str, fc.Run]) -> None:
    """A slide's joint force is reported as max |F| N, apart from the hinges' max |τ| N·m."""
    run = runs["nrm-wls"]
    loads = np.abs(run.dynamics.inverse.joint_moments)
    distance = np.array([a.kind == "distance" for a in run.model.angles])
    row = run.summary()
    assert row["max |F| N"] == pytest.approx(loads[:, distance].max())
    assert row["max |τ| N·m"] == pytest.approx(loads[:, ~distance].max())
    assert row["max |F| N"] != row["max |τ| N·m"]

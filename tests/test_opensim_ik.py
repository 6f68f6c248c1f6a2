"""OpenSim's own IK regression test, passed with OpenSim's criterion: on its synthetic Gait2354
trial (markers generated on the model, 31 markers, 73 frames) every coordinate's RMS difference
to OpenSim's own solution (std_subject01_walk1_ik.mot) is below 0.2° — translations below
0.2 mm, the same criterion in metres at the scale of the markers' rounding — for the uniform
and the weighted task sets (``--tasks``, as a user gives them), solved with the mixed
coordinates by NRM-WLS and by CNO-SQP; the compiled kernels and the numpy reference engine give
the same coordinates and rates."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fccgrb_cli.api import solve
from fccgrb_cli.model import load_model
from fccgrb_cli.trial.record import read_trc

IK_DIR = Path(__file__).resolve().parents[2] / "shared" / "data" / "opensim" / \
    "ik_gait2354_synthetic"
pytestmark = pytest.mark.skipif(not IK_DIR.is_dir(), reason="../shared/data/opensim not here")
DEGREES = 0.2      # OpenSim's tolerance for its IK regression test, per coordinate (RMS)
METRES = 0.2e-3    # translations (pelvis_tx/ty/tz)


def opensim_solution() -> tuple[list[str], np.ndarray]:
    """OpenSim's IK output: time and 23 coordinates (rotations in degrees, as IK writes them)."""
    lines = (IK_DIR / "std_subject01_walk1_ik.mot").read_text().splitlines()
    end = next(k for k, line in enumerate(lines) if line.strip() == "endheader")
    names = lines[end + 1].split()
    rows = np.array([[float(v) for v in line.split()] for line in lines[end + 2:] if line.strip()])
    return names, rows


@pytest.fixture(scope="module")
def gait():
    return (load_model(IK_DIR / "subject01_simbody.osim"),
            read_trc(IK_DIR / "subject01_synthetic_marker_data.trc"))


@pytest.mark.parametrize("tasks", ["gait2354_IK_Tasks_uniform.xml", "gait2354_IK_Tasks.xml"])
@pytest.mark.parametrize("method", ["nrm-wls", "cno-sqp"])
def test_opensims_ik_regression_passes_with_its_own_criterion(gait, method, tasks):
    model, trial = gait
    run = solve(model, trial, method=method, dynamics=False, tasks=str(IK_DIR / tasks))
    model = run.model  # the markers the task set tracks
    assert any(note.startswith("engine: compiled kernels") for note in run.notes)
    names, reference = opensim_solution()
    assert len(reference) == trial.n_frames == run.result.n_frames
    assert np.allclose(reference[:, 0], trial.start + np.arange(trial.n_frames) / trial.rate,
                       atol=6e-4)  # the .mot rounds times to 1 ms
    assert run.result.converged.all()
    theta = run.result.q[:, -len(model.angles):]
    order = [c.name for c in model.angles]
    worst = {}
    for k, name in enumerate(names[1:], start=1):
        coordinate = model.angles[order.index(name)]
        ours = theta[:, order.index(name)]
        if coordinate.translational:
            rms = float(np.sqrt(np.mean((ours - reference[:, k]) ** 2)))
            assert rms < METRES, (name, rms)
        else:
            rms = float(np.sqrt(np.mean((np.degrees(ours) - reference[:, k]) ** 2)))
            assert rms < DEGREES, (name, rms)
        worst[name] = rms
    assert len(worst) == 23


@pytest.mark.parametrize("method", ["nrm-wls", "cno-sqp"])
def test_the_compiled_kernels_give_the_numpy_engines_coordinates_and_rates(gait, method):
    model, trial = gait
    runs = {engine: solve(model, trial, method=method, dynamics=False, engine=engine)
            for engine in ("numpy", "compiled")}
    assert any(note.startswith("engine: numpy reference (--engine numpy)")
               for note in runs["numpy"].notes)
    assert any(note.startswith("engine: compiled kernels") for note in runs["compiled"].notes)
    numpy, compiled = runs["numpy"].result, runs["compiled"].result
    assert numpy.converged.all() and compiled.converged.all()
    assert np.abs(compiled.theta - numpy.theta).max() < 1e-8  # rad, m
    assert np.abs(compiled.q - numpy.q).max() < 1e-8
    # the rates: Φ_top,b q̇_b = −Φ_θ θ̇ with the joints' ∂h/∂θ, and its γ, in either engine
    scale = np.abs(numpy.qd).max(), np.abs(numpy.qdd).max()
    assert np.abs(compiled.qd - numpy.qd).max() < 1e-8 * scale[0]
    assert np.abs(compiled.qdd - numpy.qdd).max() < 1e-8 * scale[1]


def test_the_command_line_solves_an_osim_model_and_exports_opensims_coordinates(tmp_path,
                                                                              monkeypatch):
    # fccgrb solve MODEL.osim TRIAL.trc, then export --format mot: OpenSim's columns, rotations
    # in degrees and translations in metres, within OpenSim's criterion of its own solution
    from cli_helpers import run_cli

    from fccgrb_cli.system import sparse

    monkeypatch.setattr(sparse, "_TOLD", set())  # the engine's notes are once per process

    results, motion = tmp_path / "r.h5", tmp_path / "ik.mot"
    solved = run_cli("solve", IK_DIR / "subject01_simbody.osim",
                     IK_DIR / "subject01_synthetic_marker_data.trc", "--method", "nrm-wls",
                     "-o", results)
    assert solved.exit_code == 0, solved.stderr
    assert "numpy reference engine solves" not in solved.stderr
    exported = run_cli("export", results, "--format", "mot", "-o", motion)
    assert exported.exit_code == 0, exported.stderr
    lines = motion.read_text().splitlines()
    assert "inDegrees=yes" in lines
    end = lines.index("endheader")
    ours_names = lines[end + 1].split()
    ours = np.array([[float(v) for v in line.split()] for line in lines[end + 2:]])
    names, reference = opensim_solution()
    assert sorted(ours_names) == sorted(names)
    for k, name in enumerate(names[1:], start=1):
        difference = ours[:, ours_names.index(name)] - reference[:, k]
        limit = METRES if name in ("pelvis_tx", "pelvis_ty", "pelvis_tz") else DEGREES
        assert np.sqrt(np.mean(difference**2)) < limit, name


def test_methods_that_cannot_take_an_imported_model_say_so_and_write_nothing(tmp_path):
    from cli_helpers import run_cli

    results = tmp_path / "r.h5"
    refused = run_cli("solve", IK_DIR / "subject01_simbody.osim",
                      IK_DIR / "subject01_synthetic_marker_data.trc", "--method", "ad",
                      "-o", results)
    assert refused.exit_code == 2 and "Traceback" not in refused.output
    assert refused.stderr.splitlines()[-1].startswith("fccgrb: error: --method ad: ")
    assert not results.exists()

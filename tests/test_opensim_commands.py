"""OpenSim users' commands beside the ones its tools run: ``solve --coordinates`` (inverse
dynamics alone), ``solve --opensim-setup`` (an IK or ID setup run unchanged) and ``--from`` /
``--to`` (its time_range), with their bad inputs as one line each."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from fccgrb_cli.opensim.storage import read_storage, write_storage
from tests.cli_helpers import one_error_line, run_cli
from tests.osim_text import knee_model

ID_DIR = Path(__file__).resolve().parents[2] / "shared" / "data" / "opensim" / "id_gait2392"
shared = pytest.mark.skipif(not ID_DIR.is_dir(), reason="../shared/data/opensim not here")


@pytest.fixture
def knee(tmp_path: Path) -> tuple[Path, Path]:
    """A small imported model and a coordinates file of its every coordinate (degrees)."""
    model = tmp_path / "knee.osim"
    model.write_text(re.sub(r"<ForceSet>.*?</ForceSet>", "", knee_model(), flags=re.S))
    from fccgrb_cli.model import load_model

    names = [c.name for c in load_model(model).angles]
    time = np.arange(60) / 60.0
    values = np.column_stack([10.0 * np.sin(2 * np.pi * (k + 1) * 0.5 * time)
                              for k in range(len(names))])
    coordinates = tmp_path / "knee_ik.mot"
    write_storage(coordinates, names, time, values, in_degrees=True)
    return model, coordinates


def test_coordinates_alone_give_a_run_of_forces(knee, tmp_path):
    model, coordinates = knee
    results = tmp_path / "r.h5"
    done = run_cli("solve", model, "--coordinates", coordinates, "--from", "0.25", "--to",
                   "0.75", "-o", results)
    assert done.exit_code == 0, done.output
    assert "wrote run 'id'" in done.stdout
    table = tmp_path / "f.sto"
    assert run_cli("export", results, "--format", "sto", "-o", table).exit_code == 0
    forces = read_storage(table)
    assert forces.time[0] == pytest.approx(0.25) and forces.time[-1] == pytest.approx(0.75)
    assert all(name.endswith(("_moment", "_force")) for name in forces.names)
    # the same name again is refused before any work, the first run kept
    again = run_cli("solve", model, "--coordinates", coordinates, "-o", results)
    one_error_line(again, "already holds the run 'id'")


@pytest.mark.parametrize("case", ["trial beside", "yaml model", "no columns", "range outside",
                                  "to before from", "c3d window", "nothing"])
def test_bad_coordinates_commands_are_one_line(case, knee, tmp_path):
    model, coordinates = knee
    out = tmp_path / "r.h5"
    if case == "trial beside":
        done = run_cli("solve", model, "walk.trc", "--coordinates", coordinates, "-o", out)
        expected = ("--coordinates", "expected no trial")
    elif case == "yaml model":
        pendulum = Path(__file__).resolve().parents[1] / "configs" / "models" / "pendulum.yaml"
        done = run_cli("solve", pendulum, "--coordinates", coordinates, "-o", out)
        expected = ("--coordinates", "expected an OpenSim model")
    elif case == "no columns":
        other = tmp_path / "other.mot"
        write_storage(other, ["a", "b"], np.arange(10) / 10.0, np.zeros((10, 2)),
                      in_degrees=True)
        done = run_cli("solve", model, "--coordinates", other, "-o", out)
        expected = (str(other), "expected columns named after")
    elif case == "range outside":
        done = run_cli("solve", model, "--coordinates", coordinates, "--from", "5", "-o", out)
        expected = ("--from/--to", "0–0.983333 s")
    elif case == "to before from":
        done = run_cli("solve", model, "--coordinates", coordinates, "--from", "0.5", "--to",
                       "0.2", "-o", out)
        expected = ("--to", "at or after --from 0.5")
    elif case == "c3d window":
        c3d = tmp_path / "walk.c3d"
        c3d.write_bytes(b"")
        done = run_cli("solve", model, c3d, "--from", "0.5", "-o", out)
        expected = (str(c3d), "--from/--to", "expected a TRC trial or --coordinates")
    else:
        done = run_cli("solve", "-o", out)
        expected = ("expected MODEL",)
    one_error_line(done, *expected)
    assert not out.exists()


@shared
def test_an_id_setup_runs_unchanged(tmp_path):
    """OpenSim's own ID setup (model, coordinates, external loads, 6 Hz, time range 0.5–1.6 s,
    every file relative to the setup's folder) gives the run the same command typed out gives,
    over the setup's time range."""
    setup = ID_DIR / "subject01_Setup_InverseDynamics.xml"
    by_setup, typed = tmp_path / "setup.h5", tmp_path / "typed.h5"
    done = run_cli("solve", "--opensim-setup", setup, "-o", by_setup)
    assert done.exit_code == 0, done.output
    assert "output_gen_force_file" in done.stderr and "subject01_InverseDynamics.sto" in \
        done.stderr
    done = run_cli("solve", ID_DIR / "subject01.osim", "--coordinates",
                   ID_DIR / "subject01_walk1_ik.mot", "--loads",
                   ID_DIR / "subject01_walk1_grf.xml", "--filter-cutoff", "6", "--from", "0.5",
                   "--to", "1.6", "-o", typed)
    assert done.exit_code == 0, done.output
    tables = []
    for results in (by_setup, typed):
        table = results.with_suffix(".sto")
        assert run_cli("export", results, "--format", "sto", "-o", table).exit_code == 0
        tables.append(read_storage(table))
    a, b = tables
    assert a.names == b.names and np.array_equal(a.values, b.values)
    assert a.time[0] == pytest.approx(0.5) and a.time[-1] == pytest.approx(1.6, abs=1e-6)


IK_DIR = ID_DIR.parent / "ik_gait2354_synthetic"


@pytest.mark.skipif(not IK_DIR.is_dir(), reason="../shared/data/opensim not here")
def test_a_markers_window_is_the_trials_own_clock(tmp_path):
    """--from/--to on a TRC select the frames whose Time lies in the range (OpenSim's IK
    time_range), and the exports keep that clock; an IK setup's time range does the same."""
    results = tmp_path / "r.h5"
    done = run_cli("solve", IK_DIR / "subject01_simbody.osim",
                   IK_DIR / "subject01_synthetic_marker_data.trc", "--from", "0.5", "--to",
                   "0.75", "--no-dynamics", "-o", results)
    assert done.exit_code == 0, done.output
    motion = tmp_path / "r.mot"
    assert run_cli("export", results, "--format", "mot", "-o", motion).exit_code == 0
    rows = read_storage(motion).time
    assert rows[0] == pytest.approx(0.5) and rows[-1] == pytest.approx(0.75)
    assert len(rows) == 16  # 60 Hz: 0.5, 0.5167, …, 0.75


@pytest.mark.skipif(not IK_DIR.is_dir(), reason="../shared/data/opensim not here")
def test_an_ik_setups_accuracy_is_the_tolerance_unless_typed(tmp_path):
    """An IK setup's ``accuracy`` (OpenSim: the solution's absolute accuracy) is the solve's
    tolerance on ‖Δq‖∞; ``--tol`` typed beside the setup wins. A looser tolerance stops the
    frames earlier and moves the coordinates by the order of that tolerance (a bound on the
    last step, not on the error: Gauss–Newton converges linearly here; 4e-4 rad at 1e-4 on one
    hip frame, 4e-6 at OpenSim's 1e-5, RMS 20 times less)."""
    setup = tmp_path / "setup.xml"
    text = (IK_DIR / "subject01_Setup_InverseKinematics.xml").read_text()
    for name in ("subject01_simbody.osim", "gait2354_IK_Tasks_uniform.xml",
                 "subject01_synthetic_marker_data.trc"):
        text = text.replace(name, str(IK_DIR / name))
    setup.write_text(text.replace("<accuracy>1e-5</accuracy>", "<accuracy>1e-4</accuracy>"))
    runs = {}
    for label, typed in (("setup", ()), ("typed", ("--tol", "1e-10"))):
        results = tmp_path / f"{label}.h5"
        done = run_cli("solve", "--opensim-setup", setup, *typed, "--no-dynamics", "-o",
                       results)
        assert done.exit_code == 0, done.output
        from fccgrb_cli.api import read_results

        (run,) = read_results(results).values()
        runs[label] = run.result
    loose, strict = runs["setup"], runs["typed"]
    assert loose.tol == 1e-4 and strict.tol == 1e-10
    assert loose.converged.all() and strict.converged.all()
    assert loose.iterations.mean() < strict.iterations.mean() - 0.5
    moved = np.abs(loose.theta - strict.theta)
    assert 0 < moved.max() < 1e-3 and np.sqrt(np.mean(moved ** 2)) < 1e-4

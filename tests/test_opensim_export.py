"""`fccgrb export --format mot|sto` in OpenSim's storage layout, read back by
``opensim.storage.read_storage``: nRows, nColumns, inDegrees, the angles in degrees (distances
in metres) under the model's coordinate names, the generalized forces as
``<coordinate>_moment`` / ``<coordinate>_force``, time on the trial's clock; each number equal
to the run's own (converted independently here)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from cli_helpers import run_cli

import fccgrb_cli as fc
from fccgrb_cli.opensim.storage import read_storage

ROOT = Path(__file__).resolve().parents[1]
SLIDER = ROOT / "configs" / "models" / "slider.yaml"


@pytest.fixture(scope="module")
def solved(tmp_path_factory) -> tuple[Path, fc.Run]:
    """The slider (one distance, one angle) synthesized, solved with the dynamics."""
    folder = tmp_path_factory.mktemp("opensim_export")
    trial = folder / "slider.c3d"
    synth = run_cli("synth", SLIDER, "-o", trial, "--duration", "1.0", "--rate", "100")
    assert synth.exit_code == 0, synth.output
    results = folder / "slider.h5"
    solve = run_cli("solve", SLIDER, trial, "--dynamics", "-o", results)
    assert solve.exit_code == 0, solve.stderr
    (run,) = fc.read_results(results).values()
    return results, run


def test_mot_reads_back_in_degrees_and_metres(solved, tmp_path):
    results, run = solved
    target = tmp_path / "slider.mot"
    assert run_cli("export", results, "--format", "mot", "-o", target).exit_code == 0
    table = read_storage(target)
    names = run.result.angle_names
    assert table.names == names and table.in_degrees is True
    assert table.header["nRows"] == str(len(run.result.time))
    assert table.header["nColumns"] == str(1 + len(names))
    np.testing.assert_array_equal(table.time, run.result.time + run.start_time)
    units = {a.name: a.kind for a in run.model.angles}
    assert sorted(units.values()) == ["angle", "distance"]
    for k, name in enumerate(names):
        theta = run.result.theta[:, k]
        expected = theta if units[name] == "distance" else theta * 180.0 / np.pi
        np.testing.assert_allclose(table.values[:, k], expected, rtol=1e-15, atol=0)


def test_sto_reads_back_as_opensims_generalized_forces(solved, tmp_path):
    results, run = solved
    target = tmp_path / "slider.sto"
    assert run_cli("export", results, "--format", "sto", "-o", target).exit_code == 0
    table = read_storage(target)
    kinds = {a.name: a.kind for a in run.model.angles}
    expected = tuple(f"{n}_{'force' if kinds[n] == 'distance' else 'moment'}"
                     for n in run.result.angle_names)
    assert table.names == expected and table.in_degrees is False
    assert any(n.endswith("_force") for n in expected) and any(n.endswith("_moment")
                                                               for n in expected)
    np.testing.assert_array_equal(table.values, run.dynamics.inverse.joint_moments)
    assert table.header["untrustedFrames"] == str(int((~run.trusted).sum()))

"""Units and scaling of the clinical curves in every export format.

The pendulum (``configs/models/pendulum.yaml``) with clinical signs written into it (+1, −1, −1,
+1) and a subject of 62.5 kg: each format must hold, for every frame, the clinical angle
sign·(θ − 90°) in degrees and the clinical moment sign·τ in N·m — not N·m/kg, not radians, not
unsigned — computed here from the run's θ (rad), its joint moments τ (N·m) and the signs and mass
read back from the YAML, and label them so. The C3D's outputs are points (value in X, as Nexus
and Visual3D store them) read with ezc3d itself.
"""

from __future__ import annotations

from pathlib import Path

import ezc3d
import numpy as np
import pytest
import yaml
from cli_helpers import run_cli
from test_export import read_storage

import fccgrb_cli as fc

ROOT = Path(__file__).resolve().parents[1]
SIGNS = {"shoulder_x": 1, "shoulder_y": -1, "elbow_x": -1, "elbow_y": 1}
MASS = 62.5


@pytest.fixture(scope="module")
def solved(tmp_path_factory) -> tuple[Path, fc.Run, np.ndarray, np.ndarray]:
    folder = tmp_path_factory.mktemp("units")
    doc = yaml.safe_load((ROOT / "configs" / "models" / "pendulum.yaml").read_text("utf-8"))
    for angle in doc["angles"]:
        angle["clinical"] = {"sign": SIGNS[angle["name"]]}
    doc["subject"] = {"mass": MASS}
    model = folder / "pendulum.yaml"
    model.write_text(yaml.safe_dump(doc), encoding="utf-8")
    trial = folder / "pendulum.c3d"
    assert run_cli("synth", model, "-o", trial, "--duration", "1").exit_code == 0
    results = folder / "r.h5"
    assert run_cli("solve", model, trial, "-o", results).exit_code == 0
    run = next(iter(fc.read_results(results).values()))
    written = yaml.safe_load(model.read_text("utf-8"))
    signs = np.array([a["clinical"]["sign"] for a in written["angles"]], dtype=float)
    degrees = signs * (np.degrees(run.result.theta) - 90.0)
    newton_metres = signs * run.dynamics.inverse.joint_moments
    assert written["subject"]["mass"] == MASS
    # a scaling error would show: the moments are tens of N·m, not 1/62.5 of it
    assert np.abs(newton_metres).max() > 1.0
    return results, run, degrees, newton_metres


def _export(results: Path, fmt: str, target: Path) -> Path:
    result = run_cli("export", results, "--format", fmt, "-o", target)
    assert result.exit_code == 0, result.output
    return target


def test_mot_degrees(solved, tmp_path: Path):
    results, _, degrees, _ = solved
    header, labels, rows = read_storage(_export(results, "mot", tmp_path / "a.mot"))
    assert header["inDegrees"] == "yes" and header["units"] == "deg"
    assert labels == ["time", *SIGNS]
    np.testing.assert_allclose(rows[:, 1:], degrees, rtol=1e-9, atol=1e-9)


def test_sto_newton_metres(solved, tmp_path: Path):
    results, _, _, newton_metres = solved
    header, labels, rows = read_storage(_export(results, "sto", tmp_path / "m.sto"))
    assert header["inDegrees"] == "no" and header["units"] == "N·m"
    assert labels == ["time", *(f"{n}_moment" for n in SIGNS)]
    np.testing.assert_allclose(rows[:, 1:], newton_metres, rtol=1e-9, atol=1e-9)


def test_csv_degrees_and_newton_metres(solved, tmp_path: Path):
    results, _, degrees, newton_metres = solved
    lines = _export(results, "csv", tmp_path / "t.csv").read_text("utf-8").splitlines()
    header = lines[0].split(",")
    values = [*(f"{n} [deg]" for n in SIGNS), *(f"{n}_moment [N·m]" for n in SIGNS)]
    sd = [v.replace(" [", " sd [") for v in values]  # the smoother's, when it ran
    assert header[:3] == ["trial time [s]", "trusted", "moments trusted"]
    assert header[3:] in (values, values + sd)
    rows = np.array([[float(v) for v in line.split(",")[3:]] for line in lines[1:]])
    np.testing.assert_allclose(rows[:, :4], degrees, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(rows[:, 4:8], newton_metres, rtol=1e-9, atol=1e-9)


def test_c3d_points_degrees_and_newton_metres(solved, tmp_path: Path):
    results, _, degrees, newton_metres = solved
    c3d = ezc3d.c3d(str(_export(results, "c3d", tmp_path / "out.c3d")))
    point = c3d["parameters"]["POINT"]
    assert list(point["ANGLE_UNITS"]["value"]) == ["deg"]
    assert list(point["MOMENT_UNITS"]["value"]) == ["N.m"]
    labels = [label.strip() for label in point["LABELS"]["value"]]
    xyz = c3d["data"]["points"][:3]
    for names, expected in ((point["ANGLES"]["value"], degrees),
                            (point["MOMENTS"]["value"], newton_metres)):
        columns = [labels.index(name.strip()) for name in names]
        np.testing.assert_allclose(xyz[0, columns].T, expected, rtol=1e-6, atol=1e-4)
        assert not np.abs(xyz[1:, columns]).any()  # Y and Z zero


def test_per_kg_is_the_results_file_and_report_view_only(solved):
    """N·m/kg is the clinical view (run.clinical_moments, the summary): the exports above are
    N·m, and the per-kg values are those over the YAML's mass."""
    _, run, _, newton_metres = solved
    per_kg = run.clinical_moments
    assert per_kg.units == ("N·m/kg",) * 4
    np.testing.assert_allclose(per_kg.values, newton_metres / MASS, rtol=1e-12)

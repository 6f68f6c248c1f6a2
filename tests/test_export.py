"""`fccgrb export`: OpenSim .mot/.sto, tidy CSV and C3D files that other tools read, holding the
run's numbers (checked against the run's own arrays, in the units each format declares) and
marking the frames the quality checks do not trust."""

from __future__ import annotations

from pathlib import Path

import ezc3d
import numpy as np
import pytest
from cli_helpers import one_error_line, run_cli

import fccgrb_cli as fc

ROOT = Path(__file__).resolve().parents[1]
MODEL = ROOT / "configs" / "models" / "five_bar.yaml"
TRIAL = ROOT / "sample_data" / "five_bar.c3d"
GAIT = ROOT.parent / "shared" / "data" / "c3d" / "Qualisys.c3d"


def read_storage(path: Path) -> tuple[dict[str, str], list[str], np.ndarray]:
    """An OpenSim Storage file as OpenSim reads it: the first line is the name, key=value lines
    up to ``endheader``, then the column labels (tab-separated) and nRows rows of nColumns."""
    lines = path.read_text(encoding="utf-8").splitlines()
    end = lines.index("endheader")
    header = dict(line.split("=", 1) for line in lines[1:end] if "=" in line)
    labels = lines[end + 1].split("\t")
    rows = np.array([[float(v) for v in line.split("\t")] for line in lines[end + 2:]])
    assert int(header["nRows"]) == len(rows)
    assert int(header["nColumns"]) == len(labels) == rows.shape[1]
    return header, labels, rows


@pytest.fixture(scope="module")
def five_bar(tmp_path_factory) -> tuple[Path, fc.Run]:
    out = tmp_path_factory.mktemp("export") / "five_bar.h5"
    run = fc.solve(fc.load_model(MODEL), fc.read_trial(TRIAL), perturb_mm=7.5, seed=2)
    fc.write_results(run, out)
    return out, run


def test_mot_holds_the_angles_in_degrees(five_bar, tmp_path: Path):
    results, run = five_bar
    target = tmp_path / "angles.mot"
    assert run_cli("export", results, "--format", "mot", "-o", target).exit_code == 0
    header, labels, rows = read_storage(target)
    assert header["inDegrees"] == "yes" and header["untrustedFrames"] == "0"
    assert labels == ["time", *run.result.angle_names]
    np.testing.assert_allclose(rows[:, 0], run.result.time, atol=1e-12)
    np.testing.assert_allclose(np.radians(rows[:, 1:]), run.result.theta, rtol=1e-9)
    assert 50 < rows[:, 1:].max() < 180  # degrees, not radians


def test_sto_holds_the_moments_as_opensim_names_them(five_bar, tmp_path: Path):
    results, run = five_bar
    target = tmp_path / "moments.sto"
    assert run_cli("export", results, "--format", "sto", "-o", target).exit_code == 0
    header, labels, rows = read_storage(target)
    assert header["inDegrees"] == "no"
    assert labels == ["time", *(f"{n}_moment" for n in run.result.angle_names)]
    np.testing.assert_allclose(rows[:, 1:], run.dynamics.inverse.joint_moments, rtol=1e-9,
                               atol=1e-9)


def test_csv_reads_in_one_pandas_call_with_units_in_the_header(five_bar, tmp_path: Path):
    pd = pytest.importorskip("pandas")
    results, run = five_bar
    target = tmp_path / "run.csv"
    assert run_cli("export", results, "--format", "csv", "-o", target).exit_code == 0
    table = pd.read_csv(target)
    assert list(table.columns[:4]) == ["trial time [s]", "trusted", "moments trusted",
                                      "J1_z [deg]"]
    assert table["trusted"].dtype == bool and table["trusted"].all()
    assert len(table) == len(run.result.time)
    np.testing.assert_allclose(np.radians(table["J3_w [deg]"]), run.angles["J3_w"], rtol=1e-9)
    np.testing.assert_allclose(table["J3_w_moment [N·m]"], run.moments["J3_w"], rtol=1e-9,
                               atol=1e-9)


def test_c3d_keeps_the_trial_and_adds_angles_and_moments_as_points(five_bar, tmp_path: Path):
    results, run = five_bar
    target = tmp_path / "out.c3d"
    assert run_cli("export", results, "--format", "c3d", "-o", target).exit_code == 0
    original, out = ezc3d.c3d(str(TRIAL)), ezc3d.c3d(str(target))
    labels = list(out["parameters"]["POINT"]["LABELS"]["value"])
    n_markers = original["data"]["points"].shape[1]
    assert labels[:n_markers] == list(original["parameters"]["POINT"]["LABELS"]["value"])
    np.testing.assert_array_equal(out["data"]["points"][:3, :n_markers],
                                  original["data"]["points"][:3])
    params = out["parameters"]["POINT"]
    assert list(params["ANGLES"]["value"]) == list(run.result.angle_names)
    assert list(params["ANGLE_UNITS"]["value"]) == ["deg"]
    assert list(params["MOMENT_UNITS"]["value"]) == ["N.m"]
    k = labels.index("J3_w")
    np.testing.assert_allclose(np.radians(out["data"]["points"][0, k]), run.angles["J3_w"],
                               rtol=1e-6)
    np.testing.assert_array_equal(out["data"]["points"][1:3, k], 0.0)
    m = labels.index("J3_w_moment")
    np.testing.assert_allclose(out["data"]["points"][0, m], run.moments["J3_w"], rtol=1e-5,
                               atol=1e-5)


@pytest.mark.skipif(not GAIT.exists(), reason=f"{GAIT} is absent (a user's clone)")
def test_gait_c3d_keeps_analogs_events_and_plates_and_adds_clinical_curves(tmp_path: Path):
    trial = fc.read_trial(GAIT)
    model = fc.calibrate(fc.load_model(ROOT / "configs" / "models" / "lower_limb.yaml"), trial,
                         mass=67)
    results = tmp_path / "gait.h5"
    fc.write_results(fc.solve(model, trial, filter_cutoff=6), results)
    target = tmp_path / "gait.c3d"
    assert run_cli("export", results, "--format", "c3d", "-o", target).exit_code == 0
    original, out = ezc3d.c3d(str(GAIT)), ezc3d.c3d(str(target))
    np.testing.assert_array_equal(out["data"]["analogs"], original["data"]["analogs"])
    for group, key in (("EVENT", "LABELS"), ("EVENT", "USED"), ("EVENT", "TIMES"),
                       ("FORCE_PLATFORM", "CORNERS"), ("FORCE_PLATFORM", "CHANNEL")):
        np.testing.assert_array_equal(np.asarray(out["parameters"][group][key]["value"]),
                                      np.asarray(original["parameters"][group][key]["value"]))
    angles = list(out["parameters"]["POINT"]["ANGLES"]["value"])
    assert "knee_flexion_r" in angles and "ankle_dorsiflexion_l" in angles
    assert "knee_flexion_r_moment" in list(out["parameters"]["POINT"]["MOMENTS"]["value"])


def test_untrusted_frames_are_exported_marked_and_counted(tmp_path: Path):
    """Goal attainment at 30 mm jumps between per-frame optima: every frame is flagged, and the
    exports say so instead of passing the numbers on as good."""
    results = tmp_path / "mo.h5"
    run = fc.solve(fc.load_model(MODEL), fc.read_trial(TRIAL), method="mo-ed", perturb_mm=30,
                   dynamics=False)
    fc.write_results(run, results)
    result = run_cli("export", results, "--format", "mot", "-o", tmp_path / "mo.mot")
    assert result.exit_code == 0
    assert "300 of 300 frames" in result.stderr and "not trusted" in result.stderr
    header, _, _ = read_storage(tmp_path / "mo.mot")
    assert header["untrustedFrames"] == "300"
    run_cli("export", results, "--format", "csv", "-o", tmp_path / "mo.csv")
    trusted = [line.split(",")[1] for line in
               (tmp_path / "mo.csv").read_text(encoding="utf-8").splitlines()[1:]]
    assert set(trusted) == {"false"}


def test_export_refuses_what_it_cannot_write(five_bar, tmp_path: Path):
    results, _ = five_bar
    kinematic = tmp_path / "kin.h5"
    model, trial = fc.load_model(MODEL), fc.read_trial(TRIAL)
    fc.write_results(fc.solve(model, trial, dynamics=False, name="a"), kinematic)
    one_error_line(run_cli("export", kinematic, "--format", "sto", "-o", tmp_path / "x.sto"),
                   "no joint moments")
    fc.write_results(fc.solve(model, trial, dynamics=False, name="b"), kinematic)
    one_error_line(run_cli("export", kinematic, "--format", "mot"), "expected --run NAME")
    one_error_line(run_cli("export", kinematic, "--format", "mot", "--run", "c"),
                   "no run 'c'", "a, b")
    one_error_line(run_cli("export", results, "--format", "csv", "-o", results),
                   "inputs are never modified")
    assert run_cli("export", kinematic, "--format", "mot", "--run", "b").exit_code == 0
    assert (tmp_path / "kin.b.mot").exists()


def test_opensim_reads_the_mot_and_sto_files(five_bar, tmp_path: Path):
    """OpenSim 4's own readers (runs where the `opensim` package is installed)."""
    osim = pytest.importorskip("opensim")
    results, run = five_bar
    mot, sto = tmp_path / "a.mot", tmp_path / "m.sto"
    run_cli("export", results, "--format", "mot", "-o", mot)
    run_cli("export", results, "--format", "sto", "-o", sto)
    table = osim.TimeSeriesTable(str(mot))
    assert table.getNumRows() == len(run.result.time)
    assert list(table.getColumnLabels()) == list(run.result.angle_names)
    assert table.getTableMetaDataAsString("inDegrees") == "yes"
    last = table.getRowAtIndex(table.getNumRows() - 1).to_numpy()
    np.testing.assert_allclose(np.radians(last), run.result.theta[-1], rtol=1e-9)
    storage = osim.Storage(str(sto))
    assert storage.getSize() == len(run.result.time) and not storage.isInDegrees()
    assert storage.getColumnLabels().getSize() == 1 + len(run.result.angle_names)

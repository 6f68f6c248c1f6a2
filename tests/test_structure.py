"""Rank analysis, redundant constraints, and the five-bar trial written by ``fccgrb synth``.

A revolute joint is written twice over (a ``parallel`` joint repeating its axis rows): the model
check must count the redundant equations, and the AD analysis (least squares with minimum norm on
the redundant system) must give the same motion as the non-redundant model.
"""

from __future__ import annotations

from pathlib import Path

import ezc3d
import numpy as np
import pytest
from click.testing import CliRunner

from fccgrb_cli.cli.main import main
from fccgrb_cli.model import load_model, parse_model
from fccgrb_cli.pipeline.synth import synthesize
from fccgrb_cli.system.structure import analyse

ROOT = Path(__file__).resolve().parents[1]
FIVE_BAR = ROOT / "configs" / "models" / "five_bar.yaml"


def redundant_five_bar() -> str:
    text = FIVE_BAR.read_text()
    extra = "  - {name: J1_again, type: parallel, bodies: [ground, B1], axes: [z, w]}\n"
    return text.replace("\nangles:\n", "\n" + extra + "\nangles:\n")


@pytest.mark.parametrize("form", ["full", "reduced"])
def test_non_redundant_models_report_full_rank(form: str) -> None:
    for name in ("pendulum", "five_bar"):
        model = load_model(ROOT / "configs" / "models" / f"{name}.yaml").with_form(form)
        report = analyse(model)
        assert report.ad_rank == report.nq
        assert report.mc_rank == report.nq_mixed
        assert report.redundant == ()
        assert report.dof == report.n_angles == len(model.angles)


@pytest.mark.parametrize("form", ["full", "reduced"])
def test_redundant_rows_are_reported_and_ad_stays_exact(form: str) -> None:
    plain = load_model(FIVE_BAR).with_form(form)
    doubled = parse_model(redundant_five_bar(), "redundant.yaml").with_form(form)
    report = analyse(doubled)
    assert len(report.redundant) == 2
    assert report.ad_rank == report.nq
    assert report.dof == 9
    a = synthesize(plain, duration=0.5)
    b = synthesize(doubled, duration=0.5)
    assert b.result.converged.all()
    assert np.abs(a.markers - b.markers).max() < 1e-12
    assert np.abs(a.result.qd - b.result.qd).max() < 1e-9
    assert np.abs(a.result.qdd - b.result.qdd).max() < 1e-8


def test_check_prints_the_redundant_equations(tmp_path: Path) -> None:
    path = tmp_path / "redundant.yaml"
    path.write_text(redundant_five_bar())
    result = CliRunner().invoke(main, ["check", str(path)])
    assert result.exit_code == 0, result.output
    assert "redundant equations (2)" in result.output
    assert "rank 60 of 60" in result.output


@pytest.mark.parametrize("units, scale", [("mm", 1e-3), ("m", 1.0)])
def test_five_bar_synth_writes_300_frames_at_100_hz(tmp_path: Path, units: str,
                                                     scale: float) -> None:
    out = tmp_path / "x.c3d"
    result = CliRunner().invoke(main, ["synth", str(FIVE_BAR), "-o", str(out),
                                       "--units", units])
    assert result.exit_code == 0, result.output
    c3d = ezc3d.c3d(str(out))
    point = c3d["parameters"]["POINT"]
    assert point["UNITS"]["value"][0] == units
    assert point["RATE"]["value"][0] == 100.0
    labels = [label.strip() for label in point["LABELS"]["value"]]
    assert labels == [f"P{k}" for k in range(1, 10)]
    xyz = np.transpose(c3d["data"]["points"][:3], (2, 1, 0)) * scale
    assert xyz.shape == (300, 9, 3)
    exact = synthesize(load_model(FIVE_BAR)).markers
    assert np.abs(xyz - exact).max() < 1e-6
    # P1 sits on the ground revolute's axis: it never moves
    assert np.abs(xyz[:, 0] - xyz[0, 0]).max() < 1e-6


@pytest.mark.parametrize("name", ["pendulum", "five_bar"])
def test_bundled_sample_trials_match_their_models(name: str) -> None:
    """sample_data/ must be regenerated whenever a model changes: the truth file carries the
    model text it was made from, and the C3D's markers are the model's (to 32-bit precision)."""
    import h5py

    from fccgrb_cli.trial.record import read_trial

    model_path = ROOT / "configs" / "models" / f"{name}.yaml"
    trial = ROOT / "sample_data" / f"{name}.c3d"
    with h5py.File(trial.with_name(f"{name}.truth.h5"), "r") as h5:
        assert h5.attrs["model"] == model_path.read_text(), \
            f"regenerate: fccgrb synth {model_path.relative_to(ROOT)} -o sample_data/{name}.c3d"
    exact = synthesize(load_model(model_path)).markers
    assert np.abs(read_trial(trial).markers - exact).max() < 1e-6


def test_optimizer_runs_keep_every_frame_status(tmp_path: Path) -> None:
    """/runs/<name>/status: the optimizer's own message for every frame (none for NRM); and the
    runs whose status says success did succeed: on the unperturbed trial both recover the
    closed-form angles of the YAML (tests/five_bar_minimal.py) within 1e-5 rad (the C3D's 32-bit
    millimetres move them by ~1e-6) and every model point lies within 1e-3 mm of its marker."""
    import h5py
    from five_bar_minimal import closed_form

    trial, out = tmp_path / "x.c3d", tmp_path / "r.h5"
    runner = CliRunner()
    assert runner.invoke(main, ["synth", str(FIVE_BAR), "-o", str(trial),
                                "--duration", "0.1"]).exit_code == 0
    for method in ("cno-sqp", "nrm-wls"):
        result = runner.invoke(main, ["solve", str(FIVE_BAR), str(trial), "--method", method,
                                      "-o", str(out), "--no-dynamics"])
        assert result.exit_code == 0, result.output
    with h5py.File(out, "r") as h5:
        status = [s.decode() for s in h5["runs/cno-sqp/status"][()]]
        assert len(status) == 10 and all("success" in s for s in status)
        assert "status" not in h5["runs/nrm-wls"]
        truth = closed_form(np.arange(10) / 100.0)
        for run in ("cno-sqp", "nrm-wls"):
            g = h5[f"runs/{run}"]
            assert g["converged"][()].all(), run
            assert np.abs(g["theta"][()] - truth).max() < 1e-5, run
            assert 1e3 * g["ed"][()].max() < 1e-3, run


def test_reverse_cuthill_mckee_is_scipys_order(monkeypatch):
    """The factor's order (system/sparse.py writes the ordering out instead of importing
    scipy.sparse) against scipy.sparse.csgraph.reverse_cuthill_mckee: random symmetric patterns
    with and without diagonals, disconnected parts, ties; and every template's normal matrix,
    mixed and classical."""
    from scipy.sparse import csr_matrix
    from scipy.sparse.csgraph import reverse_cuthill_mckee

    from fccgrb_cli.system import compile_system, sparse
    from fccgrb_cli.system.sparse import _reverse_cuthill_mckee

    def scipys(graph):
        return np.asarray(reverse_cuthill_mckee(csr_matrix(graph), symmetric_mode=True))

    rng = np.random.default_rng(5)
    for _ in range(400):
        n = int(rng.integers(1, 50))
        graph = rng.random((n, n)) < rng.uniform(0.0, 0.3)
        graph |= graph.T
        np.fill_diagonal(graph, rng.random(n) < rng.choice([0.0, 0.5, 1.0]))
        assert np.array_equal(_reverse_cuthill_mckee(graph), scipys(graph))
    graphs = []
    monkeypatch.setattr(sparse, "_reverse_cuthill_mckee",
                        lambda graph: graphs.append(graph) or _reverse_cuthill_mckee(graph))
    for path in sorted((ROOT / "configs" / "models").glob("*.yaml")):
        model = load_model(path)
        for system in (compile_system(model, angles="coordinate", track=True),
                       compile_system(model, angles="driver")):
            if sparse.compilable(system):
                sparse.sparse_system(system)
    assert len(graphs) > 10
    for graph in graphs:
        assert np.array_equal(_reverse_cuthill_mckee(graph), scipys(graph))

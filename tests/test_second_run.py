"""A second run never loses the first: a solve into a results file that already holds a run of
the same name is refused (one error line naming the file, the run and the command that made it;
the file untouched) unless ``--replace``; default run names carry what changes the answer
(filter, smoothing, perturbation); ``report`` shows every run as its own row, labelled with
what made it.

Independent references: the names are written out here by hand; each report row's mean
Euclidean distance is recomputed here from the run's own stored distances.
"""

from __future__ import annotations

import csv
import io
from pathlib import Path

import h5py
import numpy as np
import pytest
from cli_helpers import one_error_line, run_cli

from fccgrb_cli.pipeline.options import SolveOptions
from fccgrb_cli.pipeline.solve import _smoothing, run_name

ROOT = Path(__file__).resolve().parents[1]
MODEL = ROOT / "configs" / "models" / "five_bar.yaml"
TRIAL = ROOT / "sample_data" / "five_bar.c3d"


@pytest.mark.parametrize("changes,expected", [
    ({}, "nrm-wls"),
    ({"smooth": "auto"}, "nrm-wls-smooth"),
    ({"smooth": "auto", "smooth_cutoff": 6.0}, "nrm-wls-smooth6Hz"),
    ({"smooth": "auto", "smooth_noise": 0.5}, "nrm-wls-smooth-n0.5mm"),
    ({"filter_cutoff": 6.0}, "nrm-wls-f6Hz"),
    ({"filter_cutoff": 6.0, "perturb_mm": 30.0}, "nrm-wls-f6Hz-P30"),
])
def test_default_names_carry_what_changes_the_answer(changes, expected):
    options = SolveOptions.from_mapping({"method": "nrm-wls", **changes})
    got = run_name("nrm-wls", options.ad_drivers, options.filter_cutoff,
                   options.perturb_level_m, options.perturb_markers, _smoothing(options))
    assert got == expected


def runs_in(path: Path) -> dict[str, str]:
    with h5py.File(path, "r") as h5:
        return {name: str(run.attrs["command"]) for name, run in h5["runs"].items()}


def test_a_second_solve_under_one_name_is_refused_unless_replace(tmp_path):
    results = tmp_path / "r.h5"
    first = run_cli("solve", MODEL, TRIAL, "-o", results, "--method", "ad")
    assert first.exit_code == 0, first.stderr
    before = results.read_bytes()
    one_error_line(run_cli("solve", MODEL, TRIAL, "-o", results, "--method", "ad", "--tol",
                           "1e-9"), f"{results}: already holds the run 'ad'",
                   f"(made by: {runs_in(results)['ad']})", "--replace")
    assert results.read_bytes() == before
    one_error_line(run_cli("solve", MODEL, TRIAL, "-o", results, "--name", "ad"),
                   "already holds the run 'ad'")
    assert results.read_bytes() == before
    again = run_cli("solve", MODEL, TRIAL, "-o", results, "--method", "ad", "--tol", "1e-9",
                    "--replace")
    assert again.exit_code == 0, again.stderr
    with h5py.File(results, "r") as h5:
        assert list(h5["runs"]) == ["ad"] and h5["runs/ad"].attrs["tol"] == 1e-9


def test_report_shows_every_run_as_its_own_row(tmp_path):
    """AD, AD 6 Hz and an AD run under another name: three rows, each labelled with what made
    it and holding its own run's figures."""
    results = tmp_path / "r.h5"
    for extra in ([], ["--filter-cutoff", "6"], ["--name", "again"]):
        out = run_cli("solve", MODEL, TRIAL, "-o", results, "--method", "ad", *extra)
        assert out.exit_code == 0, out.stderr
    assert set(runs_in(results)) == {"ad", "ad-f6Hz", "again"}
    out = run_cli("report", results, "--format", "csv")
    assert out.exit_code == 0, out.stderr
    rows = [r for r in csv.DictReader(io.StringIO(out.stdout)) if r["metric"] == "mean ED (mm)"]
    by_variant = {r["variant"]: float(r["ours"]) for r in rows}
    assert set(by_variant) == {"AD [ad]", "AD [filter_cutoff=6 Hz]", "AD [again]"}
    with h5py.File(results, "r") as h5:
        for name, variant in (("ad", "AD [ad]"), ("ad-f6Hz", "AD [filter_cutoff=6 Hz]")):
            ed = h5[f"runs/{name}/ed"][()]
            assert by_variant[variant] == pytest.approx(1e3 * np.mean(ed), rel=1e-5)
    assert by_variant["AD [filter_cutoff=6 Hz]"] > 100 * by_variant["AD [ad]"]


def test_the_write_itself_refuses_a_taken_name(tmp_path):
    """The check under the results file's lock (where two solves racing for one name meet)."""
    import fccgrb_cli as fc
    from fccgrb_cli.core.errors import InputError
    from fccgrb_cli.results.storage import write_runs

    run = fc.solve(fc.load_model(MODEL), fc.read_trial(TRIAL), method="ad")
    results = tmp_path / "r.h5"
    write_runs(results, [run], "first")
    before = results.read_bytes()
    with pytest.raises(InputError, match="already holds the run 'ad' \\(made by: first\\)"):
        write_runs(results, [run], "second", replace=False)
    assert results.read_bytes() == before
    write_runs(results, [run], "third", replace=True)
    assert runs_in(results) == {"ad": "third"}


@pytest.mark.parametrize("changes,expected", [
    ({"method": "nrm-ls"}, "nrm-ls"),
    ({"method": "cno-sqp", "objective": "ed"}, "cno-sqp-ed"),
    ({"method": "cno-ip"}, "cno-ip"),
    ({"method": "mo-ed", "filter_cutoff": 6.0}, "mo-ed-f6Hz"),
    ({"method": "cno-sqp", "parallel": True, "workers": 1, "parallel_init": "same"},
     "cno-sqp-parallel"),
    ({"method": "nrm-wls", "perturb_mm": 7.5, "seed": 3}, "nrm-wls-P7.5"),
])
def test_the_name_known_before_the_solve_is_the_runs(changes, expected):
    """``expected_run_name`` (what the CLI checks the results file for before any work) is the
    name the solved run carries, for the methods whose solver labels itself."""
    from fccgrb_cli.model import load_model
    from fccgrb_cli.pipeline.solve import expected_run_name, solve_trial
    from fccgrb_cli.trial.record import read_trial

    options = SolveOptions.from_mapping({"events": "none", **changes})
    assert expected_run_name(options) == expected
    trial = read_trial(TRIAL)
    short = type(trial)(trial.path, trial.labels, trial.markers[:12], trial.rate)
    run = solve_trial(load_model(MODEL), short, options)
    assert run.name == expected and run.result.method == expected.split("-f")[0].split("-P")[0]


def test_a_second_solve_is_refused_before_any_work(tmp_path, monkeypatch):
    results = tmp_path / "r.h5"
    assert run_cli("solve", MODEL, TRIAL, "-o", results).exit_code == 0
    before = results.read_bytes()

    def no_work(*args, **kwargs):
        raise AssertionError("solved before refusing")

    monkeypatch.setattr("fccgrb_cli.pipeline.solve.solve_trial", no_work)
    one_error_line(run_cli("solve", MODEL, TRIAL, "-o", results), "already holds the run")
    assert results.read_bytes() == before

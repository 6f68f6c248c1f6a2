"""The Python API: the docs' examples run, the CLI, a sweep and the API give the same bits for the
same options, and the options object refuses what it cannot mean."""

from __future__ import annotations

import doctest
import os
import re
from pathlib import Path

import h5py
import numpy as np
import pytest
from cli_helpers import run_cli

import fccgrb_cli as fc
from fccgrb_cli.core.errors import InputError
from fccgrb_cli.pipeline.options import SWEEP_KEYS, SolveOptions, describe

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared" / "data" / "c3d"
MODEL = ROOT / "configs" / "models" / "five_bar.yaml"
TRIAL = ROOT / "sample_data" / "five_bar.c3d"


def _sections(text: str) -> list[tuple[str, str]]:
    """The docs split at their second-level headings: (heading, body)."""
    parts = re.split(r"^## (.+)$", text, flags=re.MULTILINE)
    return list(zip(parts[1::2], parts[2::2], strict=True))


@pytest.fixture()
def in_project_copy(tmp_path: Path):
    """A folder that looks like the project's (configs/, sample_data/, ../shared) so that the
    docs' relative paths work and what they write lands in a temporary folder."""
    work = tmp_path / "project"
    work.mkdir()
    for name in ("configs", "sample_data"):
        (work / name).symlink_to(ROOT / name)
    if SHARED.exists():
        (tmp_path / "shared").symlink_to(ROOT.parent / "shared")
    before = Path.cwd()
    os.chdir(work)
    yield work
    os.chdir(before)


@pytest.mark.parametrize("section", [name for name, _ in _sections(
    (ROOT / "docs" / "api.md").read_text(encoding="utf-8"))])
def test_docs_api_examples_run_as_written(section: str, in_project_copy: Path):
    body = dict(_sections((ROOT / "docs" / "api.md").read_text(encoding="utf-8")))[section]
    if "../shared" in body and not SHARED.exists():
        pytest.skip(f"{SHARED} is absent (a user's clone)")
    parser = doctest.DocTestParser()
    test = parser.get_doctest(body, {}, f"docs/api.md: {section}", "docs/api.md", 0)
    assert test.examples, f"docs/api.md section {section!r} has no examples"
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS)
    report: list[str] = []
    runner.run(test, out=report.append)
    assert runner.failures == 0, "".join(report)


def _datasets(group: h5py.Group) -> dict[str, np.ndarray]:
    out: dict[str, np.ndarray] = {}
    group.visititems(lambda name, item: out.__setitem__(name, item[()])
                     if isinstance(item, h5py.Dataset) else None)
    return out


def fccgrb_ok(*args: object) -> None:
    result = run_cli(*args)
    assert result.exit_code == 0 and result.exception is None, \
        f"{result.exception!r}\n{result.stderr}"


TIMING = {"time_s"}  # wall-clock seconds per frame: the only arrays allowed to differ


def test_cli_sweep_and_api_give_identical_arrays(tmp_path: Path):
    """One trial solved three ways with the same options: every array of the three results
    files is equal bit for bit (except the per-frame wall-clock time)."""
    options = {"method": "nrm-wls", "perturb_mm": 7.5, "seed": 1, "filter_cutoff": 6.0,
               "dynamics": True, "name": "run"}
    by_cli = tmp_path / "cli.h5"
    fccgrb_ok("solve", MODEL, TRIAL, "--method", "nrm-wls", "--perturb", "7.5", "--seed", "1",
              "--filter-cutoff", "6", "--dynamics", "--name", "run", "-o", by_cli)

    config = tmp_path / "one.yaml"
    config.write_text(
        f"name: one\ntable: table2\nmodel: {MODEL}\ntrial: {{file: {TRIAL}}}\n"
        "cells:\n  - {method: nrm-wls, tol: 1.0e-10, level: 7.5, seed: 1, filter_cutoff: 6,"
        " dynamics: true}\n", encoding="utf-8")
    by_sweep = tmp_path / "sweep.h5"
    fccgrb_ok("sweep", config, "-o", by_sweep)

    by_api = tmp_path / "api.h5"
    fc.write_results(fc.solve(fc.load_model(MODEL), fc.read_trial(TRIAL), **options), by_api)

    with h5py.File(by_cli) as a, h5py.File(by_sweep) as b, h5py.File(by_api) as c:
        (cell,) = b["cells"].values()
        groups = {"cli": a["runs/run"], "sweep": cell["runs/run"], "api": c["runs/run"]}
        arrays = {how: _datasets(g) for how, g in groups.items()}
        options_json = {how: g.attrs["options"] for how, g in groups.items()}
    names = set(arrays["cli"])
    assert names == set(arrays["sweep"]) == set(arrays["api"])
    assert {"q", "theta", "joint_moments"} <= {n.split("/")[-1] for n in names}
    compared = 0
    for name in sorted(names):
        if name.split("/")[-1] in TIMING:
            continue
        for how in ("sweep", "api"):
            assert np.array_equal(arrays["cli"][name], arrays[how][name], equal_nan=True) \
                if arrays["cli"][name].dtype.kind == "f" else \
                np.array_equal(arrays["cli"][name], arrays[how][name]), f"{how}: {name}"
        compared += 1
    assert compared > 20
    chosen = {how: SolveOptions.from_json(text) for how, text in options_json.items()}
    assert chosen["cli"] == chosen["sweep"] == chosen["api"] == SolveOptions(**options)


def test_help_of_solve_explains_every_option_with_its_unit():
    text = fc.solve.__doc__
    for name, field in SolveOptions.__dataclass_fields__.items():
        assert f"\n    {name}" in text, name
        if field.metadata["unit"]:
            assert f"{name} [{field.metadata['unit']}]" in text
    assert "perturb_mm [mm]" in describe() and "filter_cutoff [Hz]" in describe()


def test_every_option_is_a_cli_flag_and_a_sweep_key():
    from click.testing import CliRunner

    from fccgrb_cli.cli.main import main

    help_text = CliRunner().invoke(main, ["solve", "--help"], terminal_width=200).output
    for field in SolveOptions.__dataclass_fields__.values():
        flag = "--" + (field.metadata["flag"] or field.name).replace("_", "-")
        assert flag in help_text, flag
    assert "level" in SWEEP_KEYS and "perturb_mm" not in SWEEP_KEYS


@pytest.mark.parametrize(("changes", "message"), [
    ({"method": "newton"}, "method: expected one of"),
    ({"tol": 0.0}, "tol: expected a finite number > 0"),
    ({"perturb_mm": -1.0}, "perturb_mm: expected a finite number ≥ 0 and ≤ 1000 (mm)"),
    ({"max_iter": 2.5}, "max_iter: expected an integer"),
    ({"name": 3}, "name: expected a text"),
    ({"dynamics": 1}, "dynamics: expected true or false"),
    ({"filter_order": 9}, "filter_order: expected an integer ≥ 1 and ≤ 8"),
    ({"parallel_init": "all"}, "parallel_init: expected one of same, chunks, nrm"),
])
def test_options_refuse_values_they_cannot_mean(changes: dict, message: str):
    with pytest.raises(InputError, match=re.escape(message)):
        SolveOptions(**changes)


def test_options_accept_sweep_spellings_and_round_trip_through_json():
    chosen = SolveOptions.from_mapping({"level": 30, "map": {"P1": "p1"}, "track": ["P1", "P2"],
                                        "name": "x", "max_iter": 3})
    assert chosen.perturb_mm == 30 and chosen.perturb_level_m == pytest.approx(0.03)
    assert chosen.mapping == (("P1", "p1"),) and chosen.track == ("P1", "P2")
    assert SolveOptions.from_json(chosen.to_json()) == chosen
    with pytest.raises(InputError, match=r"cell\.levle: expected one of"):
        SolveOptions.from_mapping({"levle": 30}, "cell")


def test_run_coordinates_are_named_as_the_system_lays_them_out():
    """Each body's r, u, v (w) columns of run.q are where the compiled system keeps them: the
    unit vectors are unit and orthogonal, and r is the body's origin as the system places it."""
    from fccgrb_cli.system import compile_system

    run = fc.solve(fc.load_model(MODEL), fc.read_trial(TRIAL), dynamics=False)
    system = compile_system(run.model)
    q = run.q
    for body in run.model.bodies:
        u = np.stack([q[f"{body.name}.u.{a}"] for a in "xyz"], axis=1)
        v = np.stack([q[f"{body.name}.v.{a}"] for a in "xyz"], axis=1)
        np.testing.assert_allclose(np.linalg.norm(u, axis=1), 1.0, atol=1e-8)
        np.testing.assert_allclose(np.einsum("fi,fi->f", u, v), 0.0, atol=1e-8)
        r = np.stack([q[f"{body.name}.r.{a}"] for a in "xyz"], axis=1)
        np.testing.assert_array_equal(r, run.result.q[:, system.layout.q_slice(body.name)][:, :3])
    for name in run.result.angle_names:
        np.testing.assert_array_equal(q[name], run.angles[name])


def test_named_arrays_are_arrays_to_numpy():
    """np.asarray of a NamedArray is its frames × columns values (not a 0-d object array),
    column k being a["name k"]; numpy 2's copy contract holds."""
    from fccgrb_cli.core.named import NamedArray

    rng = np.random.default_rng(7)
    values = rng.normal(size=(5, 3))
    a = NamedArray(values, ("a", "b", "c"), ("rad",) * 3, np.arange(5) / 100.0)
    plain = np.asarray(a)
    assert plain.shape == a.shape == (5, 3) and plain.dtype == a.dtype == np.float64
    for k, name in enumerate(a.names):
        np.testing.assert_array_equal(plain[:, k], a[name])
    np.testing.assert_array_equal(np.mean(a, axis=0), values.mean(axis=0))
    np.testing.assert_array_equal(np.asarray(a, dtype=np.float32), values.astype(np.float32))
    copied = np.array(a, copy=True)
    copied[0, 0] += 1.0
    assert a.values[0, 0] == values[0, 0] != copied[0, 0]
    assert np.asarray(a, copy=False) is values
    with pytest.raises(ValueError, match="without a copy"):
        np.asarray(a, dtype=np.float32, copy=False)


def test_results_of_another_format_version_are_refused(tmp_path: Path):
    path = tmp_path / "old.h5"
    run = fc.solve(fc.load_model(MODEL), fc.read_trial(TRIAL), dynamics=False, name="old")
    fc.write_results(run, path)
    with h5py.File(path, "r+") as h5:
        h5.attrs["format_version"] = 1
    with pytest.raises(InputError, match="results format 1"):
        fc.read_results(path)


def test_public_names_are_exactly_those_listed():
    for name in fc.__all__:
        assert getattr(fc, name) is not None
    with pytest.raises(AttributeError):
        _ = fc.solve_trial


def test_the_installed_package_carries_the_paper_tables():
    """`fccgrb report` puts the paper's figures beside ours from a wheel install too: the table
    lives inside the package, not beside it in the repository."""
    from fccgrb_cli.presentation.tables import PAPER_TABLES, paper_figures

    assert PAPER_TABLES.is_relative_to(Path(fc.__file__).parent) and PAPER_TABLES.is_file()
    assert len(paper_figures("table1")) > 10 and len(paper_figures("table2")) > 10


def test_a_second_run_of_the_same_name_is_refused_unless_replaced(tmp_path: Path) -> None:
    """The API keeps the command line's promise: a run already in the results file is never
    replaced silently; ``replace=True`` replaces it, and the file holds the new run's numbers."""
    model, trial = fc.load_model(MODEL), fc.read_trial(TRIAL)
    path = tmp_path / "r.h5"
    first = fc.solve(model, trial, dynamics=False, name="same")
    fc.write_results(first, path)
    second = fc.solve(model, trial, dynamics=False, name="same", perturb_mm=5)
    with pytest.raises(fc.InputError, match="same"):
        fc.write_results(second, path)
    kept = fc.read_results(path)["same"]
    assert np.array_equal(kept.result.q, first.result.q)
    fc.write_results(second, path, replace=True)
    assert np.array_equal(fc.read_results(path)["same"].result.q, second.result.q)

"""Batch sweeps (``fccgrb sweep``), paper-style tables (``fccgrb report``) and figures
(``fccgrb plot``).

Covers: sweep-config validation (one line naming the file and key path, exit status 2 from the
CLI, ``InputError`` from ``load_sweep``); grid expansion, de-duplication, defaults and stable cell
keys; resumability (a rerun does nothing and leaves the merged file's content unchanged; a sweep
killed with SIGKILL halfway leaves only complete cell files and a rerun runs only the missing
cells); ``--fresh``; ``--workers 2`` and a Dask ``LocalCluster`` giving the same numbers as one
local worker; an unreachable scheduler; the text / csv / markdown tables with the paper's figures
(checked against ``fccgrb_cli/data/paper_tables.csv`` read independently); every plot kind as
PNG or PDF; and that ``configs/sweeps/table1.yaml`` and ``table2.yaml`` cover every row of the
paper's tables they claim (without running them).

The sweeps are tiny (pendulum, 0.3 s at 100 Hz, a handful of cheap cells) and run in-process
through click's ``CliRunner`` except where a real process is needed (the kill, the unreachable
scheduler).
"""

from __future__ import annotations

import csv
import hashlib
import io
import itertools
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest
import yaml
from cli_helpers import one_error_line, run_cli
from click.testing import Result

from fccgrb_cli.batch.sweep import Cell, cells_folder, load_sweep
from fccgrb_cli.core.errors import InputError
from fccgrb_cli.presentation.tables import METRICS, collect

ROOT = Path(__file__).resolve().parents[1]
PENDULUM = ROOT / "configs" / "models" / "pendulum.yaml"
SWEEPS = ROOT / "configs" / "sweeps"
PAPER_CSV = ROOT / "fccgrb_cli" / "data" / "paper_tables.csv"
FCCGRB = shutil.which("fccgrb") or str(Path(sys.executable).with_name("fccgrb"))
SYNTH = {"synth": {"duration": 0.3, "rate": 100}}
FINAL_LINE = re.compile(r"^wrote (?P<out>.+): (?P<ran>\d+) cells run, (?P<kept>\d+) already done")
CSV_HEADER = ["table", "method", "variant", "points", "tol", "level", "metric", "ours", "paper"]
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
N_METRICS = len(METRICS)

# The base sweep: the AD baseline with the true angles, NRM LS / WLS at P0 and P30 (rows of the
# paper's Table 1) and NRM WLS at a tolerance the paper does not have (no paper figures).
BASE_CELLS = [
    {"method": "ad", "ad_drivers": "truth"},
    {"method": ["nrm-ls", "nrm-wls"], "level": [0, 30]},
    {"method": "nrm-wls", "tol": 1.0e-8},
]
BASE_COUNT = 6


# ---- helpers ------------------------------------------------------------------------------


def ok(result: Result) -> Result:
    assert result.exit_code == 0, (result.exit_code, result.output, result.exception)
    assert result.exception is None, repr(result.exception)
    return result


def final_counts(result: Result) -> tuple[int, int]:
    """(cells run, already done) from the sweep's last stdout line."""
    match = FINAL_LINE.match(result.stdout.strip().splitlines()[-1])
    assert match, result.stdout[-500:]
    return int(match["ran"]), int(match["kept"])


def write_config(path: Path, cells: list[dict], **top: object) -> Path:
    doc = {"name": path.stem, "model": str(PENDULUM), "trial": SYNTH, "seed": 0, **top,
           "cells": cells}
    path.write_text(yaml.safe_dump(doc, sort_keys=False), encoding="utf-8")
    return path


def cell_files(store: Path) -> list[Path]:
    """Finished cells: ``*.h5`` in the store; temporary files start with '.' and end in .tmp."""
    if not store.is_dir():
        return []
    return sorted(p for p in store.glob("*.h5") if not p.name.startswith("."))


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def h5_contents(path: Path) -> dict[str, tuple[dict, object]]:
    """Every group and dataset of an HDF5 file: name → (attributes, data or None)."""
    out: dict[str, tuple[dict, object]] = {}
    with h5py.File(path, "r") as h5:
        out["/"] = (dict(h5.attrs.items()), None)

        def visit(name: str, obj: h5py.HLObject) -> None:
            data = obj[()] if isinstance(obj, h5py.Dataset) else None
            out[name] = (dict(obj.attrs.items()), data)

        h5.visititems(visit)
    return out


def same_value(a: object, b: object) -> bool:
    if a is None or b is None:
        return a is b
    x, y = np.asarray(a), np.asarray(b)
    if x.shape != y.shape:
        return False
    if x.dtype.kind in "fc" and y.dtype.kind in "fc":
        return bool(np.array_equal(x, y, equal_nan=True))
    return bool(np.all(x == y))


def assert_same_contents(a: Path, b: Path) -> None:
    left, right = h5_contents(a), h5_contents(b)
    assert sorted(left) == sorted(right)
    for name, (attrs, data) in left.items():
        other_attrs, other_data = right[name]
        assert sorted(attrs) == sorted(other_attrs), name
        for key, value in attrs.items():
            assert same_value(value, other_attrs[key]), (name, key)
        assert same_value(data, other_data), name


def csv_rows(text: str) -> list[dict[str, str]]:
    reader = csv.reader(io.StringIO(text))
    header = next(reader)
    assert header == CSV_HEADER
    return [dict(zip(header, row, strict=True)) for row in reader]


def numbers_but_time(path: Path) -> list[tuple[str, ...]]:
    """The csv table of a sweep file without its ms/frame values (they depend on the load)."""
    rows = csv_rows(ok(run_cli("report", path, "--format", "csv")).stdout)
    return sorted(tuple(r.values()) for r in rows if r["metric"] != "ms/frame")


def paper_rows() -> list[dict[str, str]]:
    """fccgrb_cli/data/paper_tables.csv read independently of fccgrb_cli.presentation.tables."""
    lines = [line for line in PAPER_CSV.read_text(encoding="utf-8").splitlines()
             if line.strip() and not line.startswith("#")]
    return list(csv.DictReader(lines))


def block(text: str, metric: str) -> str:
    """The text table of one metric."""
    for part in text.split("\n\n"):
        if part.splitlines()[0].split(" — ")[1].startswith(metric):
            return part
    raise AssertionError(f"no {metric} table in:\n{text}")


def table_line(part: str, family: str, variant: str, tol: str) -> str:
    for line in part.splitlines()[2:]:
        if line.split()[:2] == [family, variant] and f" {tol} " in line:
            return line
    raise AssertionError(f"no {family} {variant} {tol} row in:\n{part}")


# ---- fixtures -----------------------------------------------------------------------------


@pytest.fixture(scope="module")
def base(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """The base sweep, run once: (config, merged output)."""
    folder = tmp_path_factory.mktemp("base")
    config = write_config(folder / "base.yaml", BASE_CELLS, table="table1")
    out = folder / "base.h5"
    started = time.perf_counter()
    result = ok(run_cli("sweep", config, "-o", out, "--workers", "1"))
    print(f"base sweep: {time.perf_counter() - started:.2f} s")
    assert final_counts(result) == (BASE_COUNT, 0)
    assert len(cell_files(cells_folder(out))) == BASE_COUNT
    return config, out


@pytest.fixture(scope="module")
def solved(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``fccgrb synth`` (0.3 s) then two ``fccgrb solve`` runs into one results file."""
    folder = tmp_path_factory.mktemp("solve")
    trial = folder / "trial.c3d"
    ok(run_cli("synth", PENDULUM, "-o", trial, "--duration", "0.3"))
    out = folder / "results.h5"
    ok(run_cli("solve", PENDULUM, trial, "-o", out, "--method", "nrm-wls"))
    ok(run_cli("solve", PENDULUM, trial, "-o", out, "--method", "nrm-wls", "--perturb", "30"))
    with h5py.File(out, "r") as h5:
        assert sorted(h5["runs"]) == ["nrm-wls", "nrm-wls-P30"]
        assert "truth" in h5
    return out


@pytest.fixture(scope="module")
def unreachable(base: tuple[Path, Path], tmp_path_factory: pytest.TempPathFactory):
    """``fccgrb sweep --scheduler tcp://127.0.0.1:1`` started in the background (it waits for
    the scheduler's connect timeout, so it overlaps the Dask test): (process, start, output)."""
    pytest.importorskip("dask.distributed")
    out = tmp_path_factory.mktemp("unreachable") / "never.h5"
    started = time.perf_counter()
    proc = subprocess.Popen([FCCGRB, "sweep", str(base[0]), "-o", str(out), "--scheduler",
                             "tcp://127.0.0.1:1"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    yield proc, started, out
    if proc.poll() is None:
        proc.kill()
        proc.communicate()


@pytest.fixture(scope="module")
def cluster():
    """A local Dask cluster: 2 worker processes, one thread each."""
    distributed = pytest.importorskip("dask.distributed")
    with distributed.LocalCluster(n_workers=2, processes=True, threads_per_worker=1,
                                  dashboard_address=None) as local:
        yield local


# ---- 1. config validation -----------------------------------------------------------------


MODEL = str(PENDULUM)
INVALID = {
    "unknown top-level key": (
        {"model": MODEL, "cells": [{"method": "ad"}], "bogus_top": 1}, ("bogus_top",)),
    "unknown cell key": (
        {"model": MODEL, "cells": [{"method": "ad", "bogus": 1}]}, ("cells[0].bogus",)),
    "unknown method": (
        {"model": MODEL, "cells": [{"method": "ad"}, {"method": ["nrm-ls", "nrm-foo"]}]},
        ("cells[1].method", "nrm-foo")),
    "undefined points variant": (
        {"model": MODEL, "variants": {"points": {"two": ["P1", "P3"]}},
         "cells": [{"method": "nrm-wls", "points": ["two", "nine"]}]},
        ("cells[0].points", "nine", "two")),
    "non-number tol": (
        {"model": MODEL, "cells": [{"method": "nrm-ls", "tol": [1.0e-6, "abc"]}]},
        ("cells[0].tol", "a number", "abc")),
    "missing model file": (
        {"model": "no_such_model.yaml", "cells": [{"method": "ad"}]},
        ("model", "no_such_model.yaml")),
}


def _bad_config(tmp_path: Path, case: str) -> tuple[Path, tuple[str, ...]]:
    path = tmp_path / "bad.yaml"
    if case == "missing file":
        return tmp_path / "absent.yaml", ("absent.yaml", "not found")
    if case == "bad YAML":
        path.write_text("name: x\nmodel: [unclosed\ncells: {\n", encoding="utf-8")
        return path, ("invalid YAML",)
    doc, fragments = INVALID[case]
    path.write_text(yaml.safe_dump(doc), encoding="utf-8")
    return path, fragments


@pytest.mark.parametrize("case", ["missing file", "bad YAML", *INVALID])
def test_bad_config_gives_one_line(tmp_path: Path, case: str) -> None:
    path, fragments = _bad_config(tmp_path, case)
    with pytest.raises(InputError) as caught:
        load_sweep(path)
    message = str(caught.value)
    assert "\n" not in message
    assert message.startswith(f"{path}: ")
    for fragment in fragments:
        assert fragment in message, (fragment, message)
    out = tmp_path / "out.h5"
    line = one_error_line(run_cli("sweep", path, "-o", out), str(path), *fragments)
    assert line == f"fccgrb: error: {message}"
    assert not out.exists() and not cells_folder(out).exists()


@pytest.mark.parametrize("case", ["folder", "not UTF-8"])
def test_unreadable_config_gives_one_line(tmp_path: Path, case: str) -> None:
    path = tmp_path / "config.yaml"
    if case == "folder":
        path.mkdir()
    else:
        path.write_bytes(b"name: \xff\xfe\n")
    with pytest.raises(InputError):
        load_sweep(path)


@pytest.mark.parametrize("value", [["P1", "P3"], [["P1", "P3"]]])
def test_perturb_markers_subset_in_a_sweep(tmp_path: Path, value: list) -> None:
    config = write_config(tmp_path / "pm.yaml",
                          [{"method": "nrm-wls", "level": 30, "perturb_markers": value}])
    sweep = load_sweep(config)
    assert len(sweep.cells) == 1
    out = tmp_path / "pm.h5"
    result = run_cli("sweep", config, "-o", out)
    assert result.exit_code == 0, result.output
    with h5py.File(out, "r") as h5:
        (cell,) = h5["cells"].values()
        assert list(cell["runs/run"].attrs["perturb_markers"]) == ["P1", "P3"]


# ---- 2. grid expansion --------------------------------------------------------------------


GRID_CELLS = [
    {"method": ["nrm-ls", "nrm-wls"], "tol": [1.0e-6, 1.0e-10], "level": [0, 7.5, 30],
     "points": ["two", "all"]},                                         # 2 × 2 × 3 × 2 = 24
    {"method": "nrm-ls", "tol": 1.0e-10, "level": 0.0, "points": "two", "seed": 7},  # duplicate
    {"method": "ad", "ad_drivers": "truth"},                            # 1, every default
    {"method": "ad", "ad_drivers": "truth", "tol": 1.0e-10, "level": 0, "seed": 7},  # duplicate
    {"method": "mo-ed", "seed": [1, 2], "level": [30, 30.0]},           # 2 (levels repeat)
]


def test_grid_expands_every_combination(tmp_path: Path) -> None:
    config = write_config(tmp_path / "grid.yaml", GRID_CELLS, seed=7,
                          variants={"points": {"two": ["P1", "P3"], "all": ["P1", "P2", "P3"]}})
    sweep = load_sweep(config)
    assert len(sweep.cells) == 24 + 1 + 2
    params = [dict(c.params) for c in sweep.cells]
    nrm = {(p["method"], p["tol"], p["level"], p["points"]) for p in params
           if p["method"].startswith("nrm")}
    assert nrm == set(itertools.product(("nrm-ls", "nrm-wls"), (1e-6, 1e-10), (0.0, 7.5, 30.0),
                                        ("two", "all")))
    assert len([p for p in params if p["method"].startswith("nrm")]) == 24
    (ad,) = [p for p in params if p["method"] == "ad"]
    assert ad == {"method": "ad", "ad_drivers": "truth", "seed": 7, "tol": 1e-10, "level": 0.0}
    assert isinstance(ad["tol"], float) and isinstance(ad["level"], float)
    mo = sorted((p["seed"], p["level"]) for p in params if p["method"] == "mo-ed")
    assert mo == [(1, 30.0), (2, 30.0)]
    assert all(p["seed"] == 7 for p in params if p["method"] != "mo-ed")
    assert sweep.variants == {"points": {"two": ["P1", "P3"], "all": ["P1", "P2", "P3"]}}
    assert sweep.model == PENDULUM and sweep.trial == SYNTH


def test_seed_defaults_to_zero(tmp_path: Path) -> None:
    doc = {"model": str(PENDULUM), "cells": [{"method": "nrm-ls"}]}
    (tmp_path / "noseed.yaml").write_text(yaml.safe_dump(doc), encoding="utf-8")
    (cell,) = load_sweep(tmp_path / "noseed.yaml").cells
    assert dict(cell.params) == {"method": "nrm-ls", "seed": 0, "tol": 1e-10, "level": 0.0}


def test_cell_keys_are_stable_and_distinct(tmp_path: Path) -> None:
    variants = {"points": {"two": ["P1", "P3"], "all": ["P1", "P2", "P3"]}}
    config = write_config(tmp_path / "grid.yaml", GRID_CELLS, seed=7, variants=variants)
    first = [c.key for c in load_sweep(config).cells]
    again = [c.key for c in load_sweep(config).cells]
    assert first == again
    assert len(set(first)) == len(first)
    # the same parameters written in another order, with defaults spelled out: the same key
    cell = Cell(tuple(sorted({"method": "nrm-ls", "seed": 0, "tol": 1e-10,
                              "level": 0.0}.items())))
    reordered = write_config(tmp_path / "other.yaml",
                             [{"level": 0, "tol": 1.0e-10, "method": "nrm-ls"}])
    assert load_sweep(reordered).cells[0].key == cell.key
    # a hash of the parameters' JSON: the same in every process (resuming relies on it); this
    # literal was computed by a separate `fccgrb sweep` run
    assert cell.key == "nrm-ls_tc_ptsall_tol1e-10_P0_seq_s0_c3009144"
    # one parameter changed: another key
    for change in ({"seed": 1}, {"tol": 1e-6}, {"level": 7.5}, {"method": "nrm-wls"},
                   {"parallel": True}, {"hessian": "exact"}):
        other = Cell(tuple(sorted((dict(cell.params) | change).items())))
        assert other.key != cell.key, change


# ---- 3. resumable and safe ----------------------------------------------------------------


def test_rerun_does_nothing_and_keeps_the_merged_content(base: tuple[Path, Path],
                                                         tmp_path: Path) -> None:
    config, out = base
    before = tmp_path / "before.h5"
    shutil.copyfile(out, before)
    hashes = {p.name: digest(p) for p in cell_files(cells_folder(out))}
    result = ok(run_cli("sweep", config, "-o", out))
    assert final_counts(result) == (0, BASE_COUNT)
    assert {p.name: digest(p) for p in cell_files(cells_folder(out))} == hashes
    assert_same_contents(before, out)
    with h5py.File(out, "r") as h5:
        assert len(h5["cells"]) == BASE_COUNT
        assert h5.attrs["table"] == "table1"
        assert h5.attrs["config"] == config.read_text(encoding="utf-8")


def test_killed_sweep_resumes_with_the_missing_cells(tmp_path: Path) -> None:
    """SIGKILL after the first cell file appears: the finished cells are complete HDF5 files,
    the rerun runs only the others and leaves the finished ones byte-identical."""
    cells = [{"method": "mo-ed", "level": [0, 7.5, 30], "seed": [0, 1]}]
    config = write_config(tmp_path / "kill.yaml", cells, trial={"synth": {"duration": 0.5,
                                                                           "rate": 100}})
    total = len(load_sweep(config).cells)
    assert total == 6
    out = tmp_path / "kill.h5"
    store = cells_folder(out)
    started = time.perf_counter()
    proc = subprocess.Popen([FCCGRB, "sweep", str(config), "-o", str(out), "--workers", "1"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 120
        seen: list[Path] = []
        while not seen and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.005)
            seen = cell_files(store)
        proc.kill()
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.wait(timeout=30)
    killed_after = time.perf_counter() - started
    assert proc.returncode == -signal.SIGKILL, \
        f"the sweep ended (status {proc.returncode}) before it could be killed halfway"
    present = cell_files(store)
    print(f"killed after {killed_after:.2f} s with {len(seen)} cell(s) seen, "
          f"{len(present)} present; temporary files: "
          f"{sorted(p.name for p in store.iterdir() if p.name.startswith('.'))}")
    assert 1 <= len(seen) <= len(present) < total
    assert not out.exists()
    for path in store.iterdir():  # cells, or a cell's temporary file or lock cut short by the
        # kill (the kernel released the lock; the next writer of that cell takes it and removes it)
        assert path in present or (path.name.startswith(".")
                                    and path.suffix in (".tmp", ".lock")), path
    keys = {c.key for c in load_sweep(config).cells}
    for path in present:
        assert path.stem in keys
        with h5py.File(path, "r") as h5:
            run = h5["runs/run"]
            assert run["q"].shape[0] == 50
            assert bool(np.all(run["converged"][()]))
            assert "reference" in h5 and "cell" in h5.attrs
    hashes = {p.name: digest(p) for p in present}

    started = time.perf_counter()
    result = ok(run_cli("sweep", config, "-o", out, "--workers", "1"))
    ran, kept = final_counts(result)
    print(f"rerun: {ran} cells run, {kept} already done ({time.perf_counter() - started:.2f} s)")
    assert (ran, kept) == (total - len(present), len(present))
    assert kept >= len(seen)
    assert {p.name: digest(p) for p in present} == hashes
    assert len(cell_files(store)) == total
    with h5py.File(out, "r") as h5:
        assert sorted(h5["cells"]) == sorted(keys)


# ---- 4. --fresh ---------------------------------------------------------------------------


def test_fresh_runs_every_cell_again(base: tuple[Path, Path], tmp_path: Path) -> None:
    config, out = base
    copy = tmp_path / "copy.h5"
    shutil.copytree(cells_folder(out), cells_folder(copy))
    kept = cell_files(cells_folder(copy))
    for path in kept:
        os.utime(path, (1_000_000_000, 1_000_000_000))  # 2001: any rewrite is newer
    kept[0].write_bytes(b"not a cell any more")  # only --fresh can repair this one
    (cells_folder(copy) / "stale_cell.h5").write_bytes(b"from another config")
    result = ok(run_cli("sweep", config, "-o", copy, "--fresh"))
    assert final_counts(result) == (BASE_COUNT, 0)
    now = cell_files(cells_folder(copy))
    assert [p.name for p in now] == [p.name for p in kept]
    assert all(p.stat().st_mtime > 1_000_000_000 + 1 for p in now)
    for path in now:
        with h5py.File(path, "r") as h5:
            assert "runs/run" in h5
    assert numbers_but_time(copy) == numbers_but_time(out)


# ---- 5. workers ---------------------------------------------------------------------------


def test_two_workers_give_the_same_numbers(base: tuple[Path, Path], tmp_path: Path) -> None:
    config, out = base
    other = tmp_path / "two.h5"
    started = time.perf_counter()
    result = ok(run_cli("sweep", config, "-o", other, "--workers", "2"))
    print(f"--workers 2: {time.perf_counter() - started:.2f} s")
    assert final_counts(result) == (BASE_COUNT, 0)
    assert numbers_but_time(other) == numbers_but_time(out)


# ---- 7. tables ----------------------------------------------------------------------------


def test_text_table_shows_the_paper_in_brackets(base: tuple[Path, Path]) -> None:
    _, out = base
    text = ok(run_cli("report", out, "--format", "text")).stdout
    ms = block(text, "ms/frame")
    assert ms.splitlines()[0] == "table1 — ms/frame (ours [paper])"
    assert "[8.8]" in table_line(ms, "NRM", "WLS", "1e-10")
    assert "[13.5]" in table_line(ms, "NRM", "LS", "1e-10")  # P30
    assert "[8.6]" in table_line(ms, "KA", "AD", "1e-10")
    iterations = block(text, "iterations/frame")
    wls = table_line(iterations, "NRM", "WLS", "1e-10")
    assert "[4]" in wls and "[6.5]" in wls
    assert "[" not in table_line(ms, "NRM", "WLS", "1e-08")  # no such row in the paper
    assert "[" not in block(text, "mean ED (mm)").split("\n", 1)[1]  # no such metric there
    assert "–" in wls  # P7.5 was not run


def test_csv_table_has_the_paper_column(base: tuple[Path, Path]) -> None:
    _, out = base
    rows = csv_rows(ok(run_cli("report", out, "--format", "csv")).stdout)
    assert len(rows) == BASE_COUNT * N_METRICS
    assert {r["table"] for r in rows} == {"table1"}
    paper = {(r["method"], r["variant"], float(r["tol"]), r["level"]): r
             for r in paper_rows() if r["table"] == "table1"}
    columns = {"ms/frame": "time_ms_per_frame", "iterations/frame": "iterations",
               "mean ‖Φ‖": "phi_norm_mean", "max |Φ_top|": "phi_top_max"}
    filled = empty = 0
    for row in rows:
        float(row["ours"])
        theirs = paper.get((row["method"], row["variant"], float(row["tol"]), row["level"]))
        if theirs is not None and row["metric"] in columns:
            assert float(row["paper"]) == float(theirs[columns[row["metric"]]]), row
            filled += 1
        else:
            assert row["paper"] == "", row
            empty += 1
    assert filled == 5 * 4 and empty == BASE_COUNT * N_METRICS - 20
    wls = [r for r in rows if (r["method"], r["variant"], r["tol"], r["level"], r["metric"])
           == ("NRM", "WLS", "1e-10", "P0", "ms/frame")]
    assert [r["paper"] for r in wls] == ["8.8"]
    assert [r["points"] for r in wls] == [""]
    unmatched = [r for r in rows if r["tol"] == "1e-08"]
    assert len(unmatched) == N_METRICS and all(r["paper"] == "" for r in unmatched)


def test_markdown_table_is_pipe_tables(base: tuple[Path, Path]) -> None:
    _, out = base
    text = ok(run_cli("report", out, "--format", "markdown")).stdout
    assert "**table1 — ms/frame (ours [paper])**" in text
    assert text.count("| method | variant | points | tol | P0 | P7.5 | P30 |") == N_METRICS
    assert text.count("|---|---|---|---|---|---|---|") == N_METRICS
    rows = [line for line in text.splitlines()
            if line.startswith("| NRM | WLS |  | 1e-10 |")]
    assert len(rows) == N_METRICS
    assert "[8.8]" in rows[0] and "[4]" in rows[1]
    assert all(line.endswith(" |") for line in rows)


def test_report_on_solve_results_has_no_paper(solved: Path) -> None:
    text = ok(run_cli("report", solved)).stdout
    assert "[" not in text and "ours [paper]" not in text
    ms = block(text, "ms/frame")
    assert ms.splitlines()[0] == "runs — ms/frame"
    line = table_line(ms, "NRM", "WLS", "1e-10")
    assert "–" in line  # P7.5
    rows = csv_rows(ok(run_cli("report", solved, "--format", "csv")).stdout)
    assert {(r["level"], r["paper"], r["table"]) for r in rows} == {("P0", "", ""),
                                                                  ("P30", "", "")}


def test_report_on_a_non_hdf5_file(tmp_path: Path) -> None:
    path = tmp_path / "notes.h5"
    path.write_text("not HDF5\n", encoding="utf-8")
    one_error_line(run_cli("report", path), str(path), "not an HDF5 results file")
    one_error_line(run_cli("report", tmp_path / "absent.h5"), "absent.h5", "not found")


# ---- 8. plots -----------------------------------------------------------------------------


@pytest.mark.parametrize(("kind", "suffix"), [("point", ".png"), ("ed", ".png"),
                                              ("angle", ".png"), ("velocity", ".png"),
                                              ("angle", ".pdf")])
def test_plot_kinds(solved: Path, tmp_path: Path, kind: str, suffix: str) -> None:
    figure = tmp_path / f"{kind}{suffix}"
    result = ok(run_cli("plot", solved, "--kind", kind, "-o", figure))
    assert result.stdout.strip() == f"wrote {figure}: {kind} for 2 runs"
    data = figure.read_bytes()
    assert data.startswith(PNG_MAGIC if suffix == ".png" else b"%PDF")
    assert len(data) > 10_000
    assert sorted(p.name for p in tmp_path.iterdir()) == [figure.name]


@pytest.mark.parametrize(("option", "fragments"), [
    (("--kind", "point", "--marker", "NOPE"), ("--marker", "P1, P2, P3", "NOPE")),
    (("--kind", "angle", "--angle", "knee"), ("--angle", "shoulder_x", "knee")),
    (("--runs", "zzz"), ("--runs", "nrm-wls-P30")),
])
def test_plot_bad_names(solved: Path, tmp_path: Path, option: tuple[str, ...],
                        fragments: tuple[str, ...]) -> None:
    figure = tmp_path / "x.png"
    one_error_line(run_cli("plot", solved, *option, "-o", figure), *fragments)
    assert list(tmp_path.iterdir()) == []


def test_plot_rejects_other_endings(solved: Path, tmp_path: Path) -> None:
    figure = tmp_path / "x.jpg"
    one_error_line(run_cli("plot", solved, "-o", figure), str(figure), ".png or .pdf")
    assert list(tmp_path.iterdir()) == []


def test_plot_a_sweep_by_cell_key_prefix(base: tuple[Path, Path], tmp_path: Path) -> None:
    _, out = base
    figure = tmp_path / "ed.png"
    result = ok(run_cli("plot", out, "--kind", "ed", "--runs", "nrm-wls_tc_ptsall_tol1e-10",
                        "-o", figure))
    assert result.stdout.strip() == f"wrote {figure}: ed for 2 runs"
    assert figure.read_bytes().startswith(PNG_MAGIC)


# ---- 9. the paper's grids -----------------------------------------------------------------


PAPER_METHOD = {("KA", "AD"): "ad", ("NRM", "LS"): "nrm-ls", ("NRM", "WLS"): "nrm-wls",
                ("CNO", "SQP"): "cno-sqp", ("CNO", "IP"): "cno-ip", ("MO", "TC"): "mo-tc",
                ("MO", "ED"): "mo-ed"}


def covers(cell: dict, row: dict[str, str]) -> bool:
    variant = row["variant"].removesuffix("-parallel")
    parallel = row["variant"].endswith("-parallel")
    method = PAPER_METHOD[(row["method"], variant)]
    return (cell["method"] == method
            and bool(cell.get("parallel", False)) == parallel
            and (not parallel or cell.get("parallel_init", "same") == "same")
            and (method != "ad" or cell.get("ad_drivers") == "truth")
            and (not row["ref_points"] or cell.get("points") == row["ref_points"])
            and cell["tol"] == float(row["tol"])
            and cell["level"] == float(row["level"].removeprefix("P")))


@pytest.mark.parametrize("table", ["table1", "table2"])
def test_config_covers_the_paper_table(table: str) -> None:
    sweep = load_sweep(SWEEPS / f"{table}.yaml")
    assert sweep.table == table
    cells = [dict(c.params) for c in sweep.cells]
    rows = [r for r in paper_rows() if r["table"] == table]
    assert len(rows) == {"table1": 26, "table2": 47}[table]
    missing = [r for r in rows if not any(covers(c, r) for c in cells)]
    assert missing == []
    assert {c["level"] for c in cells} == {0.0, 7.5, 30.0}
    if table == "table2":
        assert sweep.variants["points"]["8"] == [f"P{k}" for k in range(1, 9)]
        assert sweep.variants["points"]["9"] == [f"P{k}" for k in range(1, 10)]


# ---- 6. Dask (last: the cluster lives until the module ends) ------------------------------


def test_dask_cluster_gives_the_same_numbers(unreachable, cluster, base: tuple[Path, Path],
                                             tmp_path: Path) -> None:
    config, out = base
    other = tmp_path / "dask.h5"
    started = time.perf_counter()
    result = ok(run_cli("sweep", config, "-o", other, "--scheduler", cluster.scheduler_address))
    print(f"dask sweep: {time.perf_counter() - started:.2f} s")
    assert final_counts(result) == (BASE_COUNT, 0)
    assert numbers_but_time(other) == numbers_but_time(out)


def test_unreachable_scheduler(unreachable) -> None:
    """One line and exit status 2 once the connect timeout (10 s) has passed."""
    proc, started, out = unreachable
    stdout, stderr = proc.communicate(timeout=90)
    elapsed = time.perf_counter() - started
    print(f"unreachable scheduler: {elapsed:.1f} s")
    assert proc.returncode == 2, stderr
    lines = stderr.splitlines()
    assert len(lines) == 1, stderr
    assert lines[0].startswith("fccgrb: error: --scheduler: cannot reach tcp://127.0.0.1:1")
    assert stdout == ""
    assert elapsed < 60
    assert not out.exists() and not cells_folder(out).exists()


# ---- regressions of defects found while writing these tests -------------------------------


def test_empty_grid_list_is_refused(tmp_path: Path) -> None:
    config = write_config(tmp_path / "empty.yaml", [{"method": "nrm-wls", "level": []}])
    with pytest.raises(InputError, match=r"cells\[0\]\.level: expected a value or a non-empty"):
        load_sweep(config)


def test_cells_differing_only_in_seed_get_their_own_rows(tmp_path: Path) -> None:
    config = write_config(tmp_path / "seeds.yaml",
                          [{"method": "nrm-wls", "level": 30, "seed": [0, 1]}])
    out = tmp_path / "seeds.h5"
    assert run_cli("sweep", config, "-o", out).exit_code == 0
    _, rows = collect(out)
    assert sorted(r.variant for r in rows) == ["WLS", "WLS [seed=1]"]
    # each row is its own seed's: the artefacts differ, so do the fits (mean ED, mm)
    ed = {r.variant: r.values["mean ED (mm)"] for r in rows}
    assert all(v > 1.0 for v in ed.values()) and abs(ed["WLS"] - ed["WLS [seed=1]"]) > 1e-3


def test_a_broken_cell_file_is_run_again(tmp_path: Path) -> None:
    config = write_config(tmp_path / "broken.yaml", [{"method": "nrm-wls", "level": [0, 30]}])
    out = tmp_path / "broken.h5"
    assert run_cli("sweep", config, "-o", out).exit_code == 0
    victim = sorted(cells_folder(out).glob("*.h5"))[0]
    victim.write_bytes(b"not HDF5")
    result = run_cli("sweep", config, "-o", out)
    assert result.exit_code == 0, result.output
    assert "1 cells run, 1 already done" in result.stdout
    with h5py.File(victim, "r") as h5:
        assert "runs/run" in h5

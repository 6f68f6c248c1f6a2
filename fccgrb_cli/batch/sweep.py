"""Batch sweeps: a grid of solves over models, trials, methods, tolerances, perturbation levels
and seeds, tracked-point variants and sequential/parallel — resumable and safe.

A sweep config (YAML) names a model, a trial (synthesized or a file) and ``cells``: a list of
grids, each expanding to every combination of its list-valued keys. Each finished cell is
written atomically to its own file in ``OUTPUT.cells/`` (a killed sweep leaves the finished
cells intact; a rerun skips them), then all cells are merged into OUTPUT, also atomically.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import shutil
import time as clock
from collections.abc import Callable, Iterator
from concurrent.futures import Executor
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any, NoReturn

from fccgrb_cli.batch.cells import Job, cells_folder, pending, run_jobs
from fccgrb_cli.core.atomic import atomic_path, remove_stale
from fccgrb_cli.core.bounds import describe_range, in_range
from fccgrb_cli.core.errors import InputError
from fccgrb_cli.core.hdf5_writer import writing
from fccgrb_cli.core.inputs import check_name, load_yaml, read_text, shown
from fccgrb_cli.core.lock import exclusive
from fccgrb_cli.pipeline.options import SEED_MAX, SWEEP_KEYS, SolveOptions

TABLES = ("table1", "table2")  # the paper's tables (fccgrb_cli/data/paper_tables.csv)

# every solve option by its sweep key (``level``: the perturbation in mm), and ``points``
CELL_KEYS = set(SWEEP_KEYS) - {"name", "map", "track"} | {"points"}
TOP_KEYS = {"name", "table", "model", "trial", "seed", "variants", "cells"}


@dataclass(frozen=True)
class Cell:
    """One solve of the sweep: every parameter fixed."""

    params: tuple[tuple[str, Any], ...]

    def get(self, key: str, default: Any = None) -> Any:
        return dict(self.params).get(key, default)

    @property
    def key(self) -> str:
        """A stable identifier: method, variant, points, tolerance, level, seed, hash."""
        p = dict(self.params)
        text = json.dumps(p, sort_keys=True, default=str)
        digest = hashlib.sha1(text.encode()).hexdigest()[:8]
        init = p.get("parallel_init", "nrm")
        mode = ("par" + ("" if init == "same" else f"-{init}")) if p.get("parallel") else "seq"
        return (f"{p['method']}_{p.get('objective', 'tc')}_pts{p.get('points', 'all')}_"
                f"tol{p['tol']:g}_P{p.get('level', 0):g}_{mode}_s{p.get('seed', 0)}_{digest}")


@dataclass(frozen=True)
class Sweep:
    name: str
    table: str
    source: Path
    model: Path
    trial: dict
    variants: dict
    cells: tuple[Cell, ...]


def _fail(source: Path, path: str, expected: str, got: Any = None) -> NoReturn:
    raise InputError(f"{source}: {path}: expected {expected}" +
                     ("" if got is None else f", got {shown(got)}"))


def _axis(key: str, value: Any) -> list:
    """The values a grid key takes. ``perturb_markers`` names one subset (a list of names) or
    several (a list of lists); every other key is one value or a list of values."""
    if key == "perturb_markers":
        def names(v: list) -> tuple:  # a mapping or a list stays one, for _scalars to name
            return tuple(str(m) if isinstance(m, (str, int, float)) else m for m in v)

        if isinstance(value, list) and value and all(isinstance(v, list) for v in value):
            return [names(v) for v in value]
        return [names(value if isinstance(value, list) else [value])]
    return value if isinstance(value, list) else [value]


def _scalars(source: Path, where: str, combo: dict) -> None:
    """Every value of an expanded cell one scalar (``perturb_markers``: names), so that a
    mapping or a list of lists where one value is expected is named with its key."""
    for key, value in combo.items():
        if key == "perturb_markers":
            value = next((m for m in value if not isinstance(m, str)), None)
            if value is not None:
                _fail(source, f"{where}.{key}", "marker names, or lists of them", value)
        elif value is not None and not isinstance(value, (str, int, float, bool)):
            _fail(source, f"{where}.{key}", "one value or a list of values", value)


def _expand(grid: dict) -> Iterator[dict]:
    keys = list(grid)
    values = [_axis(key, value) for key, value in grid.items()]
    for combo in itertools.product(*values):
        yield dict(zip(keys, combo, strict=True))


def load_sweep(path: str | Path) -> Sweep:
    """Read and validate a sweep config; paths inside it are relative to the config."""
    from fccgrb_cli.pipeline.options import METHODS

    path = Path(path)
    doc = load_yaml(read_text(path, "sweep config"), str(path))
    if not isinstance(doc, dict):
        _fail(path, "(top level)", "a mapping", doc)
    unknown = set(doc) - TOP_KEYS
    if unknown:
        _fail(path, sorted(unknown)[0], f"one of the keys {sorted(TOP_KEYS)}")
    for key in ("model", "cells"):
        if key not in doc:
            _fail(path, key, "this key to be present")
    name = check_name(doc.get("name", path.stem), f"{path}: name")
    table = doc.get("table", "")
    if table not in ("", None, *TABLES):
        _fail(path, "table", f"one of the paper's tables {', '.join(TABLES)}", table)
    if not isinstance(doc["model"], str):
        _fail(path, "model", "the path of a model file", doc["model"])
    model = (path.parent / doc["model"]).resolve()
    if not model.is_file():
        _fail(path, "model", "an existing model file", str(doc["model"]))
    trial = doc.get("trial", {"synth": {"duration": 3.0, "rate": 100.0}})
    if not isinstance(trial, dict) or not ({"synth"} == set(trial) or {"file"} == set(trial)):
        _fail(path, "trial", "{synth: {duration, rate}} or {file: PATH}", trial)
    if "file" in trial:
        if not isinstance(trial["file"], str):
            _fail(path, "trial.file", "the path of a trial file", trial["file"])
        trial = {"file": str((path.parent / trial["file"]).resolve())}
    else:
        _check_synth(path, trial["synth"])
    seed = doc.get("seed", 0)
    if not in_range(seed, int, 0, False, SEED_MAX):
        _fail(path, "seed", f"an integer from 0 to {SEED_MAX}", seed)
    variants = doc.get("variants") or {}
    if not isinstance(variants, dict) or not isinstance(variants.get("points", {}), dict):
        _fail(path, "variants", "{points: {NAME: [marker names]}}", variants)
    variants = {"points": {str(k): list(v) for k, v in variants.get("points", {}).items()}}
    cells: list[Cell] = []
    if not isinstance(doc["cells"], list) or not doc["cells"]:
        _fail(path, "cells", "a non-empty list of grids", doc["cells"])
    for k, grid in enumerate(doc["cells"]):
        where = f"cells[{k}]"
        if not isinstance(grid, dict):
            _fail(path, where, "a mapping of cell parameters", grid)
        bad = set(grid) - CELL_KEYS
        if bad:
            _fail(path, f"{where}.{sorted(bad)[0]}", f"one of {sorted(CELL_KEYS)}")
        for key, value in grid.items():
            if isinstance(value, list) and not value:
                _fail(path, f"{where}.{key}", "a value or a non-empty list", value)
        for combo in _expand(grid):
            _scalars(path, where, combo)
            combo.setdefault("seed", doc.get("seed", 0))
            combo.setdefault("tol", 1e-10)
            combo.setdefault("level", 0.0)
            if combo.get("method") not in METHODS:
                _fail(path, f"{where}.method", f"one of {', '.join(METHODS)}",
                      combo.get("method"))
            if combo.get("points") is not None:
                combo["points"] = str(combo["points"])
                if combo["points"] not in variants["points"]:
                    _fail(path, f"{where}.points", "a variant named under variants.points "
                          f"({', '.join(variants['points']) or 'none'})", combo["points"])
            for key in ("tol", "level"):
                if isinstance(combo[key], bool) or not isinstance(combo[key], (int, float)):
                    _fail(path, f"{where}.{key}", "a number", combo[key])
                combo[key] = float(combo[key])
            if not 0.0 <= combo["level"] <= 1000.0:  # NaN fails too
                _fail(path, f"{where}.level", "a perturbation level from 0 to 1000 (mm)",
                      combo["level"])
            if not 0.0 < combo["tol"] <= 1.0:
                _fail(path, f"{where}.tol", "a tolerance in (0, 1]", combo["tol"])
            cells.append(Cell(tuple(sorted(combo.items()))))
    unique = list(dict.fromkeys(cells))
    sweep = Sweep(str(name), str(table or ""), path, model, trial, variants, tuple(unique))
    for cell in sweep.cells:  # every cell's options checked before any cell runs
        cell_options(sweep, cell)
    return sweep


def _check_synth(path: Path, spec: Any) -> None:
    """trial.synth: {duration: s, rate: Hz}, finite and of a bounded number of frames."""
    from fccgrb_cli.pipeline.synth import frame_count

    if not isinstance(spec, dict) or set(spec) - {"duration", "rate"}:
        _fail(path, "trial.synth", "{duration: SECONDS, rate: HZ}", spec)
    duration, rate = spec.get("duration", 3.0), spec.get("rate", 100.0)
    for key, value, high in (("duration", duration, None), ("rate", rate, 1e5)):
        if not in_range(value, float, 0.0, True, high):
            _fail(path, f"trial.synth.{key}", describe_range(float, 0.0, True, high), value)
    frame_count(duration, rate, f"{path}: trial.synth: duration × rate")


@lru_cache(maxsize=4)
def _synthesized(model_path: str, duration: float, rate: float, tol: float):
    """The synthesized trial of a model, once per process (cells reuse it)."""
    from fccgrb_cli.model import load_model
    from fccgrb_cli.pipeline.synth import synthesize
    from fccgrb_cli.trial.record import Trial
    from fccgrb_cli.trial.truth import Truth

    model = load_model(model_path)
    s = synthesize(model, duration, rate, tol)
    r = s.result
    truth = Truth(r.time, r.theta, r.theta_d, r.theta_dd, r.angle_names, r.q, "full",
                  s.markers, s.labels, rate, model.text)
    return Trial(f"<synth {Path(model_path).name}>", s.labels, s.markers, rate), truth


def run_cell(sweep: Sweep, cell: Cell, store: Path) -> Path:
    """Solve one cell and write it atomically to the store; returns the cell's file."""
    from fccgrb_cli.model import load_model
    from fccgrb_cli.pipeline.solve import solve_trial
    from fccgrb_cli.results.storage import write_run
    from fccgrb_cli.trial.record import read_trial

    target = store / f"{cell.key}.h5"
    truth = None
    if "synth" in sweep.trial:
        spec = sweep.trial["synth"]
        trial, truth = _synthesized(str(sweep.model), float(spec.get("duration", 3.0)),
                                    float(spec.get("rate", 100.0)), 1e-12)
    else:
        trial = read_trial(sweep.trial["file"], sweep.trial.get("accept_truncated", False))
    run = solve_trial(load_model(sweep.model), trial, cell_options(sweep, cell), truth=truth)
    write_run(target, run, f"fccgrb sweep {sweep.source} (cell {cell.key})",
              cell=dict(cell.params) | {"sweep": sweep.name, "table": sweep.table})
    return target


def cell_options(sweep: Sweep, cell: Cell) -> SolveOptions:
    """A cell's solve options: its keys are the options' (``level`` in mm for ``perturb_mm``),
    ``points`` names a variant of tracked markers, ``form`` falls back on the model's, and the
    inverse dynamics runs only where the cell asks for it."""
    p = dict(cell.params)
    values = {k: v for k, v in p.items() if k != "points" and v is not None}
    if p.get("points") is not None:
        values["track"] = tuple(sweep.variants["points"][p["points"]])
    values.setdefault("dynamics", False)
    return SolveOptions.from_mapping(values | {"name": "run"}, where=f"{sweep.source}: cell")


def check_sweep_output(output: Path, name: str) -> None:
    """An InputError unless ``output`` is absent or this sweep's own results (a sweep file of
    the sweep ``name``, which a rerun merges again): a text file, another command's results or
    another sweep's are never replaced."""
    import h5py

    if not output.exists() and not output.is_symlink():
        return
    try:
        with h5py.File(output, "r") as h5:
            written_by = h5.attrs.get("sweep")
            merged = "cells" in h5
    except OSError:
        raise InputError(f"{output}: exists and is not a sweep's results file; choose another "
                         "output") from None
    if written_by is None or not merged:
        raise InputError(f"{output}: exists and holds no sweep's cells (another command's "
                         "results?); choose another output")
    if str(written_by) != name:
        raise InputError(f"{output}: holds the results of the sweep {str(written_by)!r}, not "
                         f"{name!r}; choose another output")


def run_sweep(sweep: Sweep, output: Path, *, workers: int = 1, executor: Executor | None = None,
              progress: Callable[[str], None] | None = None) -> tuple[int, int]:
    """Run the missing cells (sequential-mode cells over the executor or a local process pool,
    then the parallel-mode ones alone, one at a time, so that their timing is not shared), and
    merge every cell into ``output``. Returns (cells run now, cells already done). The sweep
    holds ``output``'s lock throughout (another sweep into it is refused at once), removes the
    scratch files of cells a killed run left, and its local workers end with it. A run that
    fails before any cell is finished (a full disk, a cell refused) takes away the cells'
    folder it made: a folder is left only with finished cells in it, to resume from."""
    store = cells_folder(output)
    jobs = [Job(cell.key, store / f"{cell.key}.h5", run_cell, (sweep, cell, store),
                alone=bool(cell.get("parallel"))) for cell in sweep.cells]

    def forget(path: Path) -> None:
        if progress is not None:
            progress(f"{path.name} is unreadable; running that cell again")

    finished = 0
    started = clock.perf_counter()

    def done(job: Job, error: BaseException | None) -> None:
        nonlocal finished
        if error is not None:
            raise error
        finished += 1
        if progress is not None:
            progress(f"{finished}/{len(todo)} cells ({clock.perf_counter() - started:.0f} s): "
                     f"{job.name}")

    with exclusive(output, wait=0):
        made = not store.exists()
        store.mkdir(exist_ok=True)
        try:
            remove_stale(store)
            todo = pending(jobs, _readable, forget)
            run_jobs(todo, done, workers=workers, executor=executor)
            merge(sweep, store, output)
        except BaseException:
            if made and not any(store.glob("*.h5")):  # nothing finished to resume from
                shutil.rmtree(store, ignore_errors=True)
            raise
    return len(todo), len(jobs) - len(todo)


def _readable(path: Path) -> bool:
    """A cell file that opens and holds its run (files are renamed into place whole, so only
    something outside the sweep can break one)."""
    import h5py

    try:
        with h5py.File(path, "r") as h5:
            return "runs/run" in h5
    except OSError:
        return False


def merge(sweep: Sweep, store: Path, output: Path) -> None:
    """Copy every cell's file into one HDF5 (``/cells/<key>/``), atomically."""
    import h5py

    with atomic_path(output) as tmp, writing(tmp) as out:
        out.attrs["sweep"] = sweep.name
        out.attrs["table"] = sweep.table
        out.attrs["config"] = sweep.source.read_text(encoding="utf-8")
        group = out.create_group("cells")
        for cell in sweep.cells:
            path = store / f"{cell.key}.h5"
            if not path.exists():
                continue
            with h5py.File(path, "r") as src:
                target = group.create_group(cell.key)
                for key, value in src.attrs.items():
                    target.attrs[key] = value
                for name in src:
                    src.copy(src[name], target, name=name)

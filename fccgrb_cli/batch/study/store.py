"""A study's results file (``fccgrb batch -o study.h5``), made from the cells folder in one
atomic write, and read back for the tables and the clinical report.

Layout (results format 2, root attribute ``kind`` = ``study``):

* root attributes: ``format_version``, ``kind``, ``study`` (the study's name), ``study_text``
  (the study file), ``command``, ``versions`` (JSON, of the process that made the file);
* ``/runs/<subject>-<trial>/``: each solved trial's run, as ``fccgrb solve`` writes it
  (``fccgrb_cli.results.storage``: ``fccgrb export``, ``plot`` and ``report`` read it), with the
  attributes ``subject``, ``trial_name`` and ``versions`` (the worker's);
* ``/subjects/<subject>/``: attributes ``group``, ``template``, ``static`` (paths relative to
  the study file's folder), ``model`` (the
  personalized model's YAML), ``mass`` (kg, NaN when none), ``runs`` (solved), ``trials`` (all);
  ``cycles/<side>/`` every trial's strides pooled (``results.gait``, mean ± SD over the
  trusted ones), ``spatiotemporal/<side>/`` ``mean``, ``sd``, ``n`` of each parameter over them;
* ``/groups/<group>/``: attribute ``subjects``; ``cycles/<side>/`` ``mean``, ``sd`` (101 ×
  variables; between-subject), ``n`` (subjects per variable), ``subjects`` (each subject's mean
  curve); ``spatiotemporal/<side>/`` ``values`` (subjects × parameters: each subject's mean),
  ``mean``, ``sd``, ``n`` (``study.pooling``);
* ``/errors/``: ``where`` and ``message`` (strings): every calibration or trial that failed;
* ``/timings/<run>/``: what differs between two runs of the same study and nothing else:
  ``time_s`` (per frame) and ``classical_time_s`` (the dynamics stage's), attributes
  ``solve_s`` (the trial's wall time in its worker) and ``wall_s``. The runs' own ``time_s``
  and ``classical/time_s`` are soft links to them (readers find them where a solve's file has
  them) and the runs' ``wall_s`` is NaN (ms/frame is then the mean per-frame time). So two
  files of one study, interrupted or not, local or on a cluster, are equal outside
  ``/timings`` (``tests/test_batch.py`` compares every dataset and attribute).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fccgrb_cli.batch.study.flags import Flag, run_flags
from fccgrb_cli.batch.study.pooling import group_cycles, group_parameters, stride_parameters
from fccgrb_cli.batch.study.spec import Study
from fccgrb_cli.core.atomic import atomic_path
from fccgrb_cli.core.datasets import open_results, put
from fccgrb_cli.core.errors import InputError
from fccgrb_cli.core.hdf5_writer import writing
from fccgrb_cli.core.inputs import regular_file
from fccgrb_cli.gait.analysis import GaitResults
from fccgrb_cli.gait.cycles import PARAMETERS, SideCycles, pooled
from fccgrb_cli.results.gait import read_cycles, read_gait, write_cycles
from fccgrb_cli.results.storage import FORMAT_VERSION, versions

KIND = "study"
TIMINGS = "timings"


@dataclass(frozen=True)
class Solved:
    """What the batch hands the writer: each solved run's cell file by run name, each
    calibrated subject's model file, and the failures (where, message) in the study's order."""

    runs: dict[str, Path]
    models: dict[str, Path]
    failures: tuple[tuple[str, str], ...]


def _text(h5py):
    return h5py.string_dtype(encoding="utf-8")


def write_study(study: Study, output: Path, solved: Solved, command: str) -> None:
    """The study file from the cells, atomically (nothing is written when a step fails)."""
    import h5py

    with atomic_path(output) as tmp, writing(tmp) as h5:
        h5.attrs.update({"format_version": FORMAT_VERSION, "kind": KIND, "study": study.name,
                         "study_text": study.text, "command": command,
                         "versions": json.dumps(versions())})
        runs = h5.create_group("runs", track_order=True)
        timings = h5.create_group(TIMINGS, track_order=True)
        h5.create_group("subjects", track_order=True)
        per_subject: dict[str, dict[str, SideCycles]] = {}
        for subject in study.subjects:
            names = [subject.trial_name(t) for t in subject.trials]
            done = [n for n in names if n in solved.runs]
            gaits = []
            for name in done:
                gait = _copy_run(solved.runs[name], name, subject.name, runs, timings)
                if gait is not None:
                    gaits.append(gait)
            g = h5["subjects"].create_group(subject.name)
            model = solved.models.get(subject.name)
            g.attrs.update({
                "group": subject.group, "template": study.relative(subject.template),
                "static": study.relative(subject.static),
                "model": model.read_text(encoding="utf-8") if model is not None else "",
                "mass": np.nan if subject.mass is None else subject.mass})
            g.attrs.create("runs", done, dtype=_text(h5py))
            g.attrs.create("trials", names, dtype=_text(h5py))
            if gaits:
                cycles = pooled(gaits)
                per_subject[subject.name] = cycles
                write_cycles(g, cycles)
                _write_spatiotemporal(g, {side: stride_parameters(c) for side, c in
                                          cycles.items()})
        _write_groups(h5, study, per_subject)
        errors = h5.create_group("errors")
        errors.create_dataset("where", data=[w for w, _ in solved.failures], dtype=_text(h5py))
        errors.create_dataset("message", data=[m for _, m in solved.failures],
                              dtype=_text(h5py))


def _copy_run(cell: Path, name: str, subject: str, runs, timings) -> dict[str, SideCycles] | None:
    """Copy one cell's run into /runs, its timings into /timings (linked back); its cycles."""
    import h5py

    with h5py.File(cell, "r") as src:
        src.copy(src["runs"][name], runs, name=name)
        solve_s = json.loads(src.attrs["cell"])["solve_s"]
        worker_versions = src.attrs["versions"]
    g = runs[name]
    g.attrs.update({"subject": subject, "trial_name": name[len(subject) + 1:],
                    "versions": worker_versions})
    t = timings.create_group(name)
    t.attrs.update({"solve_s": solve_s, "wall_s": g.attrs["wall_s"]})
    g.attrs["wall_s"] = np.nan
    for key, moved in (("time_s", "time_s"), ("classical/time_s", "classical_time_s")):
        if key in g:
            g.file.move(g[key].name, f"{t.name}/{moved}")
            g[key] = h5py.SoftLink(f"{t.name}/{moved}")
    return read_cycles(g["gait"]) if "gait" in g else None


def _write_spatiotemporal(g, spreads: dict) -> None:
    out = g.create_group("spatiotemporal")
    for side, spread in spreads.items():
        s = out.create_group(side)
        for key in ("mean", "sd", "n"):
            put(s, key, getattr(spread, key))
        s.attrs.update({"names": [p for p, _ in PARAMETERS], "units": [u for _, u in PARAMETERS],
                        "rows": list(spread.rows)})


def _write_groups(h5, study: Study, per_subject: dict[str, dict[str, SideCycles]]) -> None:
    import h5py

    groups = h5.create_group("groups", track_order=True)
    order = list(dict.fromkeys(s.group for s in study.subjects))
    for name in order:
        members = [s.name for s in study.subjects if s.group == name]
        g = groups.create_group(name)
        g.attrs.create("subjects", members, dtype=_text(h5py))
        walked = {m: per_subject[m] for m in members if m in per_subject}
        sides = list(dict.fromkeys(side for cycles in walked.values() for side in cycles))
        cycles, spatial = g.create_group("cycles"), {}
        for side in sides:
            by_subject = {m: c[side] for m, c in walked.items() if side in c}
            curves = group_cycles(by_subject)
            c = cycles.create_group(side)
            for key in ("mean", "sd", "n"):
                put(c, key, getattr(curves, key))
            put(c, "subjects", curves.means)
            c.attrs.update({"names": list(curves.names), "units": list(curves.units),
                            "subjects": list(curves.subjects)})
            spatial[side] = group_parameters(by_subject)
        _write_spatiotemporal(g, spatial)
        for side, spread in spatial.items():
            put(g["spatiotemporal"][side], "values", spread.values)


# --- reading -----------------------------------------------------------------------------------

@dataclass(frozen=True)
class Table:
    """Rows of mean, SD and count per spatiotemporal parameter (``PARAMETERS`` order)."""

    mean: np.ndarray
    sd: np.ndarray
    n: np.ndarray


@dataclass(frozen=True)
class TrialResults:
    """A solved trial's quality and trust: frames, trusted frames, every flag of the file with
    its count (``study.flags``), the flag datasets' other attributes as the file states them,
    the fit (mean and max distance of the model points to the markers, mm), the warnings, the
    options and the versions it was solved with, and its gait events and strides (or None)."""

    name: str
    trial: str
    method: str
    frames: int
    trusted: int
    flags: tuple[Flag, ...]
    flag_notes: tuple[tuple[str, str], ...]
    mean_ed_mm: float
    max_ed_mm: float
    warnings: tuple[str, ...]
    options: dict
    versions: dict
    gait: GaitResults | None


@dataclass(frozen=True)
class SubjectResults:
    name: str
    group: str
    template: str
    static: str
    model: str
    mass: float | None
    runs: tuple[str, ...]
    trials: tuple[str, ...]
    cycles: dict[str, SideCycles]
    spatiotemporal: dict[str, Table]
    solved: tuple[TrialResults, ...]


@dataclass(frozen=True)
class GroupResults:
    name: str
    subjects: tuple[str, ...]
    names: dict[str, tuple[str, ...]]
    units: dict[str, tuple[str, ...]]
    mean: dict[str, np.ndarray]
    sd: dict[str, np.ndarray]
    n: dict[str, np.ndarray]
    spatiotemporal: dict[str, Table]


@dataclass(frozen=True)
class StudyResults:
    path: str
    name: str
    text: str
    command: str
    versions: dict[str, str]
    subjects: tuple[SubjectResults, ...]
    groups: tuple[GroupResults, ...]
    errors: tuple[tuple[str, str], ...]


def _strings(values) -> tuple[str, ...]:
    return tuple(v.decode() if isinstance(v, bytes) else str(v) for v in values)


def is_study(path: str | Path) -> bool:
    """Whether a results file is a study's (``fccgrb batch``)."""
    with open_results(path) as h5:
        return h5.attrs.get("kind") == KIND


def check_study_output(path: Path) -> None:
    """An InputError unless ``path`` is absent from an existing folder, or a study file (which
    the batch replaces)."""
    import h5py

    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        raise InputError(f"{path}: the output folder {folder} does not exist")
    if not path.exists():
        return
    regular_file(path, "study file")  # a FIFO would block h5py
    try:
        with h5py.File(path, "r") as h5:
            kind = h5.attrs.get("kind")
    except OSError:
        kind = None
    if kind != KIND:
        raise InputError(f"{path}: exists and is not a study file (written by 'fccgrb "
                         "batch'); choose another output")


def _tables(g) -> dict[str, Table]:
    if "spatiotemporal" not in g:
        return {}
    return {side: Table(s["mean"][()], s["sd"][()], s["n"][()])
            for side, s in g["spatiotemporal"].items()}


def _trial(name: str, g, gait: bool) -> TrialResults:
    ed = g["ed"][()]
    trusted = g["converged"][()]
    ok = trusted & np.isfinite(ed).all(axis=1)
    flags, notes = run_flags(g)
    return TrialResults(
        name=name, trial=str(g.attrs["trial"]), method=str(g.attrs["method"]),
        frames=len(trusted), trusted=int(trusted.sum()), flags=flags, flag_notes=notes,
        mean_ed_mm=1e3 * float(ed[ok].mean()) if ok.any() else float("nan"),
        max_ed_mm=1e3 * float(ed[ok].max()) if ok.any() else float("nan"),
        warnings=_strings(g.attrs["warnings"]), options=json.loads(g.attrs["options"]),
        versions=json.loads(g.attrs["versions"]),
        gait=read_gait(g["gait"]) if gait and "gait" in g else None)


def read_study(path: str | Path, *, trial_gait: bool = True) -> StudyResults:
    """A study file's subjects, groups and errors (the runs stay in the file: ``h5py``);
    without ``trial_gait`` each trial's own events and cycles are left unread (``gait`` None:
    the study's tables need the subjects' pooled cycles only; reading every trial's took
    ~0.4 s of a 50-trial study's 15)."""
    with open_results(path) as h5:
        if h5.attrs.get("kind") != KIND:
            raise InputError(f"{path}: expected a study file (written by 'fccgrb batch')")
        subjects = []
        for name, g in h5["subjects"].items():
            mass = float(g.attrs["mass"])
            subjects.append(SubjectResults(
                name, str(g.attrs["group"]), str(g.attrs["template"]), str(g.attrs["static"]),
                str(g.attrs["model"]), None if np.isnan(mass) else mass,
                _strings(g.attrs["runs"]), _strings(g.attrs["trials"]),
                read_cycles(g) if "cycles" in g else {}, _tables(g),
                tuple(_trial(name, h5["runs"][name], trial_gait)
                      for name in _strings(g.attrs["runs"]))))
        groups = []
        for name, g in h5["groups"].items():
            c = g["cycles"]
            groups.append(GroupResults(
                name, _strings(g.attrs["subjects"]),
                {s: _strings(c[s].attrs["names"]) for s in c},
                {s: _strings(c[s].attrs["units"]) for s in c},
                {s: c[s]["mean"][()] for s in c}, {s: c[s]["sd"][()] for s in c},
                {s: c[s]["n"][()] for s in c}, _tables(g)))
        errors = tuple(zip(_strings(h5["errors/where"][()]),
                           _strings(h5["errors/message"][()]), strict=True))
        return StudyResults(str(path), str(h5.attrs["study"]), str(h5.attrs["study_text"]),
                            str(h5.attrs["command"]), json.loads(h5.attrs["versions"]),
                            tuple(subjects), tuple(groups), errors)

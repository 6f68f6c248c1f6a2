"""A study run as cells (``fccgrb_cli.batch.cells``, the sweep's mechanism): first every subject's
calibration, then every trial of the subjects calibrated, each writing one file of
``OUTPUT.cells/<subject>/``; then the study file from those files (``study.store``).

A cell whose file exists is done: a killed batch, run again, calibrates and solves only what is
missing, and the study file it writes equals an uninterrupted run's outside ``/timings``. A
calibration or trial that fails is collected (where, one line) and listed, never fatal to the
rest; a trial of a subject whose calibration failed is not tried.
"""

from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import Executor
from dataclasses import dataclass, replace
from pathlib import Path

from fccgrb_cli.batch.cells import Job, cells_folder, local_pool, pending, run_jobs
from fccgrb_cli.batch.study.jobs import (
    CalibrationJob,
    TrialSolve,
    calibrate_job,
    calibration_file,
    solve_trial_cell,
    trial_file,
)
from fccgrb_cli.batch.study.spec import Study
from fccgrb_cli.batch.study.store import Solved, write_study
from fccgrb_cli.core.atomic import remove_stale
from fccgrb_cli.core.errors import InputError
from fccgrb_cli.core.lock import exclusive

Progress = Callable[[int, int, str], None]


@dataclass(frozen=True)
class Outcome:
    """Trials solved by this run, trials found done, every failure (where: a subject's name for
    its calibration, else a trial's run name; message) and how many of them are trials."""

    solved: int
    kept: int
    failures: tuple[tuple[str, str], ...]
    failed_trials: int


@dataclass(frozen=True)
class Executors:
    """Where the cells run: ``executor`` (a Dask cluster's, say), else ``workers`` local
    processes (this process alone when 1)."""

    workers: int = 1
    executor: Executor | None = None


def message(error: BaseException) -> str:
    """A failure in one line: an input error as it reads, anything else with its type."""
    text = str(error).strip().splitlines()[0] if str(error).strip() else ""
    return text if isinstance(error, InputError) else f"{type(error).__name__}: {text}"


def _readable_text(path: Path) -> bool:
    try:
        return bool(path.read_text(encoding="utf-8").strip())
    except (OSError, UnicodeDecodeError):
        return False


def _readable_run(path: Path) -> bool:
    import h5py

    try:
        with h5py.File(path, "r") as h5:
            return "runs" in h5 and len(h5["runs"]) == 1 and "cell" in h5.attrs
    except OSError:
        return False


def run_study(study: Study, output: Path, where: Executors = Executors(), *,
              accept_truncated: bool = False, progress: Progress | None = None) -> Outcome:
    """Calibrate and solve what the cells folder lacks, then write ``output``, holding its lock
    throughout (another batch into it is refused at once) after removing the scratch files a
    killed run left in its cells."""
    with exclusive(output, wait=0):
        store = cells_folder(output)
        store.mkdir(exist_ok=True)
        for folder in (store, *(p for p in store.rglob("*") if p.is_dir())):
            remove_stale(folder)
        if where.executor is not None:
            return _run_study(study, output, where.executor, accept_truncated, progress)
        # one pool for the calibrations and the trials: its workers load the kernels once
        with local_pool(where.workers) as pool:
            return _run_study(study, output, pool, accept_truncated, progress)


def _run_study(study: Study, output: Path, pool: Executor | None, accept_truncated: bool,
               progress: Progress | None) -> Outcome:
    store = cells_folder(output)
    failures: dict[str, str] = {}

    def collect(job: Job, error: BaseException | None) -> None:
        if error is not None:
            if not isinstance(error, Exception):
                raise error
            failures[job.name] = message(error)

    def calibrated(job: Job, error: BaseException | None) -> None:
        if error is not None:
            collect(replace(job, name=f"{job.name} (calibration)"), error)

    calibrations = {}
    for s in study.subjects:
        try:
            target = calibration_file(s, store, accept_truncated)
        except OSError as error:
            failures[f"{s.name} (calibration)"] = f"{error.filename}: cannot read it " \
                                                  f"({error.strerror})"
            continue
        calibrations[s.name] = Job(s.name, target, calibrate_job,
                                   (CalibrationJob(s, target, accept_truncated),))
    run_jobs(pending(calibrations.values(), _readable_text), calibrated, executor=pool)
    command = f"fccgrb batch {study.source.name}"
    trials: list[Job] = []
    for s in study.subjects:
        model = calibrations[s.name].target if s.name in calibrations else None
        options = study.options.with_(mapping=s.mapping)
        for trial in s.trials:
            name = s.trial_name(trial)
            if model is None or not model.exists():
                failures[name] = f"not solved: the calibration of {s.name} failed"
                continue
            try:
                target = trial_file(s, model, trial, options, accept_truncated)
            except OSError as error:
                failures[name] = f"{trial}: cannot read it ({error.strerror})"
                continue
            trials.append(Job(name, target, solve_trial_cell, (TrialSolve(
                s.name, name, model, trial, options, target, command, accept_truncated),)))
    todo = pending(trials, _readable_run)
    kept = len(trials) - len(todo)
    finished = kept

    def solved(job: Job, error: BaseException | None) -> None:
        nonlocal finished
        collect(job, error)
        finished += 1
        if progress is not None:
            progress(finished, len(trials), job.name + (" failed" if error else ""))

    if progress is not None and todo:
        progress(finished, len(trials), "")
    run_jobs(todo, solved, executor=pool)
    runs = [s.trial_name(t) for s in study.subjects for t in s.trials]
    order = [*(f"{s.name} (calibration)" for s in study.subjects), *runs]
    listed = tuple((name, failures[name]) for name in order if name in failures)
    write_study(study, output, Solved(
        runs={job.name: job.target for job in trials if job.target.exists()},
        models={name: job.target for name, job in calibrations.items() if job.target.exists()},
        failures=listed), command)
    return Outcome(len(todo) - sum(job.name in failures for job in todo), kept, listed,
                   sum(name in runs for name, _ in listed))

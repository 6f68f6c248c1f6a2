"""What a worker does for a study, each job writing one file of the cells folder atomically (so a
killed batch loses only the jobs it was running, ``fccgrb_cli.batch.cells``): a subject's
calibration
(the personalized model, YAML) and a trial's solve (a results file of one run). Jobs take plain
picklable arguments and read their inputs from paths, so that they run alike in this process, a
local pool or a Dask worker that sees the same file system.
"""

from __future__ import annotations

import hashlib
import json
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from fccgrb_cli.batch.study.spec import SubjectSpec
from fccgrb_cli.core.atomic import atomic_path
from fccgrb_cli.core.blas import single_threaded
from fccgrb_cli.pipeline.options import SolveOptions

CELL_VERSION = 1  # bump when a job's output changes for the same inputs (old cells then rerun)


def digest(*parts: object) -> str:
    """8 hex digits identifying a job's inputs (its file's name carries them, so a study whose
    options, template, map or trial files change — their contents, not only their names — solves
    again instead of reusing old cells)."""
    text = json.dumps([CELL_VERSION, *parts], sort_keys=True, default=str)
    return hashlib.sha1(text.encode()).hexdigest()[:8]


def file_digest(path: Path) -> str:
    """A file's content, as SHA-1 (a trial re-exported under the same name is a new trial)."""
    sha = hashlib.sha1()
    with path.open("rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            sha.update(block)
    return sha.hexdigest()


@dataclass(frozen=True)
class CalibrationJob:
    """A subject's calibration job: the subject as the study gives it, the file to write and
    whether truncated trials are accepted."""

    subject: SubjectSpec
    target: Path
    accept_truncated: bool = False


@dataclass(frozen=True)
class TrialSolve:
    """A trial's solve job: the subject's personalized model (a calibration's file), the trial,
    the options (the subject's label map in them), the run's name and the file to write."""

    subject: str
    run: str
    model: Path
    trial: Path
    options: SolveOptions
    target: Path
    command: str
    accept_truncated: bool = False


def calibration_file(subject: SubjectSpec, store: Path, accept_truncated: bool) -> Path:
    """Where a subject's personalized model is kept (named by a digest of what makes it)."""
    key = digest(file_digest(subject.template), str(subject.static), file_digest(subject.static),
                 subject.frames, subject.mass, subject.measurements, subject.mapping,
                 accept_truncated)
    return store / subject.name / f"model-{key}.yaml"


def trial_file(subject: SubjectSpec, model: Path, trial: Path, options: SolveOptions,
               accept_truncated: bool) -> Path:
    """Where a trial's run is kept: named by the trial and a digest of the model file (itself
    named by its inputs), the trial's path and content, and the options."""
    key = digest(model.name, str(trial), file_digest(trial), options.to_json(), accept_truncated)
    return model.parent / f"{trial.stem}-{key}.h5"


@single_threaded
def calibrate_job(job: CalibrationJob) -> None:
    """Personalize the subject's template from its static trial with its mass and measurements
    by ``pipeline.calibration.calibrate_subject``, as ``fccgrb calibrate`` and the API do (the
    static's PROCESSING group read first, the study's values over it), and write the model."""
    from fccgrb_cli.model import load_model
    from fccgrb_cli.pipeline.calibration import Choices, Subject, calibrate_subject
    from fccgrb_cli.trial.record import read_trial

    s = job.subject
    template = load_model(s.template)
    static = read_trial(s.static, job.accept_truncated)
    given: dict[str, Any] = dict(s.measurements) if isinstance(s.measurements, tuple) else {}
    subject = Subject.from_mm(s.mass, **given)
    done = calibrate_subject(template, static, subject,
                             Choices(s.frames, mapping=dict(s.mapping)),
                             source=f"{s.name}'s personalized {template.name}")
    job.target.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(job.target) as tmp:
        tmp.write_text(done.text, encoding="utf-8")


@single_threaded
def solve_trial_cell(job: TrialSolve) -> None:
    """Solve one trial with the subject's model and write its run (``fccgrb solve``'s steps);
    the solve's wall time goes into the cell's attributes, kept apart from the results when the
    study file is made. BLAS runs on one thread throughout, as in ``fccgrb solve``: a worker
    whose numpy was loaded before this package (a Dask worker, a test process) would otherwise
    run the dynamics stage's products on several, and their last bits differ with the thread
    count."""
    from fccgrb_cli.model import load_model
    from fccgrb_cli.pipeline.solve import solve_trial
    from fccgrb_cli.results.storage import write_run
    from fccgrb_cli.trial.record import read_trial

    model = load_model(job.model)
    started = time.perf_counter()
    trial = read_trial(job.trial, job.accept_truncated)
    run = solve_trial(model, trial, job.options, spill=job.target.parent)
    elapsed = time.perf_counter() - started
    write_run(job.target, replace(run, name=job.run), job.command,
              cell={"subject": job.subject, "run": job.run, "solve_s": elapsed})

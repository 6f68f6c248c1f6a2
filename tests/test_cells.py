"""``batch.cells``' local pool, shared by several runs of jobs in turn (a study's calibrations,
then its trials): the same workers serve both, and a worker that dies fails only the jobs
then in the pool, as a pool of their own would have."""

from __future__ import annotations

import os
import signal
import sys
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path

import pytest

from fccgrb_cli.batch.cells import Job, local_pool, run_jobs

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="fork, SIGKILL")


def _write_pid(path: Path) -> None:
    path.write_text(str(os.getpid()), encoding="utf-8")


def _die(path: Path) -> None:
    os.kill(os.getpid(), signal.SIGKILL)


def _jobs(folder: Path, prefix: str, count: int, function=_write_pid) -> list[Job]:
    return [Job(f"{prefix}{k}", folder / f"{prefix}{k}", function, (folder / f"{prefix}{k}",))
            for k in range(count)]


def test_runs_in_turn_share_the_pools_workers(tmp_path: Path) -> None:
    errors: dict[str, BaseException | None] = {}
    with local_pool(2) as pool:
        first, second = _jobs(tmp_path, "first", 4), _jobs(tmp_path, "second", 4)
        run_jobs(first, lambda job, error: errors.__setitem__(job.name, error), executor=pool)
        run_jobs(second, lambda job, error: errors.__setitem__(job.name, error), executor=pool)
    assert set(errors.values()) == {None}
    pids = {job.name: int(job.target.read_text()) for job in first + second}
    assert os.getpid() not in pids.values()
    assert {pids[job.name] for job in second} <= {pids[job.name] for job in first}


def test_a_dead_worker_fails_only_the_jobs_then_in_the_pool(tmp_path: Path) -> None:
    """A calibration whose worker dies (a crash, the OOM killer) is that calibration's
    failure; the trials after it run. The broken pool made every later submit raise, and
    the whole study ended in BrokenProcessPool."""
    errors: dict[str, BaseException | None] = {}
    with local_pool(2) as pool:
        run_jobs(_jobs(tmp_path, "dies", 1, _die),
                 lambda job, error: errors.__setitem__(job.name, error), executor=pool)
        after = _jobs(tmp_path, "after", 3)
        run_jobs(after, lambda job, error: errors.__setitem__(job.name, error), executor=pool)
    assert isinstance(errors.pop("dies0"), BrokenProcessPool)
    assert errors == {job.name: None for job in after}
    assert all(job.target.exists() for job in after)

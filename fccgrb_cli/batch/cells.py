"""Resumable work in cells: each job writes one file (a sweep's cell, a study's calibration or
trial) atomically, so a job whose file exists is done and a killed run loses only the jobs it was
running. One executor path for every batch command (``fccgrb sweep``, ``fccgrb batch``): the
jobs run in this process, over a local process pool, or over any ``concurrent.futures``
executor — a Dask cluster's (``Client.get_executor()``) included — and the numbers do not depend
on which (the same function runs on the same inputs).
"""

from __future__ import annotations

import contextlib
import os
import shutil
from collections.abc import Callable, Iterable, Iterator, Sequence
from concurrent.futures import Executor, Future, ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from fccgrb_cli.core import scratch

Done = Callable[["Job", "BaseException | None"], None]


@dataclass(frozen=True)
class Job:
    """One cell: ``function(*args)`` writes ``target`` (atomically: a file that exists is whole).
    ``alone``: run in this process after the pooled jobs, one at a time (a job that spreads over
    its own processes, whose timing must not be shared)."""

    name: str
    target: Path
    function: Callable[..., Any]
    args: tuple = ()
    alone: bool = False


def cells_folder(output: Path) -> Path:
    """Where the finished cells of a command writing ``output`` are kept."""
    return output.with_name(output.name + ".cells")


def remove_cells(output: Path) -> None:
    """Forget the finished cells of ``output`` (for a clean rerun)."""
    shutil.rmtree(cells_folder(output), ignore_errors=True)


def pending(jobs: Iterable[Job], readable: Callable[[Path], bool],
            forget: Callable[[Path], None] | None = None) -> list[Job]:
    """The jobs still to run: those whose file is absent, or present but not ``readable`` (then
    removed, after ``forget(path)`` is told; files are renamed into place whole, so only
    something outside the run can break one)."""
    todo = []
    for job in jobs:
        if job.target.exists() and not readable(job.target):
            if forget is not None:
                forget(job.target)
            job.target.unlink()
        if not job.target.exists():
            todo.append(job)
    return todo


class _LocalPool(Executor):
    """``workers`` processes that end with this one (``scratch``), replaced by fresh ones when
    a worker died (a crash, the OOM killer, kill -9): the jobs then in the pool fail with
    BrokenProcessPool, and the jobs submitted after it run, as in a pool of their own."""

    def __init__(self, workers: int) -> None:
        self._workers = workers
        self._pool = self._started()

    def _started(self) -> ProcessPoolExecutor:
        return ProcessPoolExecutor(max_workers=self._workers,
                                   initializer=scratch.die_with_parent, initargs=(os.getpid(),))

    def submit(self, fn: Callable[..., Any], /, *args: Any,
               **kwargs: Any) -> Future[Any]:
        try:
            return self._pool.submit(fn, *args, **kwargs)
        except BrokenProcessPool:
            self._pool.shutdown()
            self._pool = self._started()
            return self._pool.submit(fn, *args, **kwargs)

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
        self._pool.shutdown(wait=wait, cancel_futures=cancel_futures)


@contextlib.contextmanager
def local_pool(workers: int) -> Iterator[Executor | None]:
    """A pool of ``workers`` processes that end with this one (``scratch``), for one or several
    :func:`run_jobs` in turn: its workers keep what they loaded (the compiled kernels) from one
    to the next, and a worker's death fails only the jobs then in the pool (the next are run
    by fresh workers). None when ``workers`` is 1 (the jobs run in this process). Left, it
    cancels the jobs not started."""
    if workers <= 1:
        yield None
        return
    pool = _LocalPool(workers)
    try:
        yield pool
    finally:
        pool.shutdown(cancel_futures=True)


def run_jobs(jobs: Sequence[Job], done: Done, *, workers: int = 1,
             executor: Executor | None = None) -> None:
    """Run ``jobs``: the pooled ones over ``executor``, else over a :func:`local_pool` of
    ``workers`` processes (in this process when ``workers`` is 1), then the ``alone`` ones
    here. After each, ``done(job, error)`` (error None when it succeeded; ``done`` re-raises
    what should stop the run: the remaining local jobs are cancelled)."""
    pooled = [job for job in jobs if not job.alone]
    if pooled:
        with contextlib.ExitStack() as stack:
            pool = executor if executor is not None else stack.enter_context(
                local_pool(workers))
            if pool is None:
                for job in pooled:
                    _run_here(job, done)
            else:
                futures = {pool.submit(job.function, *job.args): job for job in pooled}
                for future in as_completed(futures):
                    done(futures[future], future.exception())
    for job in jobs:
        if job.alone:
            _run_here(job, done)


def _run_here(job: Job, done: Done) -> None:
    try:
        job.function(*job.args)
    except Exception as error:  # a job's failure is the caller's to judge (done)
        done(job, error)
        return
    done(job, None)

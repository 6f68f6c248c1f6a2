"""The compiled kernels' start-up, kept apart from the per-frame figures: each kernel is loaded
(or compiled) by an empty call before any clock starts, a compile says so on stderr while it
lasts, ``fccgrb solve`` reports the load apart, and ``fccgrb compile`` compiles ahead of time."""

from __future__ import annotations

import time
from collections import Counter
from pathlib import Path
from types import SimpleNamespace

import pytest
from cli_helpers import run_cli

from fccgrb_cli.solvers import engine
from fccgrb_cli.solvers.engine import KernelClock, numba_available, ready

ROOT = Path(__file__).resolve().parents[1]
MODEL = ROOT / "configs" / "models" / "five_bar.yaml"
TRIAL = ROOT / "sample_data" / "five_bar.c3d"


class SlowKernel:
    """A stand-in for a numba dispatcher that takes ``seconds`` and did (not) compile."""

    __module__ = "fake"
    __name__ = "kernel"

    def __init__(self, seconds: float, compiled: bool) -> None:
        self.seconds = seconds
        self.calls: list[tuple] = []
        self.stats = SimpleNamespace(cache_misses=Counter({"sig": 1} if compiled else {}))

    def __call__(self, *args) -> None:
        self.calls.append(args)
        time.sleep(self.seconds)


def test_a_compile_says_so_while_it_lasts_and_its_time_is_kept_apart(monkeypatch, capsys):
    monkeypatch.setattr(engine, "NOTICE_AFTER", 0.02)
    monkeypatch.setattr(engine, "REPORT_EVERY", 0.05)
    monkeypatch.setattr(engine, "_COMPILED", set())
    monkeypatch.setattr(KernelClock, "told", False)
    KernelClock.take()
    kernel = SlowKernel(0.3, compiled=True)
    seconds = ready(kernel, "s", 0, 0)
    assert kernel.calls == [("s", 0, 0)]
    err = capsys.readouterr().err.splitlines()
    assert err[0].startswith("fccgrb: compiling the compiled kernels")
    assert "fccgrb compile" in err[0]
    assert len(err) >= 2 and all(line.startswith("fccgrb: compiling …") for line in err[1:])
    taken, compiled = KernelClock.take()
    assert taken == pytest.approx(seconds) and seconds >= 0.3
    assert compiled == ["fake.kernel"]
    assert KernelClock.take() == (0.0, [])
    ready(SlowKernel(0.3, compiled=True))  # a second kernel: its progress, not the notice again
    again = capsys.readouterr().err.splitlines()
    assert again and all(line.startswith("fccgrb: compiling …") for line in again)


def test_a_load_from_the_cache_says_nothing(monkeypatch, capsys):
    monkeypatch.setattr(engine, "NOTICE_AFTER", 5.0)
    KernelClock.take()
    ready(SlowKernel(0.0, compiled=False))
    assert capsys.readouterr().err == ""
    seconds, compiled = KernelClock.take()
    assert seconds > 0.0 and compiled == []


@pytest.mark.skipif(not numba_available(), reason="numba is not installed")
def test_solve_reports_the_kernels_load_apart_and_compile_prepares_them(tmp_path):
    compiled = run_cli("compile")
    assert compiled.exit_code == 0, compiled.output
    assert compiled.output.splitlines()[-1].startswith("compiled kernels ready")
    out = run_cli("solve", MODEL, TRIAL, "--engine", "compiled", "-o", tmp_path / "c.h5")
    assert out.exit_code == 0, out.output
    lines = [line for line in out.stderr.splitlines() if "compiled kernels" in line]
    assert len(lines) == 1 and "not in ms/frame" in lines[0], out.stderr
    numpy = run_cli("solve", MODEL, TRIAL, "--engine", "numpy", "-o", tmp_path / "n.h5")
    assert numpy.exit_code == 0, numpy.output
    assert "compiled kernels" not in numpy.stderr


# A numba dispatcher that gains a compiled overload (loaded from numba's cache, or compiled) in
# a process: one line "pid kernel" in FCCGRB_LOAD_LOG. As a sitecustomize, every process of
# the command counts, whichever way a pool starts its workers.
_COUNTING = """
import os

from numba.core import dispatcher

_compile = dispatcher.Dispatcher.compile


def compile(self, sig):
    before = len(self.overloads)
    out = _compile(self, sig)
    if len(self.overloads) > before:
        with open(os.environ["FCCGRB_LOAD_LOG"], "a") as log:
            log.write(f"{os.getpid()} {self.py_func.__module__}.{self.py_func.__qualname__}\\n")
    return out


dispatcher.Dispatcher.compile = compile
"""


def _loads(tmp_path: Path, *args: object) -> list[tuple[str, str]]:
    """(pid, kernel) of every kernel load of an ``fccgrb`` command run in a fresh process."""
    import os
    import shutil
    import subprocess

    log = tmp_path / "loads.txt"
    log.write_text("")
    hook = tmp_path / "hook"
    hook.mkdir(exist_ok=True)
    (hook / "sitecustomize.py").write_text(_COUNTING)
    env = {**os.environ, "FCCGRB_LOAD_LOG": str(log),
           "PYTHONPATH": os.pathsep.join([str(hook), os.environ.get("PYTHONPATH", "")])}
    done = subprocess.run([shutil.which("fccgrb") or "fccgrb", *map(str, args)],
                          capture_output=True, text=True, cwd=ROOT, env=env)
    assert done.returncode == 0, done.stderr
    return [tuple(line.split()) for line in log.read_text().splitlines()]


@pytest.mark.skipif(not numba_available(), reason="numba is not installed")
def test_batches_load_each_kernel_once_per_process(tmp_path):
    """A sweep of 6 compiled cells over 2 workers loads each kernel at most once in each
    process, in at most the 2 workers and the parent (a pool that started a process per cell,
    or a dispatcher rebuilt per solve, would load it again); one solve of several trials loads
    each kernel once."""
    import yaml

    config = tmp_path / "sweep.yaml"
    config.write_text(yaml.safe_dump({
        "name": "loads", "model": str(ROOT / "configs" / "models" / "pendulum.yaml"),
        "trial": {"synth": {"duration": 0.5, "rate": 100}}, "seed": 0,
        "cells": [{"smooth": "none", "method": ["nrm-ls", "nrm-wls", "cno-sqp"],
                   "level": [0, 30], "engine": "compiled"}]}))
    loads = _loads(tmp_path, "sweep", config, "-o", tmp_path / "sweep.h5", "--workers", "2")
    assert loads, "no kernel loaded: the sweep did not run compiled"
    assert len(set(loads)) == len(loads), sorted(loads)
    assert len({pid for pid, _ in loads}) <= 3
    kernels = {kernel for _, kernel in loads}
    assert any(kernel.endswith("solve_frames") for kernel in kernels), kernels

    trials = []
    for k in range(3):
        trials.append(tmp_path / f"t{k}.c3d")
        ok = run_cli("synth", MODEL, "-o", trials[-1], "--duration", 0.3 + 0.1 * k)
        assert ok.exit_code == 0, ok.output
    loads = _loads(tmp_path, "solve", MODEL, *trials, "-o", tmp_path / "trials.h5",
                   "--engine", "compiled")
    assert loads and len(set(loads)) == len(loads), sorted(loads)
    assert len({pid for pid, _ in loads}) == 1


_LIGHT = """
from numba.core import base
refreshed = []
full = base.BaseContext.refresh
base.BaseContext.refresh = lambda self: refreshed.append(1) or full(self)
from fccgrb_cli.pipeline.precompile import precompile
precompile()
print("refreshed" if refreshed else "light")
"""


@pytest.mark.skipif(not numba_available(), reason="numba is not installed")
def test_kernels_load_without_numbas_full_refresh(tmp_path):
    """Every compiled path (``fccgrb compile``'s passes: NRM, the optimizers, the smoother, the
    classical and the imported model's inverse dynamics) runs in a fresh process whose kernels
    all came from the cache on the light path (``engine.light_loads``: numba's context never
    refreshed), and a solve writes the same bits as one in a process that
    refreshed numba's context in full first."""
    import os
    import subprocess
    import sys

    env = {**os.environ, "FCCGRB_BACKGROUND_COMPILE": "0"}
    subprocess.run([sys.executable, "-c", _LIGHT], capture_output=True, text=True, env=env)
    done = subprocess.run([sys.executable, "-c", _LIGHT], capture_output=True, text=True,
                          env=env)  # the cache warm: every kernel loads
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["light"], done.stdout
    outputs = []
    for first in ("", "from numba.core.registry import cpu_target; "
                      "cpu_target.target_context.refresh(); "):
        out = tmp_path / f"r{len(outputs)}.h5"
        code = (f"import sys; {first}from fccgrb_cli.entry import run; sys.argv = ['fccgrb', "
                f"'solve', {str(MODEL)!r}, {str(TRIAL)!r}, '--perturb', '30', '--engine', "
                f"'compiled', '-o', {str(out)!r}]; run()")
        done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                              env=env)
        assert done.returncode == 0, done.stderr
        outputs.append(out)
    import h5py
    import numpy as np

    with h5py.File(outputs[0]) as a, h5py.File(outputs[1]) as b:
        (name,) = a["runs"]
        for key in ("q", "qd", "qdd", "joint_moments", "lambda", "iterations"):
            assert np.array_equal(a["runs"][name][key][()], b["runs"][name][key][()],
                                  equal_nan=True), key


@pytest.mark.parametrize(("code", "status", "said"), [(None, 0, ""), (3, 3, ""),
                                                       ("'no such file'", 1, "no such file")])
def test_the_program_leaves_with_its_status_its_output_and_its_cleanup(tmp_path, code, status,
                                                                        said):
    """``entry.leave`` (the program's exit without the interpreter's teardown) keeps what an
    ordinary exit does: the status (a text said on stderr, then 1), stdout's buffered output,
    and the atexit handlers (a temporary folder still open is removed)."""
    import os
    import subprocess
    import sys

    script = ("import tempfile; from fccgrb_cli.entry import leave; "
              "folder = tempfile.TemporaryDirectory(); print(folder.name); "
              f"print('buffered', end=''); leave({code})")
    env = {k: v for k, v in os.environ.items() if k != "PYTHONUNBUFFERED"}  # stdout buffered
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          env=env)
    folder, rest = done.stdout.split("\n", 1)
    assert done.returncode == status
    assert rest == "buffered"
    assert done.stderr.strip() == said
    assert not Path(folder).exists()

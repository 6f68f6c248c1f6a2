"""Faults a user's machine inflicts, on real ``fccgrb`` processes: Ctrl-C, SIGTERM and kill -9
at each stage of a solve and of a sweep, a sweep's parent killed alone, two solves writing one
results file at once, and a full disk (``ulimit -f``, and a 6 MB tmpfs when run as root).

After each: the exit status (130 for SIGINT, 143 for SIGTERM, 2 for a full disk) with one
``fccgrb: error:`` line, no scratch file left (``.tmp``, ``.fccgrb-spill-*``, a lock), an
existing results file bit for bit as it was, no worker left running; a rerun after a kill -9
finishes and cleans what the kill left. ``FCCGRB_FAULT_ROUNDS=6 python -m pytest
tests/test_faults.py`` repeats the racy ones (signals at random moments, concurrent writers).
"""

from __future__ import annotations

import hashlib
import os
import random
import resource
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import pytest
from fuzz.fixtures import MODELS, command, environment

ROUNDS = int(os.environ.get("FCCGRB_FAULT_ROUNDS", "1"))
FULL = ROUNDS > 1  # the longer variants too
SCRATCH = (".tmp", ".lock", ".fccgrb-spill-")
pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="POSIX signals")


def _child_setup(limit: int | None = None):
    def setup() -> None:
        os.setsid()  # its own process group, as a shell's job
        signal.signal(signal.SIGINT, signal.SIG_DFL)  # a background pytest may ignore it
        if limit is not None:
            resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
    return setup


def start(args: list[str], cwd: Path, limit: int | None = None) -> subprocess.Popen:
    return subprocess.Popen([*command(), *args], cwd=cwd, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=environment(),
                            preexec_fn=_child_setup(limit))


def run(args: list[str], cwd: Path, limit: int | None = None,
        timeout: float = 300) -> subprocess.CompletedProcess:
    process = start(args, cwd, limit)
    out, err = process.communicate(timeout=timeout)
    return subprocess.CompletedProcess(args, process.returncode, out, err)


def scratch_files(folder: Path) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*")
                  if any(mark in p.name for mark in SCRATCH))


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def one_error(stderr: str) -> str:
    lines = [line for line in stderr.splitlines() if line.startswith("fccgrb: error:")]
    assert len(lines) == 1, stderr
    assert "Traceback" not in stderr and "Exception ignored" not in stderr, stderr
    return lines[0]


def wait_for(predicate, process: subprocess.Popen, timeout: float = 120) -> bool:
    """Poll until ``predicate()`` or the process ends; whether the predicate came true."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        if process.poll() is not None:
            return False
        time.sleep(0.002)
    return False


@pytest.fixture(scope="module")
def lab(tmp_path_factory) -> Path:
    """The five-bar, a 600-frame trial of it (t.c3d) and a 100-frame one (short.c3d), and
    results holding one run."""
    folder = tmp_path_factory.mktemp("faults")
    (folder / "model.yaml").write_bytes((MODELS / "five_bar.yaml").read_bytes())
    for name, seconds in (("t", "6"), ("short", "1")):
        done = run(["synth", "model.yaml", "-o", f"{name}.c3d", "--duration", seconds], folder)
        assert done.returncode == 0, done.stderr
    done = run(["solve", "model.yaml", "t.c3d", "-o", "r.h5", "--method", "nrm-ls"], folder)
    assert done.returncode == 0, done.stderr
    return folder


def copy_lab(lab: Path, to: Path) -> Path:
    to.mkdir()
    for name in ("model.yaml", "t.c3d", "t.truth.h5", "short.c3d", "short.truth.h5", "r.h5"):
        (to / name).write_bytes((lab / name).read_bytes())
    return to


SLOW = ["--method", "cno-sqp", "--optimizer", "scipy"]  # ~10 ms a frame: seconds to interrupt
FAST = ["--method", "nrm-ls"]


def stage_reached(folder: Path, stage: str):
    """Predicates for the stages of a solve into r.h5: starting (a moment after the process
    began: still loading, or reading the model), solving (its scratch file for the largest
    arrays exists: the frames are being solved), the results being written."""
    started = time.monotonic()
    if stage == "starting":
        return lambda: time.monotonic() - started > 0.3
    if stage == "solving":
        return lambda: any(p.name.startswith(".fccgrb-spill-") for p in folder.iterdir())
    return lambda: any(p.name.startswith(".r.h5.") and ".tmp" in p.name
                       for p in folder.iterdir())


@pytest.mark.parametrize("stage", ["starting", "solving", "writing"])
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_a_signal_stops_a_solve_and_leaves_nothing(lab: Path, tmp_path: Path, sig: int,
                                                   stage: str) -> None:
    for k in range(ROUNDS):
        folder = copy_lab(lab, tmp_path / f"round{k}")
        before = digest(folder / "r.h5")
        method = FAST if stage == "writing" else SLOW
        process = start(["solve", "model.yaml", "t.c3d", "-o", "r.h5", "--name", "new", *method],
                        folder)
        reached = wait_for(stage_reached(folder, stage), process)
        if k:  # later rounds: a random moment after the stage began
            time.sleep(random.uniform(0, 0.05))
        process.send_signal(sig)
        _, err = process.communicate(timeout=120)
        if not reached and process.returncode == 0:
            pytest.skip(f"the solve finished before the stage {stage!r} could be caught")
        assert process.returncode == 128 + sig, (process.returncode, err)
        assert "interrupted" in one_error(err)
        assert digest(folder / "r.h5") == before
        assert scratch_files(folder) == []


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_a_signal_inside_stdouts_own_flush_still_ends_in_one_line(tmp_path: Path,
                                                                  sig: int) -> None:
    """Python runs a signal's handler between a buffered writer's raw writes, with the
    writer's lock held; the handler's own flush of stdout then raises "reentrant call". Seen
    as a served command answering SIGTERM with that error and status 1 just after it printed.
    Here the raw write itself sends the signal, so the handler always runs inside the flush."""
    script = f"""
import io, os, signal, sys
from fccgrb_cli.core import scratch
scratch.install()
scratch.create({str(tmp_path)!r}, "being-written-", ".h5")
class Raw(io.RawIOBase):
    def writable(self):
        return True
    def write(self, data):
        os.kill(os.getpid(), {int(sig)})
        return len(data)
sys.stdout = io.TextIOWrapper(io.BufferedWriter(Raw()))
print("ready", flush=True)
"""
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          env=environment(), timeout=60, preexec_fn=_child_setup())
    name = signal.Signals(sig).name
    assert done.returncode == 128 + sig, done.stderr
    assert done.stderr == f"fccgrb: error: interrupted by {name}; the files being written " \
                          "were removed\n"
    assert not list(tmp_path.glob("being-written-*"))


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_a_signal_with_stdout_closed_still_ends_in_one_line(tmp_path: Path, sig: int) -> None:
    """A command started with descriptor 1 closed (``>&-``) has no sys.stdout (None): its
    signal handler, which flushes stdout before its line, ended in a traceback and status 1."""
    script = f"""
import os, signal, sys, time
from fccgrb_cli.core import scratch
assert sys.stdout is None
scratch.install()
scratch.create({str(tmp_path)!r}, "being-written-", ".h5")
os.kill(os.getpid(), {int(sig)})
time.sleep(10)
"""
    done = subprocess.run(["sh", "-c", 'exec "$0" "$@" >&-', sys.executable, "-c", script],
                          stderr=subprocess.PIPE, text=True, env=environment(), timeout=60,
                          preexec_fn=_child_setup())
    name = signal.Signals(sig).name
    assert done.returncode == 128 + sig, done.stderr
    assert done.stderr == f"fccgrb: error: interrupted by {name}; the files being written " \
                          "were removed\n"
    assert not list(tmp_path.glob("being-written-*"))


@pytest.mark.parametrize("closed", ["<&-", ">&-", "2>&-"])
def test_a_command_started_with_a_standard_descriptor_closed_runs(lab: Path, tmp_path: Path,
                                                                  closed: str) -> None:
    """Started with stdin, stdout or stderr closed (``>&-``, a daemon's): Python gives it no
    stream there (None), and the progress bar's ``sys.stderr.isatty()`` or the exit's flush
    failed the command with status 1, without its results. It runs as on /dev/null; a bad
    input is still status 2."""
    folder = copy_lab(lab, tmp_path / "lab")
    shell = ["sh", "-c", f'exec "$0" "$@" {closed}', *command()]
    done = subprocess.run([*shell, "solve", "model.yaml", "short.c3d", "-o", "new.h5",
                           "--method", "nrm-ls"], cwd=folder, capture_output=True, text=True,
                          env=environment(), timeout=300)
    assert done.returncode == 0, done.stderr
    with h5py.File(folder / "new.h5", "r") as h5:
        assert len(h5["runs"]) == 1
    done = subprocess.run([*shell, "solve", "absent.yaml", "short.c3d", "-o", "bad.h5"],
                          cwd=folder, capture_output=True, text=True, env=environment(),
                          timeout=300)
    assert done.returncode == 2, done.stderr
    if closed != "2>&-":
        assert one_error(done.stderr).startswith("fccgrb: error:")


def test_kill_9_of_a_solve_is_cleaned_by_the_next_solve(lab: Path, tmp_path: Path) -> None:
    """kill -9 leaves its scratch files (nothing can remove them); the next write of the same
    results file removes those of processes that no longer run, and adds its run."""
    folder = copy_lab(lab, tmp_path / "k")
    before = digest(folder / "r.h5")
    process = start(["solve", "model.yaml", "t.c3d", "-o", "r.h5", "--name", "new", *FAST],
                    folder)
    assert wait_for(stage_reached(folder, "solving"), process)
    os.killpg(process.pid, signal.SIGKILL)
    process.communicate()
    assert digest(folder / "r.h5") == before
    assert scratch_files(folder), "the kill -9 came too late to leave anything"
    again = run(["solve", "model.yaml", "t.c3d", "-o", "r.h5", "--name", "again"], folder)
    assert again.returncode == 0, again.stderr
    assert scratch_files(folder) == []
    with h5py.File(folder / "r.h5", "r") as h5:
        assert sorted(h5["runs"]) == ["again", "nrm-ls"]


def test_two_solves_into_one_file_keep_both_runs(lab: Path, tmp_path: Path) -> None:
    for k in range(2 * ROUNDS):
        folder = copy_lab(lab, tmp_path / f"round{k}")
        processes = [start(["solve", "model.yaml", "t.c3d", "-o", "r.h5", "--name", name,
                            "--method", "nrm-ls"], folder) for name in ("a", "b")]
        for process in processes:
            _, err = process.communicate(timeout=300)
            assert process.returncode == 0, err
        with h5py.File(folder / "r.h5", "r") as h5:
            assert sorted(h5["runs"]) == ["a", "b", "nrm-ls"]
        assert scratch_files(folder) == []


@pytest.mark.parametrize("existing", [False, True])
def test_a_full_disk_is_one_line_and_leaves_everything_as_it_was(lab: Path, tmp_path: Path,
                                                                 existing: bool) -> None:
    """``ulimit -f``: every file this process writes stops at the limit (EFBIG)."""
    folder = copy_lab(lab, tmp_path / "f")
    if not existing:
        (folder / "r.h5").unlink()
    files = sorted(p.name for p in folder.iterdir())
    size = (lab / "r.h5").stat().st_size
    limits = (4096, size // 3, size - 4096, size + size // 3) if FULL else (size // 3,
                                                                            size - 4096)
    for limit in limits:
        before = digest(folder / "r.h5") if existing else None
        done = run(["solve", "model.yaml", "t.c3d", "-o", "r.h5", "--name", "new"], folder,
                   limit=limit)
        if done.returncode == 0:  # the limit left room for it: start again from the lab's
            (folder / "r.h5").unlink()
            if existing:
                (folder / "r.h5").write_bytes((lab / "r.h5").read_bytes())
            continue
        assert done.returncode == 2, done.stderr
        assert "file size limit" in one_error(done.stderr)
        assert sorted(p.name for p in folder.iterdir()) == files
        if existing:
            assert digest(folder / "r.h5") == before
    for args in (["synth", "model.yaml", "-o", "s.c3d"], ["perturb", "t.c3d", "p.c3d",
                                                            "--level", "1"]):
        done = run(args, folder, limit=8192)
        assert done.returncode == 2, done.stderr
        assert "file size limit" in one_error(done.stderr)
        assert sorted(p.name for p in folder.iterdir()) == files


@pytest.mark.skipif(not FULL or os.geteuid() != 0, reason="FCCGRB_FAULT_ROUNDS > 1, as root")
def test_a_full_tmpfs_is_one_line_and_leaves_everything_as_it_was(lab: Path,
                                                                  tmp_path: Path) -> None:
    """A 6 MB file system filled to leave less and less room: every solve, synth and perturb
    succeeds or fails with one line, leaving the results file as it was and nothing else."""
    disk = tmp_path / "disk"
    disk.mkdir()
    if subprocess.run(["mount", "-t", "tmpfs", "-o", "size=6m", "tmpfs", str(disk)],
                      capture_output=True).returncode != 0:
        pytest.skip("cannot mount a tmpfs here")
    try:
        for name in ("model.yaml", "t.c3d", "t.truth.h5", "r.h5"):
            (disk / name).write_bytes((lab / name).read_bytes())
        files = sorted([*(p.name for p in disk.iterdir()), "fill"])
        free = os.statvfs(disk).f_bavail * os.statvfs(disk).f_frsize
        for used in range(0, free, free // 12):
            (disk / "fill").write_bytes(bytes(used))
            before = digest(disk / "r.h5")
            for args in (["solve", "model.yaml", "t.c3d", "-o", "r.h5", "--name", "new"],
                         ["synth", "model.yaml", "-o", "s.c3d"],
                         ["perturb", "t.c3d", "p.c3d", "--level", "1"]):
                done = run(args, disk)
                if done.returncode == 0:
                    for name in ("s.c3d", "s.truth.h5", "p.c3d", "p.truth.h5"):
                        (disk / name).unlink(missing_ok=True)
                    (disk / "r.h5").write_bytes((lab / "r.h5").read_bytes())
                    continue
                assert done.returncode == 2, done.stderr
                assert "the disk is full" in one_error(done.stderr)
                assert sorted(p.name for p in disk.iterdir()) == files
                assert digest(disk / "r.h5") == before
    finally:
        subprocess.run(["umount", str(disk)], check=False)


SWEEP = """name: sw
model: model.yaml
trial: {file: short.c3d}
cells:
  - {method: nrm-ls, level: [0, 1, 2, 3, 4, 5, 6, 7]}
"""


def workers_of(pid: int) -> list[int]:
    try:
        children = Path(f"/proc/{pid}/task/{pid}/children").read_text().split()
    except OSError:
        return []
    return [int(c) for c in children]


def gone(pids: list[int], timeout: float = 10) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        alive = [p for p in pids if Path(f"/proc/{p}").exists()
                 and "zombie" not in Path(f"/proc/{p}/status").read_text().lower()]
        if not alive:
            return True
        time.sleep(0.05)
    return False


@pytest.mark.parametrize("how", ["parent-sigkill", "sigint", *(["group-sigkill", "sigterm"]
                                                                if FULL else [])])
def test_a_killed_sweep_leaves_nothing_a_rerun_does_not_clean(lab: Path, tmp_path: Path,
                                                              how: str) -> None:
    folder = copy_lab(lab, tmp_path / "s")
    (folder / "s.yaml").write_text(SWEEP, encoding="utf-8")
    cells = folder / "s.h5.cells"
    process = start(["sweep", "s.yaml", "-o", "s.h5", "--workers", "2"], folder)
    assert wait_for(lambda: len(workers_of(process.pid)) >= 2 and cells.is_dir()
                    and any(p.name.endswith(".tmp") for p in cells.iterdir()), process)
    workers = workers_of(process.pid)
    if how == "parent-sigkill":
        os.kill(process.pid, signal.SIGKILL)
    elif how == "group-sigkill":
        os.killpg(process.pid, signal.SIGKILL)
    else:
        os.kill(process.pid, signal.SIGINT if how == "sigint" else signal.SIGTERM)
    _, err = process.communicate(timeout=60)
    assert gone(workers), f"workers {workers} outlived their parent"
    if how in ("sigint", "sigterm"):
        assert process.returncode == 128 + (2 if how == "sigint" else 15), err
        assert "interrupted" in one_error(err)
    assert not (folder / "s.h5").exists()
    if how in ("sigint", "sigterm"):
        assert scratch_files(folder) == [], scratch_files(folder)
    elif how == "parent-sigkill":  # the parent's lock stays; its workers removed theirs
        assert scratch_files(cells) == [], scratch_files(cells)
    again = run(["sweep", "s.yaml", "-o", "s.h5", "--workers", "2"], folder)
    assert again.returncode == 0, again.stderr
    assert scratch_files(folder) == []
    with h5py.File(folder / "s.h5", "r") as h5:
        assert len(h5["cells"]) == 8


def test_a_sweep_on_a_full_disk_is_one_line_and_leaves_nothing(lab: Path, tmp_path: Path) -> None:
    """``ulimit -f`` too small for one cell's file: exit 2, one error line, and no output and
    no ``.cells`` folder left (the folder the run made held no finished cell)."""
    folder = copy_lab(lab, tmp_path / "s")
    (folder / "s.yaml").write_text(SWEEP.replace("level: [0, 1, 2, 3, 4, 5, 6, 7]", "level: 0"),
                                   encoding="utf-8")
    files = sorted(p.name for p in folder.iterdir())
    done = run(["sweep", "s.yaml", "-o", "s.h5"], folder, limit=16 * 1024)
    assert done.returncode == 2, done.stderr
    assert "file size limit" in one_error(done.stderr)
    assert sorted(p.name for p in folder.iterdir()) == files

"""Run one case in a fresh folder as real ``fccgrb`` processes and check the README's promises.

The folder is ``<sandbox>/outer/work`` (the commands' current folder) inside ``<sandbox>`` (so
that a file written outside the folder asked for is seen too). Before and after each step every file
under the sandbox is hashed; after a step:

* no traceback, no "Exception ignored", no death by a signal, no hang (a timeout);
* a bad input (``expect="error"``): exit status 2 and, besides warnings and progress lines,
  exactly one stderr line ``fccgrb: error: …`` holding one of the case's ``names`` (the file,
  key path or option it is about); a step that may go either way (``"any"``): status 0 or that;
* nothing new under the sandbox but the outputs a successful step declares, nothing changed but
  those, and never a scratch file (``.tmp``, ``.fccgrb-spill-*``, a lock) left behind.
"""

from __future__ import annotations

import hashlib
import os
import re
import resource
import shutil
import signal
import stat
import subprocess
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

from .cases import Case
from .fixtures import command, environment

MEMORY = 3 << 30  # bytes of address space a case may take: a bomb fails, it does not swap
SCRATCH = (".tmp", ".lock", ".fccgrb-spill-")
QUIET = ("fccgrb: warning:", "sweep: ")


@dataclass
class Outcome:
    case: Case
    problems: list[str] = field(default_factory=list)
    seconds: float = 0.0

    @property
    def ok(self) -> bool:
        return not self.problems


def snapshot(root: Path) -> dict[str, str]:
    """relative path → content hash (files), 'dir', 'fifo', 'link→target' or the file type."""
    out: dict[str, str] = {}
    for folder, dirs, files in os.walk(root):
        for name in dirs + files:
            path = Path(folder) / name
            key = str(path.relative_to(root))
            info = path.lstat()
            if stat.S_ISLNK(info.st_mode):
                out[key] = "link→" + os.readlink(path)
            elif stat.S_ISDIR(info.st_mode):
                out[key] = "dir"
            elif stat.S_ISREG(info.st_mode):
                digest = hashlib.sha256()
                with path.open("rb") as f:
                    for block in iter(lambda f=f: f.read(1 << 20), b""):
                        digest.update(block)
                out[key] = digest.hexdigest()
            else:
                out[key] = f"special {stat.S_IFMT(info.st_mode):o}"
    return out


def _limits() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY, MEMORY))
    os.setsid()  # its own process group: a timeout kills the command and its workers


PROGRESS = re.compile(r": frame \d+/\d+ \(")


def _error_lines(stderr: str) -> list[str]:
    """stderr without warnings, notes and progress lines: what should be the one error line."""
    lines = [line.rstrip("\r") for line in stderr.replace("\r", "\n").splitlines()]
    return [line for line in lines if line.strip() and not line.startswith(QUIET)
            and not (line.startswith("fccgrb: ") and not line.startswith("fccgrb: error:"))
            and not PROGRESS.search(line)]


def run_case(case: Case, base: Path, keep: Path | None = None) -> Outcome:
    """Run every step of ``case`` in a fresh sandbox made from the files in ``base``."""
    outcome = Outcome(case)
    sandbox = Path(tempfile.mkdtemp(prefix="fuzz-case-"))
    work = sandbox / "outer" / "work"  # ../../x is still inside the sandbox
    started = time.perf_counter()
    try:
        shutil.copytree(base, work, symlinks=True)
        try:
            case.setup(work)
        except Exception as error:  # a case that cannot be built is the fuzzer's own bug
            outcome.problems.append(f"setup failed: {error!r}")
            return outcome
        for step in case.steps:
            before = snapshot(sandbox)
            done = _run([*command(), *step.argv], work, step.timeout)
            if done is None:
                outcome.problems.append(f"{' '.join(step.argv)}: no answer in {step.timeout} s")
                break
            outcome.problems += _check(step, done, before, snapshot(sandbox))
            if outcome.problems:
                break
    finally:
        outcome.seconds = time.perf_counter() - started
        if keep is not None and outcome.problems:
            keep.mkdir(parents=True, exist_ok=True)
            (keep / f"{case.name.replace('/', '_')}.txt").write_text(
                "\n".join([case.klass, *(" ".join(s.argv) for s in case.steps), "",
                           *outcome.problems]) + "\n", encoding="utf-8")
        shutil.rmtree(sandbox, ignore_errors=True)
    return outcome


def _run(argv: list[str], cwd: Path, timeout: float) -> subprocess.CompletedProcess | None:
    """The finished process, or None after a timeout (then it and its workers are killed)."""
    process = subprocess.Popen(argv, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               text=True, errors="replace", env=environment(),
                               preexec_fn=_limits)
    try:
        stdout, stderr = process.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        os.killpg(process.pid, signal.SIGKILL)
        process.communicate()
        return None
    return subprocess.CompletedProcess(argv, process.returncode, stdout, stderr)


def _check(step, done: subprocess.CompletedProcess, before: dict[str, str],
           after: dict[str, str]) -> list[str]:
    what = " ".join(step.argv)
    problems = []
    text = done.stdout + done.stderr
    if "Traceback" in text or "Exception ignored" in text:
        problems.append(f"{what}: traceback: {_tail(done.stderr)}")
    if done.returncode < 0:
        problems.append(f"{what}: killed by signal {-done.returncode}")
    errors = _error_lines(done.stderr)
    if step.expect == "ok" and done.returncode != 0:
        problems.append(f"{what}: exit {done.returncode}, expected success: {_tail(done.stderr)}")
    if step.expect == "error" and done.returncode != 2:
        problems.append(f"{what}: exit {done.returncode} on bad input, expected 2: "
                        f"{_tail(done.stderr) or _tail(done.stdout)}")
    if done.returncode == 2 and step.expect != "ok":
        if len(errors) != 1 or not errors[0].startswith("fccgrb: error: "):
            problems.append(f"{what}: expected one 'fccgrb: error:' line, got {errors[:4]}")
        elif step.names and not any(n.lower() in errors[0].lower() for n in step.names):
            problems.append(f"{what}: the error names none of {list(step.names)}: {errors[0]}")
    if step.expect == "any" and done.returncode not in (0, 2):
        problems.append(f"{what}: exit {done.returncode}: {_tail(done.stderr)}")
    succeeded = done.returncode == 0
    allowed = set(step.outputs) if succeeded else set()
    for key, value in before.items():
        if after.get(key) != value and _work_relative(key) not in allowed:
            problems.append(f"{what}: {key} was " + ("removed" if key not in after else
                                                      "modified"))
    for key in sorted(set(after) - set(before)):
        scratch = any(mark in Path(key).name for mark in SCRATCH)
        if scratch or (_work_relative(key) not in allowed and not _inside(key, allowed)):
            problems.append(f"{what}: left {key}")
    return problems


def _work_relative(key: str) -> str:
    """A sandbox path as the commands spell it from their folder (outer/work)."""
    if key.startswith("outer/work/"):
        return key[len("outer/work/"):]
    return "../" + key[len("outer/"):] if key.startswith("outer/") else "../../" + key


def _inside(key: str, allowed: set[str]) -> bool:
    """A file inside a declared output folder (a sweep's cells)."""
    relative = _work_relative(key)
    return any(relative.startswith(a.rstrip("/") + "/") for a in allowed)


def _tail(text: str) -> str:
    lines = [line for line in text.strip().splitlines() if line.strip()]
    return " | ".join(lines[-2:])[:300]

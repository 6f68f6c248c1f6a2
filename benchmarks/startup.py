"""Wall time of whole commands, start-up included: the README's first solve (the bundled five-bar
sample, P30, NRM-WLS, inverse dynamics, HDF5 out), the same with ``--engine numpy`` (what loading
numba and its compiled kernels costs against the numpy engine's slower frames), the docs' gait
solve (the shared Qualisys walking trial, 340 frames, the lower-limb template calibrated as
docs/gait.md does, with the dynamics; skipped without ``../shared/data``) and ``fccgrb --help``,
each the best of ``--repeat`` fresh processes (what ``/usr/bin/time -f %e`` reports) with its CPU
time (user + system, which suffers less from other work on the machine): first each command in
its own process (``FCCGRB_SERVER=0``: a command's first run, or with the server turned off), then
through the warm server a command leaves behind (its second run onwards: docs/performance.md,
"Start-up"); then where a solve's time goes: the interpreter and the imports of each whole
command (``python -X importtime``: the sum over top-level imports, and the heaviest of other
packages and of the command's own top-level modules) and the steps of one in-process solve.

    python benchmarks/startup.py [--repeat 5] [--opensim-python PYTHON]

With ``--opensim-python``, OpenSim 4.6's IK and ID tools on its own IK trial (two processes,
start-up included, as ``benchmarks/opensim_tools.py`` runs them) are timed in the same run, and
the gait solve's wall per frame is given beside theirs.

Run it on a quiet machine: the figures are wall clock (the load average is printed before and
after). Speed goals live here, never in tests.
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from served import ALONE, warm_server

ROOT = Path(__file__).resolve().parents[1]
SOLVE = ["solve", str(ROOT / "configs" / "models" / "five_bar.yaml"),
         str(ROOT / "sample_data" / "five_bar.c3d"), "--perturb", "30"]
GAIT_TRIAL = ROOT.parent / "shared" / "data" / "c3d" / "Qualisys.c3d"
CALIBRATE = ["calibrate", str(ROOT / "configs" / "models" / "lower_limb.yaml"), str(GAIT_TRIAL),
             "--mass", "67", "-o", "personal.yaml"]
GAIT_FRAMES = 340
GAIT = ["solve", "personal.yaml", str(GAIT_TRIAL), "--method", "nrm-wls", "--filter-cutoff", "6"]
ENTRY = "from fccgrb_cli.entry import run; run()"


def command() -> list[str]:
    """The console script beside this interpreter (as a user runs it), else the same entry
    point through ``python -c``."""
    script = Path(sys.executable).with_name("fccgrb")
    if script.exists():
        return [str(script)]
    found = shutil.which("fccgrb")
    return [found] if found else [sys.executable, "-c", ENTRY]


def importtime_command(script: list[str]) -> list[str]:
    """``script`` (from :func:`command`) run by this interpreter with ``-X importtime``."""
    body = script[1:] if script[0] == sys.executable else script[:1]
    return [sys.executable, "-X", "importtime", *body]


def run(args: list[str], cwd: Path, env: dict | None = None) -> tuple[float, float, str]:
    """Wall and CPU (user + system) seconds of one run of ``args`` (in its own process unless
    ``env`` says otherwise), and its stderr; a failing run stops the benchmark."""
    for stale in cwd.glob("*.h5"):
        stale.unlink()
    with tempfile.TemporaryFile("w+") as err:
        started = time.perf_counter()
        child = subprocess.Popen(args, cwd=cwd, stdout=subprocess.DEVNULL, stderr=err,
                                 env=ALONE if env is None else env)
        _, status, usage = os.wait4(child.pid, 0)
        wall = time.perf_counter() - started
        child.returncode = os.waitstatus_to_exitcode(status)
        err.seek(0)
        text = err.read()
    if child.returncode:
        sys.exit(f"{' '.join(args)} failed:\n{text}")
    return wall, usage.ru_utime + usage.ru_stime, text


def best(args: list[str], repeat: int, cwd: Path, env: dict | None = None
         ) -> tuple[float, float]:
    """Best wall and best CPU seconds over ``repeat`` fresh processes of ``args``."""
    times = [run(args, cwd, env)[:2] for _ in range(repeat)]
    return min(wall for wall, _ in times), min(cpu for _, cpu in times)


def import_profile(args: list[str], cwd: Path, count: int = 8
                   ) -> tuple[float, list[tuple[float, str]], list[tuple[float, str]]]:
    """For one run of ``args`` under ``-X importtime`` (which adds its own overhead): the sum of
    its top-level imports' cumulative seconds, its heaviest imports of other packages (those
    imported from the package's own modules or from the top) and its heaviest top-level
    imports of the package's own modules."""
    _, _, err = run(args, cwd)
    rows = []  # (depth, cumulative s, module), children listed before their parent
    for line in err.splitlines():
        match = re.match(r"import time:\s+\d+ \|\s+(\d+) \| ( *)(\S+)", line)
        if match:
            rows.append((len(match.group(2)) // 2, int(match.group(1)) / 1e6, match.group(3)))
    total = sum(seconds for depth, seconds, _ in rows if depth == 0)
    others, own = [], []
    for k, (depth, seconds, name) in enumerate(rows):
        parent = next((n for d, _, n in rows[k + 1:] if d == depth - 1), "")
        if not name.startswith("fccgrb_cli") and (not depth or parent.startswith("fccgrb_cli")):
            others.append((seconds, name))
        elif name.startswith("fccgrb_cli") and not depth:
            own.append((seconds, name))
    return total, sorted(others, reverse=True)[:count], sorted(own, reverse=True)[:count]


def opensim_per_frame(python: str, repeat: int) -> tuple[float, int]:
    """OpenSim's IK and ID tools, each in its own process as ``opensim-cmd run-tool`` runs
    them, on its IK regression trial (``benchmarks/opensim_tools.py``): the best of ``repeat``
    of the two processes' wall over the trial's frames (ms) and the frames."""
    from opensim_tools import TRIAL, _opensim

    best_wall, frames = float("inf"), 0
    with tempfile.TemporaryDirectory() as scratch:
        folder = Path(scratch)
        for item in TRIAL.iterdir():
            (folder / item.name).symlink_to(item)
        for _ in range(repeat):
            ik, _ = _opensim(python, "ik", folder)
            inverse, _ = _opensim(python, "id", folder)
            best_wall = min(best_wall, ik + inverse)
        frames = int(_opensim(python, "solver", folder)[1]["frames"])
    return 1e3 * best_wall / frames, frames


def solve_steps() -> list[tuple[str, float]]:
    """Seconds of each step of one solve of the sample in this (warm) process."""
    import fccgrb_cli  # noqa: F401  (first: pins BLAS to one thread before numpy loads)
    from fccgrb_cli.pipeline import solve as pipeline
    from fccgrb_cli.results.storage import write_run
    from fccgrb_cli.trial.record import read_trial
    from fccgrb_cli.model import load_model
    from fccgrb_cli.pipeline.options import SolveOptions

    options = SolveOptions(perturb_mm=30.0)
    kinematics = SolveOptions(**{**options.__dict__, "dynamics": False})
    model = load_model(ROOT / "configs" / "models" / "five_bar.yaml")
    trial = read_trial(ROOT / "sample_data" / "five_bar.c3d")
    steps = []
    with tempfile.TemporaryDirectory() as folder:
        output = Path(folder) / "results.h5"
        write_run(output, pipeline.solve_trial(model, trial, options), "warm-up")
        output.unlink()
        for name, work in (("read model and trial",
                            lambda: (load_model(model.source), read_trial(trial.path))),
                           ("kinematic solve + rates",
                            lambda: pipeline.solve_trial(model, trial, kinematics)),
                           ("whole solve_trial (with dynamics)",
                            lambda: pipeline.solve_trial(model, trial, options))):
            started = time.perf_counter()
            run = work()
            steps.append((name, time.perf_counter() - started))
        started = time.perf_counter()
        write_run(output, run, "benchmark")
        steps.append(("write HDF5", time.perf_counter() - started))
    return steps


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--opensim-python", default=None, metavar="PYTHON",
                        help="a Python where `import opensim` works: OpenSim 4.6's IK and ID "
                             "tools (two processes) on its own IK trial in the same run, per "
                             "frame beside the gait solve's")
    args = parser.parse_args()
    fccgrb = command()
    env_note = "" if os.environ.get("OPENBLAS_NUM_THREADS") is None else " (BLAS threads set)"
    load = os.getloadavg()
    with tempfile.TemporaryDirectory() as folder:
        cwd = Path(folder)
        cases = [("fccgrb solve (README's first command: five-bar, P30, dynamics)",
                  [*SOLVE, "-o", "results.h5"]),
                 ("  the same, --engine numpy", [*SOLVE, "-o", "results.h5", "--engine", "numpy"])]
        if GAIT_TRIAL.is_file():
            run([*fccgrb, *CALIBRATE], cwd)
            cases.append(("fccgrb solve (docs/gait.md: Qualisys, 340 frames, dynamics)",
                          [*GAIT, "-o", "gait.h5"]))
        cases.append(("fccgrb --help", ["--help"]))
        walls = [(name, *best([*fccgrb, *case], args.repeat, cwd)) for name, case in cases]
        with warm_server() as env:
            served = [(name, *best([*fccgrb, *case], args.repeat, cwd, env))
                      for name, case in cases if "--engine" not in case]
        bare = best([sys.executable, "-c", "pass"], args.repeat, cwd)
        peer = opensim_per_frame(args.opensim_python, args.repeat) \
            if args.opensim_python and GAIT_TRIAL.is_file() else None
        profiles = [(name, import_profile(importtime_command(fccgrb) + case, cwd))
                    for name, case in cases if case[0] == "solve" and "--engine" not in case]
    print(f"best of {args.repeat} fresh processes{env_note}; load average "
          f"{load[0]:.2f} before, {os.getloadavg()[0]:.2f} after (2 busy cores = 2.0):")
    print(f"  {'':64} {'wall s':>7} {'CPU s':>7}")
    for name, wall, cpu in [*walls, ("python -c pass (the interpreter alone)", *bare)]:
        print(f"  {name:64} {wall:7.3f} {cpu:7.3f}")
    print("the same commands through the warm server (a command's second run onwards; CPU s is "
          "the command line's, not the server's fork):")
    for name, wall, cpu in served:
        print(f"  {name:64} {wall:7.3f} {cpu:7.3f}")
    if peer is not None:
        ms, frames = peer
        print(f"per frame, start-up included: OpenSim's IK + ID tools (two processes) on its "
              f"{frames}-frame IK trial {ms:.2f} ms, best of {args.repeat} in this run; the "
              f"gait solve ({GAIT_FRAMES} frames):")
        for what, rows in (("in its own process", walls), ("through the warm server", served)):
            wall = next(w for name, w, _ in rows if name.startswith("fccgrb solve (docs/gait"))
            print(f"  {what:26} {1e3 * wall / GAIT_FRAMES:6.2f} ms  "
                  f"OpenSim / fccgrb {ms / (1e3 * wall / GAIT_FRAMES):5.1f}")
    for name, (total, others, own) in profiles:
        print(f"imports of {name.split(' (')[1].split(':')[0]} (-X importtime, "
              f"{total:.3f} s in all): heaviest of other packages, then of fccgrb_cli's:")
        for seconds, module in [*others, ("", ""), *own]:
            if module:
                print(f"  {module:40} {seconds:6.3f}")
    print("steps of a solve in a warm process (s):")
    for name, seconds in solve_steps():
        print(f"  {name:40} {seconds:6.3f}")


if __name__ == "__main__":
    main()

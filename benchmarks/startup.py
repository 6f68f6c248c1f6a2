"""Wall time of whole commands, start-up included: the README's first solve (the bundled
five-bar sample, P30, NRM-WLS, inverse dynamics, HDF5 out) and ``fccgrb --help``, each the best
of ``--repeat`` fresh processes (what ``/usr/bin/time -f %e`` reports), then where a solve's time
goes: the interpreter and the imports (``python -X importtime``, heaviest top-level modules)
and the steps of one in-process solve.

    python benchmarks/startup.py [--repeat 5]

Run it on a quiet machine: the figures are wall clock. Speed goals live here, never in tests.
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

ROOT = Path(__file__).resolve().parents[1]
SOLVE = ["solve", str(ROOT / "configs" / "models" / "five_bar.yaml"),
         str(ROOT / "sample_data" / "five_bar.c3d"), "--perturb", "30"]
IMPORTS_ONLY = "import fccgrb_cli.cli.main, fccgrb_cli.pipeline.solve, fccgrb_cli.results.storage"


def command() -> list[str]:
    """The console script beside this interpreter (as a user runs it), else the same entry
    point through ``python -c``."""
    script = Path(sys.executable).with_name("fccgrb")
    if script.exists():
        return [str(script)]
    found = shutil.which("fccgrb")
    return [found] if found else [sys.executable, "-c",
                                  "import sys; from fccgrb_cli.cli.main import main; "
                                  "sys.exit(main())"]


def best_wall(args: list[str], repeat: int, cwd: Path) -> float:
    """Best wall time (s) of ``repeat`` runs of ``args``; a failing run stops the benchmark."""
    best = float("inf")
    for _ in range(repeat):
        for stale in cwd.glob("*.h5"):
            stale.unlink()
        started = time.perf_counter()
        done = subprocess.run(args, cwd=cwd, capture_output=True, text=True)
        elapsed = time.perf_counter() - started
        if done.returncode:
            sys.exit(f"{' '.join(args)} failed:\n{done.stderr}")
        best = min(best, elapsed)
    return best


def heaviest_imports(code: str, count: int = 8) -> tuple[float, list[tuple[float, str]]]:
    """Total import time (s) of ``code`` in a fresh interpreter and its heaviest imports of other
    packages (those imported from the package's own modules or from the top), from
    ``-X importtime`` (which adds its own overhead)."""
    done = subprocess.run([sys.executable, "-X", "importtime", "-c", code], capture_output=True,
                          text=True, check=True)
    rows = []  # (depth, cumulative s, module), children listed before their parent
    for line in done.stderr.splitlines():
        match = re.match(r"import time:\s+\d+ \|\s+(\d+) \| ( *)(\S+)", line)
        if match:
            rows.append((len(match.group(2)) // 2, int(match.group(1)) / 1e6, match.group(3)))
    total = sum(seconds for depth, seconds, _ in rows if depth == 0)
    entry_points = []
    for k, (depth, seconds, name) in enumerate(rows):
        parent = next((n for d, _, n in rows[k + 1:] if d == depth - 1), "")
        if not name.startswith("fccgrb_cli") and (not depth or parent.startswith("fccgrb_cli")):
            entry_points.append((seconds, name))
    return total, sorted(entry_points, reverse=True)[:count]


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
    args = parser.parse_args()
    fccgrb = command()
    env_note = "" if os.environ.get("OPENBLAS_NUM_THREADS") is None else " (BLAS threads set)"
    with tempfile.TemporaryDirectory() as folder:
        cwd = Path(folder)
        solve = best_wall([*fccgrb, *SOLVE, "-o", "results.h5"], args.repeat, cwd)
        help_ = best_wall([*fccgrb, "--help"], args.repeat, cwd)
        bare = best_wall([sys.executable, "-c", "pass"], args.repeat, cwd)
        imports = best_wall([sys.executable, "-c", IMPORTS_ONLY], args.repeat, cwd)
    print(f"best of {args.repeat} fresh processes{env_note}, wall s:")
    print(f"  fccgrb solve (README's first command: five-bar, P30, dynamics)  {solve:6.3f}")
    print(f"  fccgrb --help                                                   {help_:6.3f}")
    print(f"  python -c pass (the interpreter alone)                          {bare:6.3f}")
    print(f"  python -c '{IMPORTS_ONLY}'  {imports:6.3f}")
    total, top = heaviest_imports(IMPORTS_ONLY)
    print(f"heaviest imports of other packages on the solve path (-X importtime, {total:.3f} s "
          "in all):")
    for seconds, name in top:
        print(f"  {name:40} {seconds:6.3f}")
    print("steps of a solve in a warm process (s):")
    for name, seconds in solve_steps():
        print(f"  {name:40} {seconds:6.3f}")


if __name__ == "__main__":
    main()

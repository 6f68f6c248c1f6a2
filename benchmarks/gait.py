"""Speed on a real walking trial: calibrate the lower-limb template on Qualisys.c3d (200 Hz,
340 frames, 28 tracked markers), then solve it with NRM-WLS and CNO-SQP, and compare with real
time (the trial's own frame rate).

    python benchmarks/gait.py [--repeat 3] [--trial ../shared/data/c3d/Qualisys.c3d]

Each method and engine runs three ways ('stages'): the positions alone (no dynamics,
``smooth: none``); with the inverse dynamics on the angles low-passed at 6 Hz (the classical
route, no smoother); and with the whole-trial smoother, then the inverse dynamics on its rates
(``smooth: auto``, ``fccgrb solve --smooth auto``). The last two rows' difference is the
smoother's cost. Figures are the whole solve per frame (wall clock, best of ``--repeat``, the
kernels loaded before): the per-frame position solves plus velocities, accelerations, the later
stages and bookkeeping; 'solve ms/f' is the position solve alone (what the solvers record in
``time_s``, what ``fccgrb solve`` reports as ms/frame), for the numpy and the compiled engine.
Speed goals live here, never in tests.
"""

from __future__ import annotations

import fccgrb_cli  # noqa: F401  (first: pins BLAS to one thread before numpy loads)
import argparse
import time
from pathlib import Path

import numpy as np

from fccgrb_cli.anatomy.calibrate import calibrate
from fccgrb_cli.trial.record import read_trial
from fccgrb_cli.model import load_model, parse_model
from fccgrb_cli.pipeline.options import SolveOptions
from fccgrb_cli.pipeline.solve import solve_trial

ROOT = Path(__file__).resolve().parents[1]
TRIAL = ROOT.parent / "shared" / "data" / "c3d" / "Qualisys.c3d"


def timed(repeat: int, run):
    best, out = float("inf"), None
    for _ in range(repeat):
        started = time.perf_counter()
        out = run()
        best = min(best, time.perf_counter() - started)
    return best, out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--trial", type=Path, default=TRIAL)
    args = parser.parse_args()
    if not args.trial.exists():
        raise SystemExit(f"{args.trial}: not found (the shared data folder is not here)")
    trial = read_trial(args.trial)
    template = load_model(ROOT / "configs" / "models" / "lower_limb.yaml")
    seconds, cal = timed(args.repeat, lambda: calibrate(template, trial, mass=67.0))
    model = parse_model(cal.text, "personal.yaml")
    n = trial.n_frames
    print(f"{args.trial.name}: {n} frames at {trial.rate:g} Hz; calibrate {1e3 * seconds:.0f} ms")
    print(f"{'method':>8} {'engine':>9} {'stages':>11} {'ms/frame':>9} {'solve ms/f':>11} "
          f"{'frames/s':>9} {'x real time':>12} {'iter/frame':>11} {'mean ED mm':>11}")
    stages = (("positions", {"dynamics": False, "smooth": "none"}),
              ("+ID 6 Hz", {"dynamics": True, "filter_cutoff": 6.0}),
              ("+smooth+ID", {"dynamics": True, "smooth": "auto"}))
    for method in ("nrm-wls", "cno-sqp"):
        for engine in ("numpy", "compiled"):
            for stage, chosen in stages:
                options = SolveOptions(method=method, engine=engine, **chosen)
                if engine == "compiled":  # load the kernels outside the timing
                    solve_trial(model, trial, options)
                seconds, run = timed(args.repeat, lambda o=options: solve_trial(model, trial, o))
                fps = n / seconds
                print(f"{method:>8} {engine:>9} {stage:>11} "
                      f"{1e3 * seconds / n:9.2f} {1e3 * np.mean(run.result.time_s):11.3f} "
                      f"{fps:9.0f} {fps / trial.rate:12.1f} "
                      f"{np.mean(run.result.iterations):11.1f} {1e3 * np.mean(run.ed):11.2f}")


if __name__ == "__main__":
    main()

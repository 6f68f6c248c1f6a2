"""Speed of the dynamics stage alone (docs/formulation.md §4): the classical model driven by the
solved angles (positions, consistent velocities and accelerations), then the inverse dynamics, on
the five-bar sample (P30, NRM-WLS) and on the lower-limb gait trial (calibrated as in
``benchmarks/gait.py``, NRM-WLS, 6 Hz filter, force plates).

    python benchmarks/dynamics.py [--repeat 3] [--trial ../shared/data/c3d/Qualisys.c3d]

The kinematic solve runs once, untimed; the figure is ``pipeline``'s dynamics step per frame
(wall clock, best of ``--repeat``): the compiled kernels (every frame in machine code), the
numpy default (batched where Φ_q is square: the five-bar; frame by frame where it is taller:
the lower limb's floating pelvis), and frame by frame (the sequential reference both must
equal); speed-up is sequential / compiled. Speed goals live here, never in tests.
"""

from __future__ import annotations

import fccgrb_cli  # noqa: F401  (first: pins BLAS to one thread before numpy loads)
import argparse
import time
from pathlib import Path

import numpy as np

from fccgrb_cli.pipeline import solve as pipeline
from fccgrb_cli.anatomy.calibrate import calibrate
from fccgrb_cli.trial.record import read_trial
from fccgrb_cli.model import Model, load_model, parse_model
from fccgrb_cli.pipeline.options import SolveOptions, prepared
from fccgrb_cli.system import compile_system

ROOT = Path(__file__).resolve().parents[1]
TRIAL = ROOT.parent / "shared" / "data" / "c3d" / "Qualisys.c3d"


def stage_ms(model: Model, trial, options: SolveOptions, repeat: int, batched: bool | None,
             engine: str = "numpy") -> tuple[float, float]:
    """Best ms/frame of the dynamics stage over ``repeat`` runs (after one untimed run that
    loads the kernels), and its largest |τ| (N·m)."""
    options = SolveOptions(**{**options.__dict__, "engine": engine})
    run = pipeline.solve_trial(model, trial, SolveOptions(**{**options.__dict__,
                                                            "dynamics": False}))
    model = prepared(model, options)
    system = compile_system(model, angles="coordinate", track=True)
    best, tau = float("inf"), float("nan")
    for _ in range(repeat + 1):
        started = time.perf_counter()
        dyn = pipeline.dynamics_stage(model, trial, system, run.result, options,
                                      pipeline.StageNotes([], [], {}), batched=batched)
        best = min(best, time.perf_counter() - started) if _ else best
        tau = float(np.abs(dyn.inverse.joint_moments).max())
    return 1e3 * best / trial.n_frames, tau


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--trial", type=Path, default=TRIAL)
    args = parser.parse_args()
    cases = [("five_bar P30", load_model(ROOT / "configs" / "models" / "five_bar.yaml"),
              read_trial(ROOT / "sample_data" / "five_bar.c3d"),
              SolveOptions(method="nrm-wls", perturb_mm=30.0, dynamics=True))]
    if args.trial.exists():
        gait = read_trial(args.trial)
        template = load_model(ROOT / "configs" / "models" / "lower_limb.yaml")
        model = parse_model(calibrate(template, gait, mass=67.0).text, "personal.yaml")
        cases.append((f"gait {args.trial.name}", model, gait,
                      SolveOptions(method="nrm-wls", dynamics=True, filter_cutoff=6.0)))
    else:
        print(f"{args.trial}: not found (the shared data folder is not here); five-bar only")
    print(f"{'case':24} {'frames':>6} {'compiled':>9} {'numpy':>9} {'sequential':>11} "
          f"{'speed-up':>9} {'max|τ| N·m':>11}")
    for name, model, trial, options in cases:
        compiled, tau_c = stage_ms(model, trial, options, args.repeat, None, "compiled")
        fast, tau = stage_ms(model, trial, options, args.repeat, None)
        slow, tau_seq = stage_ms(model, trial, options, args.repeat, False)
        differ = [f"{label}: {value:.6f}" for label, value in (("compiled", tau_c),
                                                              ("sequential", tau_seq))
                  if abs(value - tau) > 1e-9 * max(1.0, tau)]
        print(f"{name:24} {trial.n_frames:6d} {compiled:9.4f} {fast:9.4f} {slow:11.4f} "
              f"{slow / compiled:9.1f} {tau:11.3f}" + (f"  ({'; '.join(differ)})"
                                                        if differ else ""))


if __name__ == "__main__":
    main()

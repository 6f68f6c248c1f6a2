"""Speed of the kinematic methods: ms/frame per model, body form, method, tolerance and
perturbation level, on synthesized 300-frame trials (3 s at 100 Hz).

    python benchmarks/kinematics.py [--repeat 3] [--models pendulum,five_bar]
        [--engines numpy,compiled]

ms/frame is the per-frame position solve (what the solvers record in ``time_s``; the compiled
engine times blocks of frames and shares each block's time equally), best of ``--repeat`` runs,
after one untimed run that loads (or compiles) the kernels; 'total' adds the consistent
velocities and accelerations and the bookkeeping, per frame. Speed goals live here, never in
timed unit tests.
"""

from __future__ import annotations

import fccgrb_cli  # noqa: F401  (first: pins BLAS to one thread before numpy loads)
import argparse
import time
from functools import partial
from pathlib import Path

import numpy as np

from fccgrb_cli.model import load_model
from fccgrb_cli.signals.artefact import perturb
from fccgrb_cli.solvers import solve_ad
from fccgrb_cli.solvers.ad.solve import stacked_drives
from fccgrb_cli.solvers.nrm.solve import NrmSettings, solve_nrm
from fccgrb_cli.pipeline.synth import synthesize
from fccgrb_cli.system import compile_system

ROOT = Path(__file__).resolve().parents[1]


def best_of(repeat: int, run):
    best = None
    for _ in range(repeat):
        started = time.perf_counter()
        result = run()
        total = time.perf_counter() - started
        per_frame = float(np.mean(result.time_s))
        if best is None or per_frame < best[0]:
            best = (per_frame, total / result.n_frames, result)
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--models", default="pendulum,five_bar")
    parser.add_argument("--forms", default="full,reduced")
    parser.add_argument("--engines", default="numpy,compiled")
    args = parser.parse_args()
    engines = args.engines.split(",")
    print(f"{'model':9} {'form':7} {'method':8} {'engine':8} {'tol':>6} {'level':>5} "
          f"{'ms/frame':>9} {'total':>7} {'iter':>5} {'max|Φtop|':>9} {'failed':>6}")
    for name in args.models.split(","):
        base = load_model(ROOT / "configs" / "models" / f"{name}.yaml")
        for form in args.forms.split(","):
            model = base.with_form(form)
            truth = synthesize(model)
            ad = compile_system(model, angles="driver")
            mc = compile_system(model, angles="coordinate", track=True)
            r = truth.result
            rows = []
            for tol in (1e-6, 1e-10):
                drives = stacked_drives(ad, r.theta, r.theta_d, r.theta_dd, None)
                rows.append(("ad", "numpy", tol, 0.0, partial(
                    solve_ad, ad, r.time, drives, ad.layout.pose_q(model), tol=tol)))
                for level in (0.0, 7.5e-3, 30e-3):
                    markers = perturb(truth.markers, truth.labels, truth.rate, level, seed=0)
                    for method, weight in (("nrm-ls", None), ("nrm-wls", 1e-3)):
                        for engine in engines:
                            settings = NrmSettings(weight, tol, engine=engine)
                            if engine == "compiled" and not settings.compiled(mc):
                                continue
                            rows.append((method, engine, tol, level, partial(
                                solve_nrm, mc, r.time, markers, settings)))
            for method, engine, tol, level, run in rows:
                run()  # load the kernels outside the timing
                per_frame, total, result = best_of(args.repeat, run)
                print(f"{name:9} {form:7} {method:8} {engine:8} {tol:6.0e} {level * 1e3:5.1f} "
                      f"{per_frame * 1e3:9.3f} {total * 1e3:7.3f} "
                      f"{result.iterations.mean():5.2f} {np.nanmax(result.phi_top_max):9.2e} "
                      f"{int((~result.converged).sum()):6d}", flush=True)


if __name__ == "__main__":
    main()

"""Speed and accuracy of the optimization methods (CNO-SQP, CNO-IP, MO-TC, MO-ED), sequential,
on the five-bar's synthesized 300-frame trial at P0, P7.5 and P30 (every point perturbed).

    python benchmarks/optimization.py [--frames 300] [--ip-frames 30] [--methods ...]

CNO-IP (scipy's trust-constr) takes 0.12–0.16 s a frame, so it runs on the first
``--ip-frames`` frames only. ms/frame is the per-frame solve; max|Φtop| the largest topological
violation over all frames; 'max err' the largest distance of a model point to the exact marker
(meaningful at P0).
"""

from __future__ import annotations

import fccgrb_cli  # noqa: F401  (first: pins BLAS to one thread before numpy loads)
import argparse
from pathlib import Path

import numpy as np

from fccgrb_cli.model import load_model
from fccgrb_cli.perturb import perturb
from fccgrb_cli.solvers.optimize import Settings, solve_optimization
from fccgrb_cli.synth import synthesize
from fccgrb_cli.system import compile_system

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=300)
    parser.add_argument("--ip-frames", type=int, default=30)
    parser.add_argument("--methods", default="cno-sqp:tc,cno-sqp:ed,cno-ip:tc,mo-tc:tc,mo-ed:ed")
    args = parser.parse_args()
    model = load_model(ROOT / "configs" / "models" / "five_bar.yaml")
    truth = synthesize(model)
    system = compile_system(model, angles="coordinate", track=True)
    which = [(tp.body, tp.point) for tp in model.tracked_points]
    print(f"{'method':8} {'obj':3} {'level':>5} {'frames':>6} {'ms/frame':>9} {'iter':>6} "
          f"{'max|Φtop|':>9} {'max err m':>9} {'failed':>6}")
    for spec in args.methods.split(","):
        method, objective = spec.split(":")
        n = args.ip_frames if method == "cno-ip" else args.frames
        for level in (0.0, 7.5e-3, 30e-3):
            markers = perturb(truth.markers, truth.labels, truth.rate, level, seed=0)[:n]
            result = solve_optimization(system, truth.result.time[:n], markers,
                                        Settings(method, objective))
            points = np.array([system.point_positions(q, which) for q in result.q])
            err = np.linalg.norm(points - truth.markers[:n], axis=2).max()
            print(f"{method:8} {objective:3} {level * 1e3:5.1f} {n:6d} "
                  f"{1e3 * result.time_s.mean():9.2f} {result.iterations.mean():6.1f} "
                  f"{result.phi_top_max.max():9.1e} {err:9.1e} "
                  f"{int((~result.converged).sum()):6d}", flush=True)


if __name__ == "__main__":
    main()

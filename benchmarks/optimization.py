"""Speed and accuracy of the optimization methods (CNO-SQP, CNO-IP, MO-TC, MO-ED), sequential,
on the five-bar's synthesized 300-frame trial at P0, P7.5 and P30 (every point perturbed).

    python benchmarks/optimization.py [--frames 300] [--ip-frames 30] [--methods ...]

CNO-IP by scipy's trust-constr takes 0.08–0.10 s a frame, so it runs on the first
``--ip-frames`` frames only (the structured interior point runs on every frame). ms/frame is
the per-frame solve; max|Φtop| the largest topological violation over all frames; 'max err' the
largest distance of a model point to the exact marker (meaningful at P0). A last table compares
scipy's SQP and IP per frame on the same frames (the first ``--ip-frames``; the sequential runs
are warm-started, so SQP's first frames of the long run are the same solves as a short one): the
paper's finding that SQP is the faster, a timing kept out of the unit tests.
"""

from __future__ import annotations

import fccgrb_cli  # noqa: F401  (first: pins BLAS to one thread before numpy loads)
import argparse
from pathlib import Path

import numpy as np

from fccgrb_cli.model import load_model
from fccgrb_cli.signals.artefact import perturb
from fccgrb_cli.solvers.optimize.solve import Settings, solve_optimization
from fccgrb_cli.pipeline.synth import synthesize
from fccgrb_cli.system import compile_system

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=300)
    parser.add_argument("--ip-frames", type=int, default=30)
    parser.add_argument("--methods", default="cno-sqp:tc:compiled,cno-sqp:tc:numpy,"
                        "cno-sqp:tc:scipy,cno-sqp:ed:scipy,cno-ip:tc:compiled,cno-ip:tc:numpy,"
                        "cno-ip:tc:scipy,mo-tc:tc:compiled,mo-tc:tc:numpy,mo-tc:tc:scipy,"
                        "mo-ed:ed:compiled,mo-ed:ed:numpy,mo-ed:ed:scipy")
    args = parser.parse_args()
    model = load_model(ROOT / "configs" / "models" / "five_bar.yaml")
    truth = synthesize(model)
    system = compile_system(model, angles="coordinate", track=True)
    which = [(tp.body, tp.point) for tp in model.tracked_points]
    print(f"{'method':8} {'obj':3} {'solver':9} {'level':>5} {'frames':>6} {'ms/frame':>9} "
          f"{'iter':>6} {'max|Φtop|':>9} {'max err m':>9} {'failed':>6}")
    seconds: dict[tuple[str, str, str, float], np.ndarray] = {}
    for spec in args.methods.split(","):
        method, objective, solver = spec.split(":")
        n = args.ip_frames if (method, solver) == ("cno-ip", "scipy") else args.frames
        settings = Settings(method, objective,
                            optimizer="scipy" if solver == "scipy" else "structured",
                            engine="numpy" if solver == "scipy" else solver)
        for level in (0.0, 7.5e-3, 30e-3):
            markers = perturb(truth.markers, truth.labels, truth.rate, level, seed=0)[:n]
            if solver == "compiled":  # load the kernels outside the timing
                solve_optimization(system, truth.result.time[:n], markers, settings)
            result = solve_optimization(system, truth.result.time[:n], markers, settings)
            seconds[method, objective, solver, level] = result.time_s
            points = np.array([system.point_positions(q, which) for q in result.q])
            err = np.linalg.norm(points - truth.markers[:n], axis=2).max()
            print(f"{method:8} {objective:3} {solver:9} {level * 1e3:5.1f} {n:6d} "
                  f"{1e3 * result.time_s.mean():9.2f} {result.iterations.mean():6.1f} "
                  f"{result.phi_top_max.max():9.1e} {err:9.1e} "
                  f"{int((~result.converged).sum()):6d}", flush=True)
    compare_sqp_ip(seconds)


def compare_sqp_ip(seconds: dict[tuple[str, str, str, float], np.ndarray]) -> None:
    """scipy's SQP and IP (TC objective) per frame on the frames both solved."""
    levels = sorted({level for method, objective, solver, level in seconds
                     if (method, objective, solver) == ("cno-ip", "tc", "scipy")
                     and ("cno-sqp", "tc", "scipy", level) in seconds})
    if not levels:
        return
    print(f"\n{'level':>5} {'frames':>6} {'SQP ms/frame':>12} {'IP ms/frame':>11} {'IP/SQP':>6}")
    for level in levels:
        ip = seconds["cno-ip", "tc", "scipy", level]
        sqp = seconds["cno-sqp", "tc", "scipy", level][: len(ip)]
        print(f"{level * 1e3:5.1f} {len(ip):6d} {1e3 * sqp.mean():12.2f} {1e3 * ip.mean():11.2f} "
              f"{ip.mean() / sqp.mean():6.1f}", flush=True)


if __name__ == "__main__":
    main()

"""fccgrb beside OpenSim's own regression outputs, as an OpenSim user would run it: the figures of
the README's "Coming from OpenSim".

    python benchmarks/opensim_agreement.py

* IK: OpenSim's Gait2354 synthetic trial (``../shared/data/opensim/ik_gait2354_synthetic``) solved
  with the subject's ``.osim`` model and each of OpenSim's task sets (``--tasks``), by NRM-WLS and
  CNO-SQP; the worst coordinate's RMS difference to OpenSim's ``std_subject01_walk1_ik.mot``
  (OpenSim's criterion: < 0.2°), and the solve's ms/frame.
* ID: arm26's generalized forces from OpenSim's coordinates (``../shared/data/opensim/
  id_gait2392``), low-passed at 6 Hz as its setup says, against OpenSim's
  ``std_arm26_InverseDynamics.sto`` (OpenSim's criterion: RMS < 2.0 N·m).
Skips what ``../shared`` does not hold."""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

import fccgrb_cli as fc
from fccgrb_cli.opensim.storage import read_storage

ROOT = Path(__file__).resolve().parents[1]
OPENSIM = ROOT.parent / "shared" / "data" / "opensim"
IK = OPENSIM / "ik_gait2354_synthetic"
ID = OPENSIM / "id_gait2392"


def ik_rows() -> list[str]:
    model = fc.load_model(IK / "subject01_simbody.osim")
    trial = fc.read_trial(IK / "subject01_synthetic_marker_data.trc")
    reference = read_storage(IK / "std_subject01_walk1_ik.mot")
    rows = []
    for tasks in ("gait2354_IK_Tasks_uniform.xml", "gait2354_IK_Tasks.xml"):
        for method in ("nrm-wls", "cno-sqp"):
            started = time.perf_counter()
            run = fc.solve(model, trial, method=method, dynamics=False, tasks=str(IK / tasks))
            seconds = time.perf_counter() - started
            theta = run.result.q[:, -len(run.model.angles):]
            names = [c.name for c in run.model.angles]
            worst_deg, worst_mm = 0.0, 0.0
            for k, name in enumerate(reference.names):
                coordinate = run.model.angles[names.index(name)]
                ours = theta[:, names.index(name)]
                if coordinate.translational:
                    rms = np.sqrt(np.mean((ours - reference.values[:, k]) ** 2))
                    worst_mm = max(worst_mm, 1e3 * rms)
                else:
                    rms = np.sqrt(np.mean((np.degrees(ours) - reference.values[:, k]) ** 2))
                    worst_deg = max(worst_deg, rms)
            rows.append(f"| {tasks} | {method} | {worst_deg:.4f} | {worst_mm:.3f} | "
                        f"{int(run.result.converged.sum())}/{run.result.n_frames} | "
                        f"{1e3 * seconds / run.result.n_frames:.1f} |")
    return rows


def arm26_rows() -> list[str]:
    """arm26's inverse dynamics from OpenSim's coordinates, low-passed at 6 Hz as its setup
    says, against OpenSim's generalized forces (its criterion: RMS < 2.0 N·m)."""
    from fccgrb_cli.dynamics.moving import forces_from_coordinates
    from fccgrb_cli.system.compiled import compile_system

    model = fc.load_model(ID / "arm26.osim")
    coordinates = read_storage(ID / "arm26_InverseKinematics.mot")
    order = [c.name for c in model.angles]
    theta = np.column_stack([np.radians(coordinates.values[:, coordinates.names.index(n)])
                             for n in order])
    tau = forces_from_coordinates(compile_system(model, angles="coordinate"), coordinates.time,
                                  theta, cutoff=6.0)[0]
    reference = read_storage(ID / "std_arm26_InverseDynamics.sto")
    rows = []
    for k, name in enumerate(order):
        column = reference.names.index(f"{name}_moment")
        rms = np.sqrt(np.mean((tau[:, k] - reference.values[:, column]) ** 2))
        rows.append(f"| arm26 | {name}_moment | {rms:.3f} |")
    return rows


def main() -> int:
    if not IK.is_dir():
        print(f"skipped: {IK} is absent")
        return 0
    print("| task set | method | worst coordinate RMS (deg) | worst translation RMS (mm) | "
          "converged | ms/frame |")
    print("|---|---|---|---|---|---|")
    for row in ik_rows():
        print(row)
    print()
    print("| model | generalized force | RMS difference (N·m) |")
    print("|---|---|---|")
    for row in arm26_rows():
        print(row)
    return 0


if __name__ == "__main__":
    sys.exit(main())

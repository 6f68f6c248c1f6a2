"""fccgrb beside OpenSim's own regression outputs, as an OpenSim user would run it: the figures of
the README's "Coming from OpenSim".

    python benchmarks/opensim_agreement.py

* IK: OpenSim's Gait2354 synthetic trial (``../shared/data/opensim/ik_gait2354_synthetic``) solved
  with the subject's ``.osim`` model and each of OpenSim's task sets (``--tasks``), by NRM-WLS and
  CNO-SQP; the worst coordinate's RMS difference to OpenSim's ``std_subject01_walk1_ik.mot``
  (OpenSim's criterion: < 0.2°), and the solve's ms/frame.
* ID: OpenSim's ID setups (``../shared/data/opensim/id_gait2392``: gait2392's walk with its two
  plates' ground reactions, and arm26) run as ``fccgrb solve --opensim-setup SETUP.xml`` runs
  them, against OpenSim's ``std_*_InverseDynamics.sto`` (OpenSim's criterion: RMS < 2.0 N·m
  or N per generalized force).
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


def id_rows() -> list[str]:
    """Each ID setup run as ``fccgrb solve --opensim-setup SETUP.xml`` runs it (its model,
    coordinates, loads, cutoff and time range), against OpenSim's generalized forces over the
    rows both have (its criterion: RMS < 2.0 N·m or N)."""
    from dataclasses import replace

    from fccgrb_cli.pipeline.coordinates import coordinates_run
    from fccgrb_cli.pipeline.opensim_setup import setup_inputs
    from fccgrb_cli.pipeline.options import SolveOptions

    rows = []
    for setup, reference_file in (("subject01_Setup_InverseDynamics.xml",
                                   "std_subject01_InverseDynamics.sto"),
                                  ("arm26_Setup_InverseDynamics.xml",
                                   "std_arm26_InverseDynamics.sto")):
        found = setup_inputs(str(ID / setup), None, (), None, SolveOptions())
        coordinates = read_storage(found.coordinates)
        if coordinates.in_degrees is None and found.in_degrees is not None:
            coordinates = replace(coordinates, in_degrees=found.in_degrees)
        started = time.perf_counter()
        run = coordinates_run(fc.load_model(found.model), coordinates, found.options)
        seconds = time.perf_counter() - started
        ours = run.result.time + run.start_time
        reference = read_storage(ID / reference_file)
        pairs = [(i, j) for i, t in enumerate(reference.time)
                 for j in np.flatnonzero(np.abs(ours - t) < 1e-5)]
        theirs, mine = (np.array(k) for k in zip(*pairs, strict=True))
        worst = {"N·m": (0.0, ""), "N": (0.0, "")}
        tau = run.dynamics.inverse.joint_moments
        for k, (name, coordinate) in enumerate(zip(run.result.angle_names, run.model.angles,
                                                   strict=True)):
            unit = "N" if coordinate.translational else "N·m"
            column = f"{name}_{'force' if unit == 'N' else 'moment'}"
            expected = reference.values[theirs, reference.names.index(column)]
            rms = float(np.sqrt(np.mean((tau[mine, k] - expected) ** 2)))
            worst[unit] = max(worst[unit], (rms, column))
        moment, force = worst["N·m"], worst["N"]
        rows.append(f"| {setup} | {len(pairs)} | {moment[0]:.4f} ({moment[1]}) | "
                    + (f"{force[0]:.4f} ({force[1]})" if force[1] else "–")
                    + f" | {1e3 * seconds / run.result.n_frames:.1f} |")
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
    print("| ID setup | rows compared | worst moment RMS (N·m) | worst force RMS (N) | "
          "ms/frame |")
    print("|---|---|---|---|---|")
    for row in id_rows():
        print(row)
    return 0


if __name__ == "__main__":
    sys.exit(main())

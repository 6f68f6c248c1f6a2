"""fccgrb's whole command beside OpenSim 4.6's IK and ID tools on OpenSim's own trial, in one run.

    python benchmarks/opensim_tools.py [--opensim-python PATH] [--repeat 5]

The trial is OpenSim's IK regression case (``../shared/data/opensim/ik_gait2354_synthetic``: the
Gait2354 subject's ``.osim``, 31 synthetic markers, 73 frames at 60 Hz, its ``Setup_IK.xml``
with the uniform task set, constraint weight 10, accuracy 1e-5). OpenSim runs in the Python
given by ``--opensim-python`` (default: this one), where ``pip install opensim`` (4.6, from the
package index) put it, each tool in a fresh process as ``opensim-cmd run-tool`` runs it:

* **IK**: ``InverseKinematicsTool(setup).run()``: reading the model and markers, the solve,
  writing the ``.mot``. Its per-frame figure is OpenSim's solver alone, measured in a separate
  process: an ``InverseKinematicsSolver`` on the same model, markers, weights, constraint
  weight and accuracy, ``assemble`` at the first time then ``track`` at each (the model's and
  markers' loading left out), divided by the frames.
* **ID**: ``InverseDynamicsTool`` on the IK tool's ``.mot`` (the model's coordinates, OpenSim's
  6 Hz low-pass, no external loads: the synthetic trial has none).
* **IK + ID wall**: the two tools' processes, start-up included, one after the other, as a user
  runs them; and, the stricter peer, both tools in one process.

fccgrb runs ``fccgrb solve --opensim-setup SETUP.xml --filter-cutoff 6 -o out.h5`` in a fresh
process of its own (``FCCGRB_SERVER=0``, as a command's first run; start-up, the kernels' load, the
solve, the angles low-passed at 6 Hz as OpenSim's ID tool does, the rates, the inverse dynamics, the
results file): its wall, and its per-frame kinematic solve as its own summary prints it
(``ms/frame``), for NRM-WLS and CNO-SQP, and with ``--no-dynamics`` (the IK alone, against OpenSim's
IK tool). Both sides solve to the setup's ``accuracy`` (1e-5: OpenSim's assembler accuracy; fccgrb's
tolerance on ‖Δq‖∞); NRM-WLS's per-frame figure is also given at fccgrb's own default, ``--tol
1e-10``. NRM-WLS's whole commands are also timed through the warm server a command leaves behind (a
command's second run onwards; ``benchmarks/served.py``).

Timings: best of ``--repeat`` runs of each, one after another in the same minutes (read the
ratios; state the machine's load, which the script prints before and after).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from served import ALONE, warm_server

ROOT = Path(__file__).resolve().parents[1]
TRIAL = ROOT.parent / "shared" / "data" / "opensim" / "ik_gait2354_synthetic"
SETUP = "subject01_Setup_InverseKinematics.xml"
METHODS = ("nrm-wls", "cno-sqp")

# Runs in OpenSim's Python: argv = tool, setup folder, setup; prints one JSON line of seconds.
_OPENSIM = r'''
import json, sys, time
started = time.perf_counter()
import opensim as osim
imported = time.perf_counter()
tool, folder, setup = sys.argv[1:4]
import os
os.chdir(folder)
out = {"import": imported - started}
if tool in ("ik", "both"):
    t = time.perf_counter()
    ik = osim.InverseKinematicsTool(setup)
    ik.setOutputMotionFileName("ik.mot")
    ik.run()
    out["ik"] = time.perf_counter() - t
if tool in ("id", "both"):
    t = time.perf_counter()
    ik = osim.InverseKinematicsTool(setup)
    idt = osim.InverseDynamicsTool()
    idt.setModelFileName(ik.get_model_file())
    idt.setCoordinatesFileName("ik.mot")
    idt.setLowpassCutoffFrequency(6.0)
    idt.setStartTime(ik.getStartTime())
    idt.setEndTime(ik.getEndTime())
    idt.setResultsDir(".")
    idt.setOutputGenForceFileName("id.sto")
    idt.run()
    out["id"] = time.perf_counter() - t
if tool == "solver":
    ik = osim.InverseKinematicsTool(setup)
    model = osim.Model(ik.get_model_file())
    state = model.initSystem()
    tasks = ik.get_IKTaskSet()
    weights = osim.SetMarkerWeights()
    for k in range(tasks.getSize()):
        task = tasks.get(k)
        if task.getConcreteClassName() == "IKMarkerTask" and task.getApply():
            weights.cloneAndAppend(osim.MarkerWeight(task.getName(), task.getWeight()))
    markers = osim.MarkersReference(ik.get_marker_file(), weights)
    solver = osim.InverseKinematicsSolver(model, markers, osim.SimTKArrayCoordinateReference(),
                                          ik.get_constraint_weight())
    solver.setAccuracy(ik.get_accuracy())
    times = [t for t in markers.getMarkerTable().getIndependentColumn()
             if ik.getStartTime() - 1e-9 <= t <= ik.getEndTime() + 1e-9]
    t = time.perf_counter()
    state.setTime(times[0])
    solver.assemble(state)
    for when in times[1:]:
        state.setTime(when)
        solver.track(state)
    out["solver"] = time.perf_counter() - t
    out["frames"] = len(times)
print(json.dumps(out))
'''


def _wall(command: list[str], cwd: Path, env: dict | None = None) -> tuple[float, str]:
    """Wall seconds of a fresh process and what it printed on stdout (exit status checked)."""
    started = time.perf_counter()
    done = subprocess.run(command, cwd=cwd, capture_output=True, text=True, env=env)
    wall = time.perf_counter() - started
    if done.returncode:
        sys.exit(f"{' '.join(command[:3])}…: exit {done.returncode}\n{done.stderr[-2000:]}")
    return wall, done.stdout


def _opensim(python: str, tool: str, folder: Path) -> tuple[float, dict]:
    wall, out = _wall([python, "-c", _OPENSIM, tool, str(folder), SETUP], folder)
    return wall, json.loads(out.strip().splitlines()[-1])


def _fccgrb(folder: Path, method: str, dynamics: bool, *extra: str,
            env: dict = ALONE) -> tuple[float, float]:
    """Wall seconds of ``fccgrb solve`` (in its own process unless ``env`` is a warm
    server's) and the ms/frame its summary prints."""
    results = folder / "out.h5"
    results.unlink(missing_ok=True)
    command = [shutil.which("fccgrb") or "fccgrb", "solve", "--opensim-setup", SETUP,
               "--method", method, "-o", str(results), *extra]
    command += ["--filter-cutoff", "6"] if dynamics else ["--no-dynamics"]
    wall, out = _wall(command, folder, env)
    lines = out.splitlines()
    header = next(k for k, line in enumerate(lines) if "ms/frame" in line)
    column = lines[header].split().index("ms/frame")
    return wall, float(lines[header + 1].split()[column])


def _load() -> str:
    return ", ".join(f"{x:.2f}" for x in os.getloadavg())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--opensim-python", default=sys.executable,
                        help="a Python where `import opensim` works (default: this one)")
    parser.add_argument("--repeat", type=int, default=5, help="runs of each, best taken")
    args = parser.parse_args()
    if not TRIAL.is_dir():
        sys.exit(f"{TRIAL}: absent (the shared data folder): nothing to compare")
    version = "import opensim; print(opensim.__version__)"
    check = subprocess.run([args.opensim_python, "-c", version], capture_output=True, text=True)
    if check.returncode:
        sys.exit(f"{args.opensim_python}: no opensim (pip install opensim in that environment)")
    print(f"load before: {_load()}", file=sys.stderr)
    best: dict[str, float] = {}

    def keep(key: str, value: float) -> None:
        best[key] = min(best.get(key, float("inf")), value)

    with tempfile.TemporaryDirectory() as scratch, warm_server() as served:
        folder = Path(scratch)
        for item in TRIAL.iterdir():
            (folder / item.name).symlink_to(item)
        frames = 0
        for _ in range(args.repeat):
            wall, seconds = _opensim(args.opensim_python, "ik", folder)
            keep("os ik wall", wall)
            keep("os ik run", seconds["ik"])
            keep("os import", seconds["import"])
            wall, seconds = _opensim(args.opensim_python, "id", folder)
            keep("os id wall", wall)
            keep("os id run", seconds["id"])
            wall, _ = _opensim(args.opensim_python, "both", folder)
            keep("os both wall", wall)
            wall, seconds = _opensim(args.opensim_python, "solver", folder)
            keep("os solver", seconds["solver"])
            frames = seconds["frames"]
            for method in METHODS:
                for dynamics in (False, True):
                    wall, ms = _fccgrb(folder, method, dynamics)
                    keep(f"{method} {dynamics} wall", wall)
                    keep(f"{method} ms", ms)
            _, ms = _fccgrb(folder, "nrm-wls", False, "--tol", "1e-10")
            keep("strict ms", ms)
            for dynamics in (False, True):
                keep(f"served {dynamics} wall", _fccgrb(folder, "nrm-wls", dynamics,
                                                        env=served)[0])
    print(f"load after: {_load()}", file=sys.stderr)
    solver_ms = 1e3 * best["os solver"] / frames
    tool_ms = 1e3 * best["os ik run"] / frames
    two = best["os ik wall"] + best["os id wall"]
    print(f"OpenSim {check.stdout.strip()} and fccgrb on {TRIAL.name} ({frames} frames), "
          f"best of {args.repeat}\n")
    print("| what | OpenSim wall (s) | fccgrb wall (s) | timing ratio OpenSim / fccgrb |")
    print("|---|---|---|---|")
    for method in METHODS:
        ik, both = best[f"{method} False wall"], best[f"{method} True wall"]
        print(f"| IK alone, {method} | {best['os ik wall']:.2f} | {ik:.2f} | "
              f"{best['os ik wall'] / ik:.2f} |")
        print(f"| IK + ID, two tool processes, {method} | {two:.2f} | {both:.2f} | "
              f"{two / both:.2f} |")
        print(f"| IK + ID, one OpenSim process, {method} | {best['os both wall']:.2f} | "
              f"{both:.2f} | {best['os both wall'] / both:.2f} |")
    ik, both = best["served False wall"], best["served True wall"]
    print(f"| IK alone, nrm-wls, through fccgrb's warm server | {best['os ik wall']:.2f} | "
          f"{ik:.2f} | {best['os ik wall'] / ik:.2f} |")
    print(f"| IK + ID, two tool processes, nrm-wls, through fccgrb's warm server | {two:.2f} | "
          f"{both:.2f} | {two / both:.2f} |")
    print(f"| IK + ID, one OpenSim process, nrm-wls, through fccgrb's warm server | "
          f"{best['os both wall']:.2f} | {both:.2f} | {best['os both wall'] / both:.2f} |")
    print("\n| IK per frame | ms/frame | timing ratio OpenSim's solver / this |")
    print("|---|---|---|")
    print(f"| OpenSim InverseKinematicsSolver (assemble, track) | {solver_ms:.2f} | 1.00 |")
    print(f"| OpenSim InverseKinematicsTool.run() (model and markers read) | {tool_ms:.2f} | "
          f"{solver_ms / tool_ms:.2f} |")
    for method in METHODS:
        ms = best[f"{method} ms"]
        print(f"| fccgrb {method} (the summary's ms/frame) | {ms:.2f} | {solver_ms / ms:.2f} |")
    strict = best["strict ms"]
    print(f"| fccgrb nrm-wls --tol 1e-10 (its default without a setup) | {strict:.2f} | "
          f"{solver_ms / strict:.2f} |")
    print(f"\nOpenSim's import: {best['os import']:.2f} s of each OpenSim process's wall.")


if __name__ == "__main__":
    main()

"""A 50-trial study on this machine: ``fccgrb batch`` over perturbed copies of the shared walking
trials, whole command wall time (start-up, calibrations, solves with the inverse dynamics, the
study file) and per trial.

    python benchmarks/batch.py [--trials 50] [--workers 2] [--keep] [--opensim-python PYTHON]

The study: ten subjects of five trials each, alternately an adult (Qualisys.c3d, 200 Hz, 340
frames; lower-limb template, calibrated from its first trial, 67 kg) and a child
(plugin_gait/HC030A05.c3d, 100 Hz, 197 frames; Helen Hayes template, calibrated from
HC030A01.c3d with the measurements of its PROCESSING group); every trial a copy of its subject's
walking trial with every marker perturbed by the soft-tissue artefact of ``fccgrb perturb``
(``fccgrb_cli.signals.artefact.artefact``, 2–10 mm, its own seed), so that no two trials are
the same,
written into a copy of the original C3D so that its force plates and events stay (``fccgrb
perturb`` writes the markers alone). Options as the README's gait example (NRM-WLS, 6 Hz).
'per trial' is the whole batch's wall time over the trials; 'solve s' each trial's own solve in
its worker (the study file's /timings), mean and range. Run it on a quiet machine: the figures
are wall clock. Speed goals live here, never in tests. The batch runs in its own process
(``FCCGRB_SERVER=0``, as a first command), then again through the warm server a command leaves
behind (``benchmarks/served.py``: the batch's own start-up saved, and its workers, forked from it,
start with the kernels loaded).

Then where a trial's time goes (``--no-breakdown`` leaves it out): one adult's and one child's
trial solved again in this process as a worker solves them (``solve_trial_cell``: read the
model and the trial, solve, write the cell), a first time untimed (a worker's kernels are
loaded once, for all its trials), a second time timed, a third under cProfile, the trial file
read anew each time (a worker meets each file once; the model's parse is kept, as between a
subject's trials); each stage's share of the profiled time (its functions' cumulative time),
scaled to the timed wall.
"""

from __future__ import annotations

import argparse
import cProfile
import pstats
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from served import ALONE, warm_server

import h5py
import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "c3d"
ADULT, CHILD = DATA / "Qualisys.c3d", DATA / "plugin_gait" / "HC030A05.c3d"
CHILD_STATIC = DATA / "plugin_gait" / "HC030A01.c3d"
PER_SUBJECT = 5


def fccgrb() -> list[str]:
    script = Path(sys.executable).with_name("fccgrb")
    return [str(script)] if script.exists() else [shutil.which("fccgrb") or "fccgrb"]


def perturbed_copy(source: Path, target: Path, level_mm: float, seed: int) -> None:
    """``source`` with every point's soft-tissue artefact added (its units), all else kept."""
    import ezc3d

    from fccgrb_cli.trial.c3d import UNIT_SCALE
    from fccgrb_cli.signals.artefact import artefact

    c3d = ezc3d.c3d(str(source))
    point = c3d["parameters"]["POINT"]
    labels = [str(v).strip() for key in sorted(k for k in point if k.startswith("LABELS"))
              for v in point[key]["value"]]
    scale = UNIT_SCALE[str(point["UNITS"]["value"][0]).strip()]
    points = c3d["data"]["points"]
    rate = float(point["RATE"]["value"][0])
    for k, label in enumerate(labels[: points.shape[1]]):
        points[:3, k, :] += artefact(label, points.shape[2], rate, level_mm * 1e-3, seed).T / scale
    c3d["data"]["points"] = points
    c3d.write(str(target))


def make_study(folder: Path, trials: int) -> Path:
    """The study file: subjects alternately adults and children, five trials each."""
    subjects = []
    for k in range(-(-trials // PER_SUBJECT)):
        adult = k % 2 == 0
        source = ADULT if adult else CHILD
        name = f"{'A' if adult else 'C'}{k + 1:02d}"
        paths = []
        for j in range(min(PER_SUBJECT, trials - k * PER_SUBJECT)):
            path = folder / f"{name}_walk{j + 1}.c3d"
            perturbed_copy(source, path, 2.0 + 2.0 * j, 100 * k + j)
            paths.append(path.name)
        subject = {"name": name, "trials": paths}
        if adult:
            subject |= {"template": str(ROOT / "configs" / "models" / "lower_limb.yaml"),
                        "static": paths[0], "mass": 67}
        else:
            subject |= {"template": str(ROOT / "configs" / "models" / "helen_hayes.yaml"),
                        "static": str(CHILD_STATIC), "measurements": "from-c3d",
                        "map": str(ROOT / "configs" / "studies" / "plugin_gait_labels.yaml")}
        subjects.append(subject)
    path = folder / "study.yaml"
    path.write_text(yaml.safe_dump({"name": "bench", "options": {"filter_cutoff": 6},
                                    "subjects": subjects}, sort_keys=False), encoding="utf-8")
    return path


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=50)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--keep", action="store_true", help="Keep the temporary folder.")
    parser.add_argument("--no-breakdown", action="store_true",
                        help="Leave out where a trial's time goes.")
    parser.add_argument("--opensim-python", default=None, metavar="PYTHON",
                        help="a Python where `import opensim` works: OpenSim 4.6's IK + ID tools "
                             "(two processes) on its synthetic trial, before and after the "
                             "batch, per frame beside the batch's")
    args = parser.parse_args()
    for path in (ADULT, CHILD, CHILD_STATIC):
        if not path.exists():
            raise SystemExit(f"{path}: not found (the shared data folder is not here)")
    folder = Path(tempfile.mkdtemp(prefix="fccgrb-batch-bench-"))
    try:
        study = make_study(folder, args.trials)
        out = folder / "study.h5"
        command = [*fccgrb(), "batch", str(study), "-o", str(out), "--workers",
                   str(args.workers)]
        peer = [_opensim_per_frame(args.opensim_python)] if args.opensim_python else []
        wall = _timed(command, ALONE)
        with warm_server() as env:  # the same study again, as a command's second run
            served = _timed([*command[:4], str(folder / "served.h5"), *command[5:]], env)
        peer += [_opensim_per_frame(args.opensim_python)] if args.opensim_python else []
        with h5py.File(out, "r") as h5:
            solve = np.array([t.attrs["solve_s"] for t in h5["timings"].values()])
            frames = np.array([len(r["theta"]) for r in h5["runs"].values()])
            rates = np.array([float(r.attrs["rate"]) for r in h5["runs"].values()])
            subjects = len(h5["subjects"])
        n = len(solve)
        print(f"{n} trials of {subjects} subjects ({int(frames.sum())} frames; "
              f"{int((rates == 200).sum())} at 200 Hz with 340 frames, "
              f"{int((rates == 100).sum())} at 100 Hz with 197), --workers {args.workers} "
              f"on {_cpus()} CPUs")
        print(f"{'batch wall s':>13} {'per trial s':>12} {'solve s mean':>13} "
              f"{'solve s min':>12} {'solve s max':>12} {'trials/min':>11}")
        print(f"{wall:13.1f} {wall / n:12.2f} {solve.mean():13.2f} {solve.min():12.2f} "
              f"{solve.max():12.2f} {60 * n / wall:11.1f}")
        print(f"the same batch through the warm server (a command's second run): {served:.1f} s")
        if peer:
            for what, seconds in (("the batch", wall), ("through the server", served)):
                ms = 1e3 * seconds / frames.sum()
                print(f"per frame: {what} {ms:.2f} ms; OpenSim's IK + ID tools on its "
                      f"synthetic trial {min(peer):.2f} ms (best of before and after); "
                      f"OpenSim / fccgrb {min(peer) / ms:.1f}")
        if not args.no_breakdown:
            breakdown(study, out)
        if args.keep:
            print(f"kept {folder}")
    finally:
        if not args.keep:
            shutil.rmtree(folder, ignore_errors=True)


def _timed(command: list[str], env: dict) -> float:
    """Wall seconds of ``command`` (exit status checked)."""
    started = time.perf_counter()
    done = subprocess.run(command, capture_output=True, text=True, check=False, env=env)
    wall = time.perf_counter() - started
    if done.returncode != 0:
        raise SystemExit(f"fccgrb batch exited with {done.returncode}:\n{done.stderr}")
    return wall


def _opensim_per_frame(python: str) -> float:
    """ms per frame of OpenSim's IK tool then its ID tool, each in a fresh process, on its
    synthetic trial (``opensim_tools.py``'s runs: start-up, the model's and markers' reading,
    the writing included)."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import opensim_tools

    with tempfile.TemporaryDirectory() as scratch:
        folder = Path(scratch)
        for item in opensim_tools.TRIAL.iterdir():
            (folder / item.name).symlink_to(item)
        ik, _ = opensim_tools._opensim(python, "ik", folder)
        identity, _ = opensim_tools._opensim(python, "id", folder)
        _, seconds = opensim_tools._opensim(python, "solver", folder)
    return 1e3 * (ik + identity) / seconds["frames"]


# A trial's stages in a worker: (label, the functions whose cumulative time is the stage's)
STAGES = (
    ("read model", ("load_model",)),
    ("read trial", ("read_trial",)),
    ("lab axes", ("lab_axes",)),
    ("kinematics (solve, rates)", ("_kinematics",)),
    ("fit checks", ("points_along", "distances", "kinematic_findings", "assessed")),
    ("conditioning check (σ_min/σ_max, every frame)", ("dynamic_findings",)),
    ("inverse dynamics", ("dynamics_stage",)),
    ("Plug-in Gait outputs", ("plugin_gait_results",)),
    ("gait cycles", ("analyse_gait",)),
    ("write the cell", ("write_run",)),
)


def forget_trial_reads() -> None:
    """Forget the reads of trial files a process keeps (``trial.c3d_file``, the platforms of
    ``trial.forceplates``): a worker meets each trial file once, so the timed solves of the
    breakdown read theirs anew. The model's parse stays kept, as a worker keeps it between a
    subject's trials."""
    from fccgrb_cli.trial import c3d_file, forceplates

    c3d_file._read.cache_clear()
    forceplates._read_plate_file.cache_clear()


def breakdown(study_file: Path, out: Path) -> None:
    """Where one adult's and one child's trial spend their time in a worker (see the module's
    docstring)."""
    from dataclasses import replace

    from fccgrb_cli.batch.cells import cells_folder
    from fccgrb_cli.batch.study.jobs import TrialSolve, calibration_file, solve_trial_cell
    from fccgrb_cli.batch.study.spec import load_study

    study = load_study(study_file)
    rows = []
    for subject in study.subjects[:2]:
        model = calibration_file(subject, cells_folder(out), False)
        trial = subject.trials[-1]
        job = TrialSolve(subject.name, "bench", model, trial,
                         study.options.with_(mapping=subject.mapping),
                         out.parent / f"breakdown-{subject.name}.h5", "bench")
        solve_trial_cell(job)
        job.target.unlink()
        forget_trial_reads()
        started = time.perf_counter()
        solve_trial_cell(job)
        wall = time.perf_counter() - started
        job.target.unlink()
        forget_trial_reads()
        profile = cProfile.Profile()
        profile.runcall(solve_trial_cell, replace(job))
        job.target.unlink()
        stats = pstats.Stats(profile).stats  # type: ignore[attr-defined]
        total = max(v[3] for k, v in stats.items() if k[2] == "solve_trial_cell")
        shares = []
        for _, names in STAGES:
            # a function called inside another of the same stage would count twice: the
            # stages' functions are siblings in solve_trial's body
            spent = sum(max((v[3] for k, v in stats.items() if k[2] == name), default=0.0)
                        for name in names)
            shares.append(spent / total)
        rows.append((subject.name, trial.name, wall, shares))
    print("\nwhere a trial's time goes in a worker (s, the timed wall split by the profiled "
          "shares)")
    width = max(len(label) for label, _ in STAGES) + 2
    print(f"{'stage':<{width}}" + "".join(f"{name + ' ' + trial + ' s':>26}"
                                          for name, trial, _, _ in rows))
    for k, (label, _) in enumerate(STAGES):
        print(f"{label:<{width}}" + "".join(f"{wall * shares[k]:26.3f}"
                                            for _, _, wall, shares in rows))
    print(f"{'other':<{width}}" + "".join(f"{wall * (1 - sum(shares)):26.3f}"
                                          for _, _, wall, shares in rows))
    print(f"{'whole trial':<{width}}" + "".join(f"{wall:26.3f}" for _, _, wall, _ in rows))


def _cpus() -> int:
    import os

    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()


if __name__ == "__main__":
    main()

"""The good files every case starts from, made once per run by the commands themselves.

    model.yaml  the five-bar (9 markers, inertia)       pend.yaml  the pendulum
    t.c3d       50 frames synthesized from model.yaml   t.truth.h5 its truth
    t.trc       the same markers as TRC                 u.c3d      t.c3d perturbed at 5 mm
    r.h5        nrm-ls results of t.c3d                 sweep.yaml one cell on t.c3d
    map.yaml    a label map (P1: P1)                     norm.csv   normative curves
    ll.yaml     the lower-limb template                 walk.trc   a synthetic walk for it
    study.yaml  a study (fccgrb batch): one subject calibrated and solved on walk.trc
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
MODELS = ROOT / "configs" / "models"
TESTS = ROOT / "tests"


def command() -> list[str]:
    """How to start ``fccgrb`` in a fresh process: the installed script beside this
    interpreter, else the module's entry point."""
    script = Path(sys.executable).with_name("fccgrb")
    if script.exists():
        return [str(script)]
    return [sys.executable, "-c", "import sys; sys.argv[0] = 'fccgrb'; "
            "from fccgrb_cli.entry import run; run()"]


def _run(args: list[str], cwd: Path) -> None:
    done = subprocess.run([*command(), *args], cwd=cwd, capture_output=True, text=True,
                          timeout=300, env=environment())
    if done.returncode != 0:
        raise RuntimeError(f"fixture command {args} failed: {done.stderr}")


def environment() -> dict[str, str]:
    """The children's environment: this one, with the code under test first on the path:
    this repository's, or the copy named by FCCGRB_FUZZ_CODE (another checkout, to count a
    version's failures with today's cases)."""
    env = dict(os.environ)
    code = env.get("FCCGRB_FUZZ_CODE", str(ROOT))
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [code, env.get("PYTHONPATH")]))
    return env


def build(folder: Path) -> Path:
    """Make the base files in ``folder`` (created); returns it."""
    folder.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(MODELS / "five_bar.yaml", folder / "model.yaml")
    shutil.copyfile(MODELS / "pendulum.yaml", folder / "pend.yaml")
    shutil.copyfile(MODELS / "lower_limb.yaml", folder / "ll.yaml")
    _run(["synth", "model.yaml", "-o", "t.c3d", "--duration", "0.5"], folder)
    _run(["perturb", "t.c3d", "t.trc", "--level", "0"], folder)
    _run(["perturb", "t.c3d", "u.c3d", "--level", "5"], folder)
    _run(["solve", "model.yaml", "t.c3d", "-o", "r.h5", "--method", "nrm-ls"], folder)
    (folder / "sweep.yaml").write_text(
        "name: sw\nmodel: model.yaml\ntrial: {file: t.c3d}\ncells:\n  - {method: nrm-ls}\n",
        encoding="utf-8")
    (folder / "map.yaml").write_text("P1: P1\n", encoding="utf-8")
    rows = ["variable,percent,mean,sd"] + [f"knee_flexion,{p},{20 + p / 10},{5}"
                                           for p in range(0, 101, 10)]
    (folder / "norm.csv").write_text("\n".join(rows) + "\n", encoding="utf-8")
    _walk(folder / "walk.trc", folder / "ll.yaml")
    (folder / "study.yaml").write_text(
        "name: st\nsubjects:\n  - {name: S01, template: ll.yaml, static: walk.trc, "
        "trials: [walk.trc], mass: 70}\n", encoding="utf-8")
    return folder


def _walk(path: Path, template: Path) -> None:
    """The calibration tests' synthetic walking subject (50 frames) as a TRC."""
    sys.path.insert(0, str(TESTS))
    try:
        from test_calibrate import walking_subject

        from fccgrb_cli.model import load_model
        from fccgrb_cli.trial.record import write_trial
    finally:
        sys.path.remove(str(TESTS))
    trial = walking_subject().trial(load_model(template).marker_labels)
    write_trial(path, list(trial.labels), trial.markers, trial.rate)

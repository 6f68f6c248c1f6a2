"""The scripts of ``examples/`` run as a user runs them, and say what is true.

Each runs in a fresh interpreter from an empty working folder, with this tree's package first
on the path. It must exit 0 with no traceback. Its key printed figures are then recomputed
here from sources the example does not use: the trial files read by ezc3d, the truth files
and the results files read by h5py, and the artefact level by its definition.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import ezc3d
import h5py
import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"
QUALISYS = ROOT.parent / "shared" / "data" / "c3d" / "Qualisys.c3d"
NUMBER = r"(-?\d+(?:\.\d+)?)"


def run_example(script: Path, folder: Path) -> str:
    """stdout of ``python script`` run from ``folder``; fails on a non-zero exit or traceback."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])])}
    done = subprocess.run([sys.executable, str(script)], cwd=folder, env=env, text=True,
                          capture_output=True, timeout=600)
    assert done.returncode == 0, done.stderr
    assert "Traceback" not in done.stderr, done.stderr
    return done.stdout


def figures(line: str) -> list[float]:
    return [float(x) for x in re.findall(NUMBER, line)]


def header(path: Path) -> tuple[int, float, list[str]]:
    """Frames, rate (Hz) and labels of a C3D file as ezc3d reads them."""
    c3d = ezc3d.c3d(str(path))
    point = c3d["parameters"]["POINT"]
    return (c3d["data"]["points"].shape[2], float(point["RATE"]["value"][0]),
            list(point["LABELS"]["value"]))


def test_every_example_is_run_here() -> None:
    tested = {name.removeprefix("test_") for name in globals() if name.startswith("test_")}
    assert {p.stem for p in EXAMPLES.glob("*.py")} <= tested


def test_mechanism_methods(tmp_path: Path) -> None:
    out = run_example(EXAMPLES / "mechanism_methods.py", tmp_path)
    frames, rate, _ = header(tmp_path / "slider_crank.c3d")
    assert f"trial: {frames} frames at {rate:g} Hz" in out
    with h5py.File(tmp_path / "slider_crank.truth.h5") as f:
        truth = f["theta"][()]
    true_turns = (truth[-1, 0] - truth[0, 0]) / (2 * np.pi)
    assert true_turns > 2.9  # the crank turns three times: the signed angle counts them
    with h5py.File(tmp_path / "mechanism.h5") as f:
        for method in ("nrm-wls", "cno-sqp"):
            theta = f["runs"][f"{method}-P7.5"]["theta"][()]
            line = next(x for x in out.splitlines() if x.startswith(f"{method}:"))
            start, end, turns, error = figures(line.split(":", 1)[1])[:4]
            assert error == pytest.approx(np.degrees(np.abs(theta - truth).max()), abs=6e-4)
            assert (start, end) == pytest.approx(np.degrees(theta[[0, -1], 0]), abs=0.06)
            assert turns == pytest.approx(true_turns, abs=0.02)


def test_api_five_bar(tmp_path: Path) -> None:
    out = run_example(EXAMPLES / "api_five_bar.py", tmp_path)
    frames, rate, labels = header(ROOT / "sample_data" / "five_bar.c3d")
    assert f"trial: {frames} frames at {rate:g} Hz, markers {', '.join(labels)}" in out
    with h5py.File(ROOT / "sample_data" / "five_bar.truth.h5") as f:
        truth = np.degrees(f["theta"][()])
    error = figures(out.split("largest angle error against the truth:")[1])[0]
    assert 0 < error < 15
    rows = [line.split() for line in out.splitlines() if re.match(r"\s+J\d_\w+\s", line)]
    assert len(rows) == truth.shape[1] == 9
    for k, (_, low, high, _) in enumerate(rows):
        # each solved angle stays within the largest error of the exact one, frame by frame,
        # so its extremes do too
        assert float(low) == pytest.approx(truth[:, k].min(), abs=error + 0.06)
        assert float(high) == pytest.approx(truth[:, k].max(), abs=error + 0.06)


def test_sweep_levels(tmp_path: Path) -> None:
    out = run_example(EXAMPLES / "sweep_levels.py", tmp_path)
    rows = [line.split() for line in out.splitlines()[1:]]
    assert [(r[0], float(r[1])) for r in rows] == [
        (m, level) for m in ("nrm-wls", "cno-sqp") for level in (0.0, 7.5, 30.0)]
    for _method, level, added, error, ed in rows:
        # the artefact's largest deviation per axis is the level, by its definition
        assert float(added) == pytest.approx(float(level), abs=0.006)
        if float(level) == 0:  # clean synthesized markers: the exact motion comes back
            assert float(error) < 1e-3 and float(ed) < 5e-3
    for method in ("nrm-wls", "cno-sqp"):
        errors = [float(r[3]) for r in rows if r[0] == method]
        assert errors == sorted(errors)


def test_read_results(tmp_path: Path) -> None:
    out = run_example(EXAMPLES / "read_results.py", tmp_path)
    with h5py.File(tmp_path / "results.h5") as f:
        names = sorted(f["runs"])
        assert f"runs {', '.join(names)}" in out
        for name in names:
            theta = f["runs"][name]["theta"]
            column = list(theta.attrs["names"]).index("J3_w")
            line = next(x for x in out.splitlines() if x.startswith(f"{name}:"))
            mean = figures(line.split("J3_w mean")[1])[0]
            assert mean == pytest.approx(np.degrees(theta[:, column]).mean(), abs=6e-5)
            assert f"{theta.shape[0]} frames" in line


def test_gait_trial(tmp_path: Path) -> None:
    out = run_example(EXAMPLES / "gait_trial.py", tmp_path)
    if not QUALISYS.is_file():
        assert out.startswith("skipped: the shared walking trial")
        pytest.skip("the shared Qualisys trial is absent: the example said so and exited 0")
    frames, rate, _ = header(QUALISYS)
    assert out.startswith(f"trial: {frames} frames at {rate:g} Hz")
    assert figures(out.splitlines()[0].split(";")[1])[0] < 67  # the legs weigh part of 67 kg
    knee = figures(out.split("right knee flexion peak:")[1])[0]
    assert 55 <= knee <= 75  # swing-phase knee flexion of adult walking (Winter 2009)


def test_gait_trial_without_the_shared_data(tmp_path: Path) -> None:
    """A copy of the example in a folder with no ``../shared`` beside it says so and exits 0."""
    copy = tmp_path / "repository" / "examples" / "gait_trial.py"
    copy.parent.mkdir(parents=True)
    shutil.copy(EXAMPLES / "gait_trial.py", copy)
    out = run_example(copy, tmp_path)
    assert out == f"skipped: the shared walking trial {tmp_path / 'shared' / 'data' / 'c3d'}" \
                  f"{os.sep}Qualisys.c3d is not on this machine\n"

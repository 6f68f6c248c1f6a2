"""``fccgrb batch``: a study of subjects (each calibrated once, every trial solved, strides pooled
per subject and per group), resumable, with failures collected, on local processes or a Dask
cluster with the same numbers.

The study here is made without the shared data (``tests/walking.py``: a synthesized walker and
perturbed copies, two subjects in two groups). Checked against independent computations:
* resume: a batch killed with SIGKILL after its first trial, run again, solves only the trials
  that had no file, and its study file equals an uninterrupted run's in every dataset,
  attribute and link outside ``/timings`` (bit for bit);
* a Dask ``LocalCluster`` (2 worker processes) through ``--scheduler`` gives that same file;
* pooling: each subject's mean ± SD cycle and parameters, and each group's mean ± between-subject
  SD, recomputed here with numpy from the runs' own per-trial cycles in the file;
* the timings live only under ``/timings`` (the runs' ``time_s`` are links there);
* failures: a trial that cannot be solved and a subject whose calibration fails are listed,
  the rest is solved, exit status 1; bad study files are one line, exit 2, nothing written.
The shared walking trials (Qualisys with the lower-limb template, the Plug-in Gait child with
the Helen Hayes template) run as one study where ``../shared/data`` is present.
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import h5py
import numpy as np
import pytest
import yaml
from cli_helpers import one_error_line, run_cli
from flag_bits import declared

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared" / "data" / "c3d"
FCCGRB = str(Path(sys.executable).with_name("fccgrb"))
TIMINGS = "timings"


def cells(out: Path) -> Path:
    """The batch's cells folder for an output."""
    return out.with_name(out.name + ".cells")


# --- comparing two study files -------------------------------------------------------------

def _attrs(obj) -> dict[str, bytes]:
    out = {}
    for key, value in obj.attrs.items():
        value = np.asarray(value)
        out[key] = value.tobytes() if value.dtype.kind != "O" else repr(value.tolist()).encode()
    return out


def tree(path: Path) -> dict[str, tuple]:
    """Every link of a file outside /timings: soft links by their target; groups by their
    attributes; datasets by dtype, shape, storage layout, filters, bytes and attributes."""
    out: dict[str, tuple] = {}
    with h5py.File(path, "r") as h5:
        out["/"] = ("group", _attrs(h5))

        def visit(name: str) -> None:
            if name.split("/")[0] == TIMINGS:
                return
            link = h5.get(name, getlink=True)
            if isinstance(link, h5py.SoftLink):
                out[name] = ("soft", link.path)
                return
            obj = h5[name]
            if isinstance(obj, h5py.Group):
                out[name] = ("group", _attrs(obj))
                return
            data = obj[()]
            raw = data.tobytes() if np.asarray(data).dtype.kind != "O" else \
                repr(np.asarray(data).tolist()).encode()
            out[name] = ("dataset", str(obj.dtype), obj.shape, obj.chunks, obj.compression,
                         obj.shuffle, raw, _attrs(obj))

        h5.visit_links(visit)
    return out


def assert_same_study(a: Path, b: Path) -> None:
    ta, tb = tree(a), tree(b)
    assert sorted(ta) == sorted(tb)
    different = [name for name in ta if ta[name] != tb[name]]
    assert not different, different[:10]


# --- 1. the study's results ----------------------------------------------------------------

def test_every_trial_is_solved_once_and_the_timings_are_apart(walking_reference: Path) -> None:
    with h5py.File(walking_reference, "r") as h5:
        assert h5.attrs["kind"] == "study"
        assert list(h5["runs"]) == ["A-walk1", "A-walk2", "A-walk3", "B-walk4", "B-walk2"]
        assert list(h5["subjects"]) == ["A", "B"]
        assert [h5["subjects"][s].attrs["group"] for s in ("A", "B")] == ["control", "patients"]
        for name, run in h5["runs"].items():
            subject = run.attrs["subject"]
            # the personalized model the run was solved with is its subject's calibration
            assert run.attrs["model"] == h5["subjects"][subject].attrs["model"]
            link = run.get("time_s", getlink=True)
            assert isinstance(link, h5py.SoftLink) and link.path == f"/timings/{name}/time_s"
            assert np.isnan(run.attrs["wall_s"])
            assert len(run["time_s"]) == len(run["theta"])  # readers follow the link
            assert h5[TIMINGS][name].attrs["solve_s"] > 0
            assert len(h5["errors/where"]) == 0
        # the two subjects' masses reach their models' inertia
        for subject, mass in (("A", 70.0), ("B", 55.5)):
            personal = yaml.safe_load(h5["subjects"][subject].attrs["model"])
            assert personal["subject"]["mass"] == mass
            total = sum(b.get("mass", 0.0) for b in personal["bodies"].values())
            assert 0.3 * mass < total < 0.7 * mass  # pelvis and legs: de Leva's shares


def test_report_lists_each_trial_with_its_frames_and_flags(walking_reference: Path) -> None:
    """``fccgrb report study.h5``: a row per trial whose counts are the file's."""
    result = run_cli("report", walking_reference)
    assert result.exit_code == 0, result.output
    lines = result.output.splitlines()
    header = lines[0].split()
    assert header[:4] == ["trial", "method", "frames", "trusted"]
    quiet = "no frame of any trial flagged by: "
    clear = next((line[len(quiet):].split(", ") for line in lines if line.startswith(quiet)),
                 [])
    assert not set(clear) & set(header)
    with h5py.File(walking_reference, "r") as h5:
        for name, run in h5["runs"].items():
            row = next(line.split() for line in lines if line.startswith(name + " "))
            assert int(row[2]) == len(run["flags"])
            assert int(row[3]) == int(run["converged"][()].sum())
            for label, (_, _, frames) in declared(run).items():
                if label in header:
                    assert int(row[header.index(label)]) == frames
                else:  # no trial carries it: named on the line after the table, not a column
                    assert frames == 0
                    assert label in clear, (label, clear)
    assert "group control: 1 subjects (A)" in result.output
    from fccgrb_cli.batch.study.store import read_study

    full, tables_only = read_study(walking_reference), read_study(walking_reference,
                                                                     trial_gait=False)
    trials = [t for s in full.subjects for t in s.solved]
    assert trials and all(t.gait is not None for t in trials)
    assert all(t.gait is None for s in tables_only.subjects for t in s.solved)
    assert repr(tables_only) == repr(replace(full, subjects=tuple(
        replace(s, solved=tuple(replace(t, gait=None) for t in s.solved))
        for s in full.subjects)))


def _run_cycles(h5: h5py.File, run: str, side: str) -> tuple[np.ndarray, np.ndarray, list]:
    c = h5["runs"][run]["gait/cycles"][side]
    names = [n.decode() if isinstance(n, bytes) else n for n in c["curves"].attrs["names"]]
    return c["curves"][()], c["trusted"][()], names, c["parameters"][()], \
        c["trusted_curves"][()]


def _masked(curves: np.ndarray, trusted: np.ndarray) -> np.ndarray:
    """strides × 101 × variables with NaN where a stride's variable is not trusted (a moment
    whose ground reaction no plate measured: README, "What fccgrb checks for you")."""
    return np.where(trusted[:, None, :], curves, np.nan)


def _mean_sd(curves: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each variable's mean and SD (n − 1) over the strides where it is known (NaN: none, or
    one for the SD)."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        count = np.isfinite(curves).sum(axis=0)
        return np.nanmean(curves, axis=0), np.where(count > 1,
                                                    np.nanstd(curves, axis=0, ddof=1), np.nan)


def test_pooling_per_subject_and_group_matches_numpy(walking_reference: Path) -> None:
    """Subject: mean ± SD (n − 1) over every trusted stride of all its trials, each variable
    over the strides it is trusted on; group: mean and between-subject SD of the subjects'
    means; recomputed from each run's own cycles."""
    with h5py.File(walking_reference, "r") as h5:
        subject_means: dict[str, dict[str, np.ndarray]] = {}
        subject_params: dict[str, dict[str, np.ndarray]] = {}
        for subject in ("A", "B"):
            runs = [r for r in h5["runs"] if h5["runs"][r].attrs["subject"] == subject]
            for side in ("left", "right"):
                parts = [_run_cycles(h5, r, side) for r in runs]
                curves = np.concatenate([_masked(p[0], p[4])[p[1]] for p in parts])
                params = np.concatenate([p[3][p[1]] for p in parts])
                assert len(curves) >= 2
                mean, sd = _mean_sd(curves)
                stored = h5["subjects"][subject]["cycles"][side]
                np.testing.assert_allclose(stored["mean"][()], mean, rtol=1e-12, atol=1e-12)
                np.testing.assert_allclose(stored["sd"][()], sd, rtol=1e-10, atol=1e-12)
                table = h5["subjects"][subject]["spatiotemporal"][side]
                np.testing.assert_allclose(table["mean"][()], params.mean(axis=0), rtol=1e-12)
                np.testing.assert_allclose(table["sd"][()], params.std(axis=0, ddof=1),
                                           rtol=1e-10)
                assert (table["n"][()] == len(params)).all()
                subject_means.setdefault(subject, {})[side] = mean
                subject_params.setdefault(subject, {})[side] = params.mean(axis=0)
        for group, members in (("control", ["A"]), ("patients", ["B"])):
            g = h5["groups"][group]
            for side in ("left", "right"):
                means = np.array([subject_means[m][side] for m in members])
                np.testing.assert_allclose(g["cycles"][side]["mean"][()], means.mean(axis=0),
                                           rtol=1e-12, atol=1e-12)
                assert np.isnan(g["cycles"][side]["sd"][()]).all()  # one subject: no SD
                np.testing.assert_allclose(g["spatiotemporal"][side]["mean"][()],
                                           np.mean([subject_params[m][side] for m in members],
                                                   axis=0), rtol=1e-12)


def test_group_of_two_subjects_has_the_between_subject_sd(walking_study: Path,
                                                          walking_reference: Path) -> None:
    """Both subjects in one group (the reference's cells reused: nothing is solved): the group's
    SD is the SD of the two subjects' means, not of the strides."""
    doc = yaml.safe_load(walking_study.read_text(encoding="utf-8"))
    for s in doc["subjects"]:
        s["group"] = "everyone"
    one = walking_study.with_name("one_group.yaml")
    one.write_text(yaml.safe_dump(doc), encoding="utf-8")
    out = walking_study.parent / "one_group.h5"
    shutil.copytree(cells(walking_reference), cells(out))
    result = run_cli("batch", one, "-o", out)
    assert result.exit_code == 0, result.output
    assert "0 trials solved now, 5 already done" in result.output
    with h5py.File(out, "r") as h5:
        g = h5["groups"]["everyone"]
        assert list(h5["groups"]) == ["everyone"]
        for side in ("left", "right"):
            a = h5["subjects/A/cycles"][side]["mean"][()]
            b = h5["subjects/B/cycles"][side]["mean"][()]
            np.testing.assert_allclose(g["cycles"][side]["mean"][()], (a + b) / 2, atol=1e-12)
            np.testing.assert_allclose(g["cycles"][side]["sd"][()], np.abs(a - b) / np.sqrt(2),
                                       atol=1e-12)
            pa = h5["subjects/A/spatiotemporal"][side]["mean"][()]
            pb = h5["subjects/B/spatiotemporal"][side]["mean"][()]
            np.testing.assert_allclose(g["spatiotemporal"][side]["sd"][()],
                                       np.abs(pa - pb) / np.sqrt(2), rtol=1e-10, atol=1e-15)
            assert (g["spatiotemporal"][side]["n"][()] == 2).all()


# --- 2. resume after kill -9 ---------------------------------------------------------------

def _trial_cells(out: Path) -> dict[Path, tuple[int, int]]:
    folder = cells(out)
    return {p: (p.stat().st_ino, p.stat().st_mtime_ns) for p in folder.glob("*/*.h5")
            if not p.name.startswith(".")}  # a solve's scratch file is not a cell


def test_killed_batch_resumes_and_equals_an_uninterrupted_run(walking_study: Path,
                                                              walking_reference: Path) -> None:
    """Two local worker processes; the batch and its workers killed at once (SIGKILL to the
    process group, as a machine that goes down) when its first trial is written."""
    out = walking_study.parent / "killed.h5"
    proc = subprocess.Popen([FCCGRB, "batch", str(walking_study), "-o", str(out), "--workers",
                             "2"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)
    deadline = time.monotonic() + 300
    while not _trial_cells(out) and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.communicate()
    assert proc.returncode == -signal.SIGKILL
    assert not out.exists()
    before = _trial_cells(out)
    assert 1 <= len(before) < 5, "kill the batch between its first and its last trial"
    result = run_cli("batch", walking_study, "-o", out)
    assert result.exit_code == 0, (result.output, result.stderr)
    assert f"{5 - len(before)} trials solved now, {len(before)} already done" in result.output
    after = _trial_cells(out)
    for path, stamp in before.items():
        assert after[path] == stamp, f"{path.name} was solved again"
    assert_same_study(out, walking_reference)


def test_rerun_solves_nothing(walking_study: Path, walking_reference: Path) -> None:
    before = _trial_cells(walking_reference)
    result = run_cli("batch", walking_study, "-o", walking_reference)
    assert "0 trials solved now, 5 already done" in result.output
    assert _trial_cells(walking_reference) == before


# --- 3. a Dask cluster ----------------------------------------------------------------------

def test_dask_cluster_gives_the_same_file(walking_study: Path, walking_reference: Path) -> None:
    distributed = pytest.importorskip("dask.distributed")
    out = walking_study.parent / "dask.h5"
    with distributed.LocalCluster(n_workers=2, processes=True, threads_per_worker=1,
                                  dashboard_address=None) as cluster:
        result = run_cli("batch", walking_study, "-o", out, "--scheduler",
                         cluster.scheduler_address)
    assert result.exit_code == 0, (result.output, result.stderr)
    assert "5 trials solved now" in result.output
    assert_same_study(out, walking_reference)


# --- 4. failures and bad input --------------------------------------------------------------

def test_failures_are_collected_and_the_rest_is_solved(walking_study: Path,
                                                       walking_reference: Path) -> None:
    folder = walking_study.parent
    broken = folder / "broken.c3d"
    broken.write_bytes(b"not a c3d file at all" * 10)
    doc = yaml.safe_load(walking_study.read_text(encoding="utf-8"))
    doc["subjects"][0]["trials"].append("broken.c3d")
    doc["subjects"].append({"name": "C", "static": "broken.c3d", "trials": ["walk1.c3d"]})
    path = folder / "failing.yaml"
    path.write_text(yaml.safe_dump(doc), encoding="utf-8")
    out = folder / "failing.h5"
    shutil.copytree(cells(walking_reference), cells(out))
    result = run_cli("batch", path, "-o", out)
    assert result.exit_code == 1, (result.output, result.stderr)
    assert "0 trials solved now, 5 already done, 2 failed (1 calibrations failed)" in result.output
    tail = result.output.split("failed (3):")[1]
    assert "C (calibration): " in tail and "A-broken: " in tail
    assert "C-walk1: not solved: the calibration of C failed" in tail
    with h5py.File(out, "r") as h5:
        where = [w.decode() for w in h5["errors/where"][()]]
        assert where == ["C (calibration)", "A-broken", "C-walk1"]
        assert len(h5["runs"]) == 5
        assert list(h5["subjects/C"].attrs["runs"]) == []


BAD = {
    "no subjects": ({"template": "T"}, "subjects: expected this key"),
    "unknown key": ({"subjects": [], "bogus": 1}, "bogus: expected one of the keys"),
    "unknown subject key": ({"subjects": [{"name": "S", "static": "walk1.c3d",
                                           "trials": "walk1.c3d", "height": 2}]},
                            "subjects[0].height: expected one of the keys"),
    "glob matches nothing": ({"subjects": [{"name": "S", "static": "walk1.c3d",
                                            "trials": ["walk1.c3d", "run*.c3d"]}]},
                             "subjects[0].trials[1]: expected trial files matching"),
    "missing static": ({"subjects": [{"name": "S", "static": "nope.c3d",
                                      "trials": "walk1.c3d"}]},
                       "subjects[0].static: expected an existing static trial file"),
    "bad mass": ({"subjects": [{"name": "S", "static": "walk1.c3d", "trials": "walk1.c3d",
                                "mass": -3}]}, "subjects[0].mass: expected a body mass"),
    "bad name": ({"subjects": [{"name": "../x", "static": "walk1.c3d",
                                "trials": "walk1.c3d"}]}, "subjects[0].name: expected a name"),
    "twice the same name": ({"subjects": [
        {"name": "S", "static": "walk1.c3d", "trials": "walk1.c3d"},
        {"name": "S", "static": "walk1.c3d", "trials": "walk2.c3d"}]},
        "subjects[1].name: expected a name no other subject has"),
    "two runs of one name": ({"subjects": [
        {"name": "S", "static": "walk1.c3d", "trials": "a-walk1.c3d"},
        {"name": "S-a", "static": "walk1.c3d", "trials": "walk1.c3d"}]},
        "subjects[1].trials: expected run names (subject-trial) no other"),
    "bad option": ({"options": {"tol": -1}, "subjects": [
        {"name": "S", "static": "walk1.c3d", "trials": "walk1.c3d"}]}, "options.tol"),
    "run name in options": ({"options": {"name": "x"}, "subjects": [
        {"name": "S", "static": "walk1.c3d", "trials": "walk1.c3d"}]}, "options.name"),
    "bad measurements": ({"subjects": [{"name": "S", "static": "walk1.c3d",
                                        "trials": "walk1.c3d", "measurements": "from-vsk"}]},
                         "subjects[0].measurements: expected from-c3d or a mapping"),
    "widths for an anatomical template": (
        {"subjects": [{"name": "S", "static": "walk1.c3d", "trials": "walk1.c3d",
                       "measurements": {"knee_width": 100}}]},
        "subjects[0].measurements: expected from-c3d or nothing"),
    "not a template": ({"template": str(ROOT / "configs" / "models" / "five_bar.yaml"),
                        "subjects": [{"name": "S", "static": "walk1.c3d",
                                      "trials": "walk1.c3d"}]}, "calibration.landmarks"),
    "bad frames": ({"subjects": [{"name": "S", "static": "walk1.c3d", "trials": "walk1.c3d",
                                  "frames": "5:2"}]}, "subjects[0].frames: expected A:B"),
    "missing map": ({"map": "lab.yaml", "subjects": [
        {"name": "S", "static": "walk1.c3d", "trials": "walk1.c3d"}]},
        "map: expected an existing label map file"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_study_is_one_line_and_writes_nothing(walking_study: Path, case: str) -> None:
    doc, fragment = BAD[case]
    doc = {"template": str(ROOT / "configs" / "models" / "lower_limb.yaml"), **doc}
    path = walking_study.parent / "bad.yaml"
    path.write_text(yaml.safe_dump(doc), encoding="utf-8")
    shutil.copyfile(walking_study.parent / "walk1.c3d", walking_study.parent / "a-walk1.c3d")
    out = walking_study.parent / "bad.h5"
    line = one_error_line(run_cli("batch", path, "-o", out), fragment)
    assert line.startswith(f"fccgrb: error: {path}: "), line
    assert not out.exists() and not out.with_name("bad.h5.cells").exists()


def test_output_may_not_be_an_input_or_another_file(walking_study: Path) -> None:
    one_error_line(run_cli("batch", walking_study, "-o", walking_study.parent / "walk1.c3d"),
                   "expected an output other than")
    other = walking_study.parent / "not_a_study.h5"
    with h5py.File(other, "w") as h5:
        h5.attrs["format_version"] = 2
    one_error_line(run_cli("batch", walking_study, "-o", other), "is not a study file")
    missing = walking_study.parent / "no" / "such" / "s.h5"
    one_error_line(run_cli("batch", walking_study, "-o", missing), "does not exist")
    assert not (walking_study.parent / "no").exists()


# --- 5. the shared walking trials ----------------------------------------------------------

@pytest.mark.skipif(not (SHARED / "Qualisys.c3d").exists() or
                    not (SHARED / "plugin_gait" / "HC030A05.c3d").exists(),
                    reason="../shared/data is absent (a user's clone)")
def test_the_shared_walking_trials_as_one_study(tmp_path: Path) -> None:
    """The README's study: Qualisys (calibrated from the walking trial itself, 67 kg) with the
    lower-limb template and the Plug-in Gait child with the Helen Hayes template, its mass and
    Davis' widths from its static's PROCESSING group."""
    out = tmp_path / "shared.h5"
    result = run_cli("batch", ROOT / "configs" / "studies" / "shared.yaml", "-o", out)
    assert result.exit_code == 0, (result.output, result.stderr)
    with h5py.File(out, "r") as h5:
        assert list(h5["runs"]) == ["Q01-Qualisys", "HC030-HC030A05"]
        q = h5["subjects/Q01/spatiotemporal/left"]
        assert q["n"][0] == 1 and 0.9 < q["mean"][0] < 1.0  # stride time (s), README: 0.945
        child = yaml.safe_load(h5["subjects/HC030"].attrs["model"])
        assert abs(child["subject"]["mass"] - 45.8) < 1e-4  # PROCESSING:Bodymass

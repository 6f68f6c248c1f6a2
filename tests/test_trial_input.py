"""Trial input for ``fccgrb solve`` and ``fccgrb perturb``: bad files, gaps, TRC and C3D.

Bad trial input (a missing file, a file that is not C3D, labels absent from the file, every
marker of a body missing in a frame, a TRC with inconsistent columns or header, an unknown
ending) must give ONE line on stderr, ``fccgrb: error: …``, naming the file (and the frame, line
or label where relevant), exit status 2, no traceback, and leave no results file nor temporary
file behind. Inputs are never modified: each case hashes its input before and after.

The trials come from ``fccgrb synth`` (pendulum and five-bar, 1 s at 100 Hz, module fixture) and
are varied with ``write_trial`` or ezc3d. The file also covers ``--skip-unsolvable``, TRC round
trips (units, gaps, labels), C3D gaps (negative residuals), label prefixes and ``--map``,
``fccgrb perturb``, the ``solve`` summary and results files that gain runs, two C3D files from
commercial systems in ``shared/data/c3d`` (skipped when absent, never copied into the project),
and truncated trials: a C3D cut anywhere (header, parameters, data; Intel, DEC and MIPS; float
and integer data; analog channels; more than 65535 frames) or a TRC short of NumFrames is one
line naming both frame counts, or with ``--accept-truncated`` the frames present and a warning.
"""

from __future__ import annotations

import hashlib
import os
import re
import shutil
import subprocess
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import ezc3d
import h5py
import numpy as np
import pytest
import yaml
from cli_helpers import one_error_line, run_cli
from click.testing import Result

from fccgrb_cli.core.errors import InputError
from fccgrb_cli.trial.c3d_header import decode_floats, read_layout
from fccgrb_cli.trial.record import read_trial, write_trial

MODELS = Path(__file__).resolve().parents[1] / "configs" / "models"
PENDULUM = MODELS / "pendulum.yaml"
FIVE_BAR = MODELS / "five_bar.yaml"
SHARED_C3D = Path(__file__).resolve().parents[2] / "shared" / "data" / "c3d"
FCCGRB = shutil.which("fccgrb")

GAP_FRAME = 50  # 0-based frame index, t = 0.500 s at 100 Hz
B5_MARKERS = ("P6",)  # the tracked marker on five-bar body B5 (P5 is tracked on B4)
SUMMARY_COLUMNS = ("method", "ms/frame", "iter/frame", "mean |Phi|", "max |Phi_top|",
                   "mean ED mm", "max ED mm", "jump mm", "failed")


# ---- helpers ------------------------------------------------------------------------------


def digest(path: Path) -> str | None:
    """SHA-256 of a file's bytes (None when it is absent or not a file)."""
    return hashlib.sha256(path.read_bytes()).hexdigest() if path.is_file() else None


def listing(folder: Path) -> list[str]:
    """Every name in the folder, hidden ones (temporary files) included."""
    return sorted(os.listdir(folder))


def solved(result: Result) -> None:
    assert result.exit_code == 0, (result.output, result.exception)
    assert result.exception is None, repr(result.exception)


def runs(path: Path) -> dict[str, dict[str, np.ndarray]]:
    """Every run of a results file: name → {dataset: array} (datasets at the run's top level)."""
    with h5py.File(path, "r") as h5:
        return {name: {key: g[key][()] for key in g if isinstance(g[key], h5py.Dataset)}
                for name, g in h5["runs"].items()}


@dataclass(frozen=True)
class Synth:
    """A synthesized trial: the C3D, its model and the markers as read (m)."""

    path: Path
    model: Path
    labels: tuple[str, ...]
    markers: np.ndarray
    rate: float


@pytest.fixture(scope="module")
def trials(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Synth]:
    """``fccgrb synth MODEL -o <tmp>/NAME.c3d --duration 1`` for the pendulum and the five-bar."""
    folder = tmp_path_factory.mktemp("synth")
    out = {}
    for name, model, file in (("pendulum", PENDULUM, "p.c3d"), ("five_bar", FIVE_BAR, "f.c3d")):
        path = folder / file
        result = run_cli("synth", model, "-o", path, "--duration", "1")
        solved(result)
        assert path.exists() and path.with_name(path.stem + ".truth.h5").exists()
        trial = read_trial(path)
        assert trial.n_frames == 100 and trial.rate == 100.0
        out[name] = Synth(path, model, trial.labels, trial.markers, trial.rate)
    return out


def with_b5_gap(synth: Synth) -> np.ndarray:
    """The five-bar markers with every tracked marker of body B5 NaN in GAP_FRAME."""
    markers = synth.markers.copy()
    markers[GAP_FRAME, [synth.labels.index(m) for m in B5_MARKERS]] = np.nan
    return markers


def test_b5_markers_are_the_ones_the_model_tracks_on_b5() -> None:
    """The body-missing cases rest on this: B5 carries the tracked point P6 only."""
    doc = yaml.safe_load(FIVE_BAR.read_text(encoding="utf-8"))
    on_b5 = tuple(tp["marker"] for tp in doc["tracking"]["points"]
                  if tp["point"].split(".")[0] == "B5")
    assert on_b5 == B5_MARKERS


# ---- bad trial input ----------------------------------------------------------------------


def trc_lines(folder: Path, synth: Synth, units: str = "mm") -> list[str]:
    path = folder / "good.trc"
    write_trial(path, list(synth.labels), synth.markers, synth.rate, units)
    lines = path.read_text(encoding="utf-8").split("\n")
    path.unlink()
    return lines


def edited_trc(name: str, edit: Callable[[list[str]], None]) -> Callable[..., Path]:
    """A pendulum TRC (mm) with one edit to its lines; data row k (0-based) is line 7 + k."""

    def make(folder: Path, trials: dict[str, Synth]) -> Path:
        lines = trc_lines(folder, trials["pendulum"])
        edit(lines)
        path = folder / name
        path.write_text("\n".join(lines), encoding="utf-8")
        return path

    return make


def drop_last_field(lines: list[str]) -> None:
    lines[9] = lines[9].rsplit("\t", 1)[0]  # line 10: 8 marker columns instead of 9


def add_field(lines: list[str]) -> None:
    lines[9] += "\t1.5"  # line 10: 10 marker columns


def word_in_field(lines: list[str]) -> None:
    fields = lines[9].split("\t")
    fields[4] = "abc"
    lines[9] = "\t".join(fields)


def more_num_markers(lines: list[str]) -> None:
    values = lines[2].split("\t")
    assert values[3] == "3"  # NumMarkers
    values[3] = "4"
    lines[2] = "\t".join(values)


def written(name: str, which: str, labels: Callable[[Synth], list[str]] | None = None,
            markers: Callable[[Synth], np.ndarray] | None = None,
            units: str = "mm") -> Callable[..., Path]:
    """A trial written by ``write_trial`` from a synthesized one, with other labels/markers."""

    def make(folder: Path, trials: dict[str, Synth]) -> Path:
        synth = trials[which]
        path = folder / name
        write_trial(path, labels(synth) if labels else list(synth.labels),
                    markers(synth) if markers else synth.markers, synth.rate, units)
        return path

    return make


def raw(name: str, content: bytes) -> Callable[..., Path]:
    def make(folder: Path, trials: dict[str, Synth]) -> Path:
        path = folder / name
        path.write_bytes(content)
        return path

    return make


def absent(folder: Path, trials: dict[str, Synth]) -> Path:
    return folder / "absent.c3d"


def a_folder(folder: Path, trials: dict[str, Synth]) -> Path:
    path = folder / "folder.c3d"
    path.mkdir()
    return path


def c3d_as_txt(folder: Path, trials: dict[str, Synth]) -> Path:
    path = folder / "pendulum.txt"
    shutil.copyfile(trials["pendulum"].path, path)
    return path


@dataclass(frozen=True)
class Case:
    id: str
    model: Path
    make: Callable[[Path, dict[str, Synth]], Path]
    fragments: tuple[str, ...]
    names_file: bool = True


CASES = [
    Case("missing-file", PENDULUM, absent, ("trial file not found",)),
    Case("folder", PENDULUM, a_folder, ("expected a trial file, got a folder",)),
    Case("c3d-that-is-text", PENDULUM, raw("garbage.c3d", b"this is not a C3D file\n" * 40),
         ("not a readable C3D file",)),
    Case("c3d-that-is-noise", PENDULUM,
         raw("noise.c3d", np.random.default_rng(7).bytes(4096)), ("not a readable C3D file",)),
    Case("c3d-empty", PENDULUM, raw("empty.c3d", b""), ("not a readable C3D file",)),
    Case("unknown-ending", PENDULUM, c3d_as_txt, ("expected a .c3d or .trc trial file",)),
    Case("c3d-other-labels", PENDULUM,
         written("other.c3d", "pendulum", labels=lambda s: ["A", "B", "C"]),
         ("not found: P1 (closest: none), P2 (closest: none), P3 (closest: none)",
          "no marker follows: A, B, C", "--map")),
    Case("trc-other-labels", PENDULUM,
         written("other.trc", "pendulum", labels=lambda s: ["P1", "X2", "P3"]),
         ("not found: P2 (closest: X2)", "no marker follows: X2 (")),
    Case("c3d-body-B5-missing", FIVE_BAR, written("b5.c3d", "five_bar", markers=with_b5_gap),
         (f"frame index {GAP_FRAME} ", "t = 0.500 s", "cannot determine", "missing: P6)"),
         names_file=False),
    Case("trc-body-B5-missing", FIVE_BAR,
         written("b5.trc", "five_bar", markers=with_b5_gap, units="m"),
         (f"frame index {GAP_FRAME} ", "t = 0.500 s", "cannot determine", "missing: P6)"),
         names_file=False),
    Case("trc-row-too-few-columns", PENDULUM, edited_trc("short.trc", drop_last_field),
         ("line 10:", "expected 9 marker columns", "got 8")),
    Case("trc-row-too-many-columns", PENDULUM, edited_trc("long.trc", add_field),
         ("line 10:", "expected 9 marker columns", "got 10")),
    Case("trc-row-with-a-word", PENDULUM, edited_trc("word.trc", word_in_field),
         ("line 10:", "expected numbers")),
    Case("trc-num-markers-disagrees", PENDULUM, edited_trc("nummarkers.trc", more_num_markers),
         ("line 4:", "expected 4 marker labels (NumMarkers)", "got 3")),
    Case("trc-that-is-text", PENDULUM, raw("text.trc", b"x,y,z\n1,2,3\n" * 5),
         ("line 1:", "PathFileType")),
    Case("trc-not-utf8", PENDULUM, raw("latin.trc", b"PathFileType\t4\n\xff\xfe\n\n\n\n\n"),
         ("expected UTF-8 text in the TRC file",)),
]


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_bad_trial_is_one_line_and_status_2(case: Case, trials: dict[str, Synth],
                                            tmp_path: Path) -> None:
    trial = case.make(tmp_path, trials)
    before, names = digest(trial), listing(tmp_path)
    out = tmp_path / "out.h5"
    result = run_cli("solve", case.model, trial, "-o", out)
    one_error_line(result, *case.fragments, *((str(trial),) if case.names_file else ()))
    assert result.stdout == ""
    assert not out.exists()
    assert listing(tmp_path) == names  # nothing left behind, temporary files included
    assert digest(trial) == before


def test_body_missing_message_names_the_file(trials: dict[str, Synth], tmp_path: Path) -> None:
    trial = tmp_path / "b5.c3d"
    write_trial(trial, list(trials["five_bar"].labels), with_b5_gap(trials["five_bar"]), 100.0)
    one_error_line(run_cli("solve", FIVE_BAR, trial, "-o", tmp_path / "out.h5"), str(trial))


@pytest.mark.skipif(FCCGRB is None, reason="the fccgrb command is not on PATH")
@pytest.mark.parametrize("case", [c for c in CASES if c.id in
                                  ("missing-file", "c3d-that-is-noise", "c3d-body-B5-missing",
                                   "trc-row-too-few-columns")],
                         ids=lambda c: c.id)
def test_real_process_bad_trial(case: Case, trials: dict[str, Synth], tmp_path: Path) -> None:
    """The same through a real process: genuine stream separation and exit status."""
    trial = case.make(tmp_path, trials)
    before, names = digest(trial), listing(tmp_path)
    proc = subprocess.run([FCCGRB, "solve", str(case.model), str(trial), "-o",
                           str(tmp_path / "out.h5")], capture_output=True, text=True,
                          timeout=120, check=False)
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr
    lines = proc.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("fccgrb: error: "), proc.stderr
    assert all(fragment in lines[0] for fragment in case.fragments), lines[0]
    assert proc.stdout == ""
    assert listing(tmp_path) == names
    assert digest(trial) == before


def test_map_with_an_unknown_model_name_is_one_line(trials: dict[str, Synth],
                                                    tmp_path: Path) -> None:
    synth = trials["pendulum"]
    trial = tmp_path / "renamed.trc"
    write_trial(trial, ["M1", "M2", "M3"], synth.markers, synth.rate)
    names = listing(tmp_path)
    result = run_cli("solve", PENDULUM, trial, "-o", tmp_path / "out.h5",
                     "--map", "P1=M1,P2=M2,P3=M3,Q7=M4")
    one_error_line(result, "--map", "(P1, P2, P3)", "Q7 (closest: none)")
    result = run_cli("solve", PENDULUM, trial, "-o", tmp_path / "out.h5", "--map", "P1")
    one_error_line(result, "--map", "MODEL_NAME=FILE_LABEL", "'P1'")
    assert listing(tmp_path) == names


# ---- --skip-unsolvable --------------------------------------------------------------------


def test_skip_unsolvable_turns_the_frame_into_a_warning(trials: dict[str, Synth],
                                                        tmp_path: Path) -> None:
    """Regression: at commit 1ba84f0 this raised LinAlgError('Singular matrix') from
    consistent_rates (q of the unsolved frame passed through np.nan_to_num → 0)."""
    trial = tmp_path / "b5.c3d"
    write_trial(trial, list(trials["five_bar"].labels), with_b5_gap(trials["five_bar"]), 100.0)
    before = digest(trial)
    out = tmp_path / "out.h5"
    result = run_cli("solve", FIVE_BAR, trial, "-o", out, "--skip-unsolvable")
    assert digest(trial) == before
    if result.exception is not None and not isinstance(result.exception, SystemExit):
        raise result.exception
    solved(result)
    warnings = [line for line in result.stderr.splitlines()
                if re.search(rf"frame index {GAP_FRAME}\b", line)]
    assert len(warnings) == 1, result.stderr
    assert warnings[0].startswith("fccgrb: warning: ")
    assert "missing: P6)" in warnings[0] and "unsolved" in warnings[0]
    assert "fccgrb: error:" not in result.stderr
    run = runs(out)["nrm-wls"]
    assert not run["converged"][GAP_FRAME] or np.isnan(run["q"][GAP_FRAME]).all()
    others = np.delete(np.arange(100), GAP_FRAME)
    assert run["converged"][others].all()


# ---- TRC ----------------------------------------------------------------------------------


@pytest.mark.parametrize("units", ["mm", "m"])
def test_trc_round_trip(tmp_path: Path, units: str) -> None:
    rng = np.random.default_rng(11)
    labels = ["P1", "r asis", "Subj:HEEL", "last"]
    markers = rng.uniform(-2.0, 2.0, (25, 4, 3)) * rng.choice([1.0, 1e-3], (25, 4, 3))
    markers[0, 0] = 0.0
    markers[3, 1] = np.nan  # a gap in the middle of a row
    markers[4, 3] = np.nan  # a gap at the end of a row: trailing empty fields
    markers[5, 0] = np.nan  # a gap at the start of a row
    path = tmp_path / "x.trc"
    write_trial(path, labels, markers, 120.0, units)
    text = path.read_text(encoding="utf-8").split("\n")
    assert text[2].split("\t")[4] == units
    assert "\t\t\t\t" in text[6 + 3]  # frame 4: three empty fields between two tabs each
    assert text[6 + 4].endswith("\t\t\t")
    trial = read_trial(path)
    assert trial.labels == tuple(labels)
    assert trial.rate == 120.0
    assert trial.markers.shape == markers.shape
    gaps = np.isnan(markers)
    np.testing.assert_array_equal(np.isnan(trial.markers), gaps)
    # 9 significant digits in the file's units: relative error ≤ 5e-9 (plus the unit scaling)
    np.testing.assert_allclose(trial.markers[~gaps], markers[~gaps], rtol=6e-9, atol=1e-300)
    assert listing(tmp_path) == ["x.trc"]


def test_trc_header_with_several_tabs_between_values(tmp_path: Path) -> None:
    """A header whose values' line puts two tabs (and spaces) between its fields where the
    keys' line has one, as opensim-models' Rajagopal walk does, reads as OpenSim reads it: empty
    header fields are skipped (a data row's are gaps, kept)."""
    rng = np.random.default_rng(3)
    markers = rng.uniform(-1.0, 1.0, (12, 3, 3))
    markers[4, 1] = np.nan
    path = tmp_path / "tabs.trc"
    write_trial(path, ["A", "B", "C"], markers, 100.0, "mm")
    lines = path.read_text(encoding="utf-8").split("\n")
    lines[2] = "\t\t".join(f"  {v}" for v in lines[2].split("\t"))  # the keys' line as it was
    spaced = tmp_path / "spaced.trc"
    spaced.write_text("\n".join(lines), encoding="utf-8")
    plain, wide = read_trial(path), read_trial(spaced)
    assert wide.labels == plain.labels and wide.rate == plain.rate == 100.0
    np.testing.assert_array_equal(wide.markers, plain.markers)
    assert np.isnan(wide.markers[4, 1]).all()


def test_trc_in_metres_solves_to_the_c3d_angles(trials: dict[str, Synth],
                                                tmp_path: Path) -> None:
    synth = trials["five_bar"]
    source = tmp_path / "f.c3d"
    shutil.copyfile(synth.path, source)
    trc = tmp_path / "metres" / "f_m.trc"
    trc.parent.mkdir()
    result = run_cli("perturb", source, trc, "--level", "0", "--units", "m")
    solved(result)
    assert read_trial(trc).labels == synth.labels
    np.testing.assert_allclose(read_trial(trc).markers, synth.markers, rtol=6e-9, atol=1e-300)
    for trial, out in ((source, tmp_path / "c3d.h5"), (trc, tmp_path / "trc.h5")):
        solved(run_cli("solve", FIVE_BAR, trial, "-o", out))
    theta_c3d = runs(tmp_path / "c3d.h5")["nrm-wls"]["theta"]
    theta_trc = runs(tmp_path / "trc.h5")["nrm-wls"]["theta"]
    assert theta_c3d.shape == (100, 9)
    assert np.abs(theta_trc - theta_c3d).max() < 1e-6


# ---- C3D gaps -----------------------------------------------------------------------------


def c3d_with_gap(source: Path, target: Path, marker: int, frame: int, how: str) -> None:
    c3d = ezc3d.c3d(str(source))
    if how == "residual":
        residuals = np.array(c3d["data"]["meta_points"]["residuals"])
        residuals[0, marker, frame] = -1.0
        c3d["data"]["meta_points"]["residuals"] = residuals
    else:
        points = np.array(c3d["data"]["points"])
        points[:3, marker, frame] = np.nan
        c3d["data"]["points"] = points
    c3d.write(str(target))


@pytest.mark.parametrize("how", ["residual", "nan-point"])
def test_c3d_gap_reads_as_nan_and_still_solves(trials: dict[str, Synth], tmp_path: Path,
                                               how: str) -> None:
    synth = trials["five_bar"]
    k, frame = synth.labels.index("P9"), 30
    trial = tmp_path / "gap.c3d"
    c3d_with_gap(synth.path, trial, k, frame, how)
    if how == "residual":
        assert ezc3d.c3d(str(trial))["data"]["meta_points"]["residuals"][0, k, frame] < 0
    before = digest(trial)
    read = read_trial(trial)
    expected = np.zeros(read.markers.shape, dtype=bool)
    expected[frame, k] = True
    np.testing.assert_array_equal(np.isnan(read.markers), expected)
    np.testing.assert_array_equal(read.markers[~expected], synth.markers[~expected])
    out = tmp_path / "out.h5"
    result = run_cli("solve", FIVE_BAR, trial, "-o", out)
    solved(result)
    assert "fccgrb: error" not in result.stderr
    run = runs(out)["nrm-wls"]
    assert run["converged"].all()
    # every frame, the gap's too, gives the YAML's closed-form angles (32-bit C3D: ~1e-6 rad)
    from five_bar_minimal import closed_form
    assert np.abs(run["theta"] - closed_form(np.arange(100) / synth.rate)).max() < 1e-5
    assert np.isnan(run["markers_input"][frame, k]).all()
    # P2 and P3 still place B2: the gap frame's model points stay on the other markers
    others = [j for j in range(9) if j != k]
    assert np.nanmax(run["ed_input"][frame, others]) < 1e-6
    assert digest(trial) == before
    assert sorted(listing(tmp_path)) == ["gap.c3d", "out.h5"]


# ---- labels: prefixes and --map -----------------------------------------------------------


def test_prefixed_labels_solve_without_mapping(trials: dict[str, Synth], tmp_path: Path) -> None:
    synth = trials["pendulum"]
    trial = tmp_path / "subject.c3d"
    write_trial(trial, [f"Subj:{label}" for label in synth.labels], synth.markers, synth.rate)
    out = tmp_path / "out.h5"
    solved(run_cli("solve", PENDULUM, trial, "-o", out))
    run = runs(out)["nrm-wls"]
    assert run["converged"].all()
    np.testing.assert_allclose(run["markers_input"], synth.markers, atol=1e-12)


def test_renamed_labels_solve_with_map(trials: dict[str, Synth], tmp_path: Path) -> None:
    synth = trials["pendulum"]
    trial = tmp_path / "renamed.trc"
    # reversed file order: the mapping, not the position, decides
    write_trial(trial, ["M3", "M2", "M1"], synth.markers[:, ::-1], synth.rate)
    out = tmp_path / "out.h5"
    solved(run_cli("solve", PENDULUM, trial, "-o", out, "--map", "P1=M1,P2=M2", "--map",
                   "P3=M3"))
    run = runs(out)["nrm-wls"]
    assert run["converged"].all()
    np.testing.assert_allclose(run["markers_input"], synth.markers, atol=1e-9)
    assert np.nanmax(run["ed_input"]) < 1e-6


# ---- fccgrb perturb -----------------------------------------------------------------------


@pytest.fixture
def pendulum_copy(trials: dict[str, Synth], tmp_path: Path) -> Path:
    """The pendulum C3D and its truth sidecar, copied into the test's folder."""
    source = tmp_path / "p.c3d"
    shutil.copyfile(trials["pendulum"].path, source)
    shutil.copyfile(trials["pendulum"].path.with_name("p.truth.h5"), tmp_path / "p.truth.h5")
    return source


def test_perturb_level_seed_and_truth(pendulum_copy: Path, tmp_path: Path) -> None:
    source = pendulum_copy
    before = digest(source)
    truth_before = digest(tmp_path / "p.truth.h5")
    a, b, c = tmp_path / "a.c3d", tmp_path / "b.c3d", tmp_path / "c.c3d"
    for target, seed in ((a, 3), (b, 3), (c, 4)):
        solved(run_cli("perturb", source, target, "--level", "30", "--seed", seed))
    assert digest(source) == before
    assert digest(tmp_path / "p.truth.h5") == truth_before
    base = read_trial(source).markers
    out_a, out_b, out_c = (read_trial(p).markers for p in (a, b, c))
    peak = np.abs(out_a - base).max(axis=0)  # markers × axes, metres
    assert np.abs(peak - 0.030).max() < 2e-7, peak  # exactly 30 mm, to float32 precision
    np.testing.assert_array_equal(out_a, out_b)  # same seed, same markers
    assert np.abs(out_c - out_a).max() > 1e-3  # another seed, another artefact
    for target in (a, b, c):  # the truth sidecar is copied beside each output
        assert digest(target.with_name(target.stem + ".truth.h5")) == truth_before


def test_perturb_only_some_markers(pendulum_copy: Path, tmp_path: Path) -> None:
    target = tmp_path / "some.trc"
    solved(run_cli("perturb", pendulum_copy, target, "--level", "30", "--seed", "3",
                   "--markers", "P2"))
    base, out = read_trial(pendulum_copy).markers, read_trial(target).markers
    diff = np.abs(out - base).max(axis=0)
    assert np.abs(diff[1] - 0.030).max() < 1e-8
    assert diff[[0, 2]].max() < 1e-9


def test_perturb_refuses_its_input_as_output(pendulum_copy: Path, tmp_path: Path) -> None:
    before = digest(pendulum_copy)
    (tmp_path / "sub").mkdir()
    (tmp_path / "link.c3d").symlink_to(pendulum_copy)
    names = listing(tmp_path)
    for target in (pendulum_copy, tmp_path / "sub" / ".." / "p.c3d", tmp_path / "link.c3d"):
        result = run_cli("perturb", pendulum_copy, target, "--level", "30", "--seed", "3")
        one_error_line(result, str(target), "inputs are never modified")
    assert digest(pendulum_copy) == before
    assert listing(tmp_path) == names


def test_perturb_to_trc_beside_the_c3d(pendulum_copy: Path, tmp_path: Path) -> None:
    """Level 0 into a TRC in metres beside the C3D: the same markers (the TRC's 9 significant
    digits: ~1e-9 m), labels and rate, the header in m; the C3D and the truth sidecar the two
    files share by name (p.truth.h5) are left as they were."""
    target = tmp_path / "p.trc"
    truth = tmp_path / "p.truth.h5"
    before = {path: digest(path) for path in (pendulum_copy, truth)}
    result = run_cli("perturb", pendulum_copy, target, "--level", "0", "--units", "m")
    assert result.exception is None or isinstance(result.exception, SystemExit), \
        repr(result.exception)
    assert result.exit_code == 0
    source, written = read_trial(pendulum_copy), read_trial(target)
    assert written.labels == source.labels and written.rate == source.rate
    np.testing.assert_allclose(written.markers, source.markers, rtol=0, atol=1e-8)
    assert target.read_text(encoding="utf-8").splitlines()[2].split("\t")[4] == "m"
    assert {path: digest(path) for path in before} == before


# ---- the solve summary and the results file -----------------------------------------------


def test_summary_and_a_second_run(trials: dict[str, Synth], tmp_path: Path) -> None:
    synth = trials["pendulum"]
    out = tmp_path / "out.h5"
    first = run_cli("solve", PENDULUM, synth.path, "-o", out)
    solved(first)
    header, values = first.stdout.splitlines()[:2]
    positions = [header.find(column) for column in SUMMARY_COLUMNS]
    assert -1 not in positions and positions == sorted(positions), header
    cells = dict(zip(("run", *SUMMARY_COLUMNS), values.split(), strict=False))
    assert cells["run"] == cells["method"] == "nrm-wls"
    assert cells["failed"] == "0"
    assert float(cells["max ED mm"]) < 1e-3  # the truth markers are the reference
    assert "wrote run 'nrm-wls' (100 frames)" in first.stdout
    kept = runs(out)["nrm-wls"]

    second = run_cli("solve", PENDULUM, synth.path, "-o", out, "--method", "nrm-ls")
    solved(second)
    assert second.stdout.splitlines()[1].split()[:2] == ["nrm-ls", "nrm-ls"]
    both = runs(out)
    assert sorted(both) == ["nrm-ls", "nrm-wls"]
    for key, value in kept.items():
        np.testing.assert_array_equal(both["nrm-wls"][key], value)
    assert np.abs(both["nrm-ls"]["theta"] - kept["theta"]).max() < 1e-6
    assert sorted(listing(tmp_path)) == ["out.h5"]


@pytest.mark.parametrize("content", [b"not an HDF5 file\n", b""], ids=["text", "empty"])
def test_results_path_that_is_not_hdf5_is_refused(trials: dict[str, Synth], tmp_path: Path,
                                                  content: bytes) -> None:
    out = tmp_path / "out.h5"
    out.write_bytes(content)
    names = listing(tmp_path)
    result = run_cli("solve", PENDULUM, trials["pendulum"].path, "-o", out)
    one_error_line(result, str(out), "not an HDF5 results file")
    assert out.read_bytes() == content
    assert listing(tmp_path) == names


def test_results_path_equal_to_the_trial_is_refused(pendulum_copy: Path, tmp_path: Path) -> None:
    before, names = digest(pendulum_copy), listing(tmp_path)
    result = run_cli("solve", PENDULUM, pendulum_copy, "-o", pendulum_copy)
    one_error_line(result, str(pendulum_copy))
    assert digest(pendulum_copy) == before
    assert listing(tmp_path) == names


def test_results_path_equal_to_the_truth_sidecar_is_refused(pendulum_copy: Path,
                                                            tmp_path: Path) -> None:
    sidecar = tmp_path / "p.truth.h5"
    before = digest(sidecar)
    result = run_cli("solve", PENDULUM, pendulum_copy, "-o", sidecar)
    assert digest(sidecar) == before
    one_error_line(result, str(sidecar))


# ---- C3D files from commercial systems (shared/data, read in place) ------------------------


def shared_c3d(name: str) -> Path:
    path = SHARED_C3D / name
    if not path.is_file():
        pytest.skip(f"{path} is not present")
    return path


def test_qualisys_c3d() -> None:
    path = shared_c3d("Qualisys.c3d")
    before = digest(path)
    trial = read_trial(path)
    assert trial.n_frames == 340
    assert len(trial.labels) == 55
    assert trial.rate == 200.0
    assert trial.markers.shape == (340, 55, 3)
    # POINT:UNITS is mm: read in metres, so marker distances from the origin are ~0.1–2.5 m
    norms = np.linalg.norm(trial.markers, axis=2)
    assert 0.1 < np.nanmedian(norms) < 2.5
    assert np.nanmax(norms) < 5.0
    assert digest(path) == before


def test_fp_type1_c3d() -> None:
    path = shared_c3d("FP_Type1.c3d")
    before = digest(path)
    trial = read_trial(path)
    assert trial.n_frames == 634
    assert trial.rate == 100.0
    assert len(trial.labels) == trial.markers.shape[1] > 0
    norms = np.linalg.norm(trial.markers, axis=2)  # POINT:UNITS is m already
    assert 0.1 < np.nanmedian(norms) < 2.5
    assert np.nanmax(norms) < 5.0
    assert digest(path) == before


# ---- truncated trials ---------------------------------------------------------------------
#
# A copy interrupted in the data section must not read as a shorter trial. The expected frame
# counts come from outside fccgrb_cli.trial.c3d_header: ezc3d's own reading of POINT:DATA_START and
# of the cut files (it reads the whole frames present), and the frame size the C3D format gives
# (4 words per point, then the analog values; 4 bytes a word in float files, 2 in integer ones).

POINT_BYTES = 4 * 4  # x, y, z, residual as 32-bit floats


def data_start_byte(path: Path) -> int:
    """Where the data start, as ezc3d reads POINT:DATA_START (1-based 512-byte blocks)."""
    return (int(ezc3d.c3d(str(path))["parameters"]["POINT"]["DATA_START"]["value"][0]) - 1) * 512


def cut(source: Path | bytes, target: Path, size: int) -> Path:
    raw = source if isinstance(source, bytes) else source.read_bytes()
    target.write_bytes(raw[:size])
    return target


def ezc3d_frames(path: Path) -> int:
    return ezc3d.c3d(str(path))["data"]["points"].shape[2]


def input_error(path: Path, accept_truncated: bool = False) -> str:
    """read_trial's InputError message (one line)."""
    with pytest.raises(InputError) as caught:
        read_trial(path, accept_truncated)
    message = str(caught.value)
    assert "\n" not in message and str(path) in message, message
    return message


@pytest.fixture(scope="module")
def five_bar_300(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``fccgrb synth five_bar.yaml`` with its defaults: 300 frames (1–300) at 100 Hz, 9 markers."""
    path = tmp_path_factory.mktemp("synth300") / "x.c3d"
    solved(run_cli("synth", FIVE_BAR, "-o", path))
    return path


def test_copy_cut_at_byte_5000_is_one_line_naming_both_counts(five_bar_300: Path,
                                                               tmp_path: Path) -> None:
    held = (5000 - data_start_byte(five_bar_300)) // (9 * POINT_BYTES)
    assert held == 24
    trial = cut(five_bar_300, tmp_path / "cut.c3d", 5000)
    assert ezc3d_frames(trial) == held  # what ezc3d alone makes of it: a 24-frame trial
    before, names = digest(trial), listing(tmp_path)
    out = tmp_path / "out.h5"
    result = run_cli("solve", FIVE_BAR, trial, "-o", out)
    one_error_line(result, str(trial), "announces 300 frames (1–300)", "the data hold 24:",
                   "truncated", "--accept-truncated")
    assert result.stdout == ""
    assert not out.exists()
    assert listing(tmp_path) == names
    assert digest(trial) == before


def test_copy_cut_at_byte_5000_accepted_warns_in_summary_and_results(
        five_bar_300: Path, trials: dict[str, Synth], tmp_path: Path) -> None:
    trial = cut(five_bar_300, tmp_path / "cut.c3d", 5000)
    out = tmp_path / "out.h5"
    result = run_cli("solve", FIVE_BAR, trial, "-o", out, "--accept-truncated")
    solved(result)
    warnings = [line for line in result.stderr.splitlines() if "truncated" in line]
    assert len(warnings) == 1 and warnings[0].startswith("fccgrb: warning: "), result.stderr
    assert all(f in warnings[0] for f in (str(trial), "300 frames (1–300)", "only 24")), warnings
    assert "(24 frames)" in result.stdout
    with h5py.File(out, "r") as h5:
        run = h5["runs/nrm-wls"]
        stored = [str(w) for w in run.attrs["warnings"]]
        inputs = run["markers_input"][()]
    assert stored == [warnings[0].removeprefix("fccgrb: warning: ")]
    # the frames present, the first 24 of the complete file
    np.testing.assert_array_equal(inputs, read_trial(five_bar_300).markers[:24])
    # a complete trial stores no warning
    solved(run_cli("solve", PENDULUM, trials["pendulum"].path, "-o", tmp_path / "full.h5"))
    with h5py.File(tmp_path / "full.h5", "r") as h5:
        assert h5["runs/nrm-wls"].attrs["warnings"].shape == (0,)


def test_every_cut_in_the_data_section_is_detected(five_bar_300: Path, tmp_path: Path) -> None:
    raw = five_bar_300.read_bytes()
    start, frame = data_start_byte(five_bar_300), 9 * POINT_BYTES
    end = start + 300 * frame
    assert end <= len(raw) < end + 512  # the data, then the last block's padding
    full = read_trial(five_bar_300).markers
    rng = np.random.default_rng(12)
    sizes = {start + k * frame + r for k in (0, 1, 2, 150, 299) for r in (0, 1, frame - 1)}
    sizes |= set(rng.integers(start, end, 60).tolist())
    for size in sorted(sizes):
        held = (size - start) // frame
        path = cut(raw, tmp_path / f"cut{size}.c3d", size)
        message = input_error(path)
        assert "announces 300 frames (1–300)" in message and "truncated" in message, message
        if held == 0:
            assert "the data hold none" in message, message
            input_error(path, accept_truncated=True)  # nothing to read, even when accepted
            continue
        assert f"the data hold {held}:" in message and "--accept-truncated" in message, message
        trial = read_trial(path, accept_truncated=True)
        assert trial.n_frames == held == ezc3d_frames(path)
        assert len(trial.warnings) == 1 and f"only {held}" in trial.warnings[0]
        np.testing.assert_array_equal(trial.markers, full[:held])
    for size in (end, end + 1, len(raw) - 1, len(raw)):  # all 300 frames there: complete
        trial = read_trial(cut(raw, tmp_path / f"whole{size}.c3d", size))
        assert trial.n_frames == 300 and trial.warnings == ()


def test_every_cut_in_the_header_or_parameters_is_one_line(five_bar_300: Path,
                                                           tmp_path: Path) -> None:
    raw = five_bar_300.read_bytes()
    start = data_start_byte(five_bar_300)
    assert raw[0] == 2 and start == 3 * 512  # the header, two parameter blocks, the data
    path = tmp_path / "cut.c3d"
    for size in range(1, start):
        message = input_error(cut(raw, path, size))
        where = ("inside its 512-byte header" if size < 512 else
                 "before its parameter section (byte 512)" if size == 512 else
                 "inside its parameter section's header (bytes 512–515)" if size < 516 else
                 "inside its parameter section (bytes 512–1535)")
        assert f"ends at byte {size}, {where}" in message, message
        assert "300 frames (1–300)" in message or size < 516
        assert "truncated" in message
    assert "not a readable C3D file" in input_error(cut(raw, path, 0))
    for size in (100, 1000):
        one_error_line(run_cli("solve", FIVE_BAR, cut(raw, path, size), "-o", tmp_path / "o.h5"),
                       str(path), f"ends at byte {size}", "truncated")
        one_error_line(run_cli("solve", FIVE_BAR, path, "-o", tmp_path / "o.h5",
                               "--accept-truncated"), str(path), "truncated")
    assert not (tmp_path / "o.h5").exists()


def test_damaged_header_or_parameters_give_an_input_error_or_a_layout(five_bar_300: Path,
                                                                      tmp_path: Path) -> None:
    """Bytes changed at random in the header and parameter section: never a crash (IndexError,
    struct.error, …), either a layout or one line."""
    raw = bytearray(five_bar_300.read_bytes())
    rng = np.random.default_rng(5)
    path = tmp_path / "damaged.c3d"
    for _ in range(300):
        damaged = raw.copy()
        for at in rng.integers(0, 1536, rng.integers(1, 5)):
            damaged[at] = int(rng.integers(0, 256))
        path.write_bytes(bytes(damaged[: int(rng.integers(1, len(raw)))]))
        try:
            read_layout(path)
        except InputError as exc:
            assert "\n" not in str(exc) and str(path) in str(exc)


def analog_trial(path: Path, frames: int = 50) -> Path:
    """An ezc3d file with 3 points and 2 analog channels at 10 samples per frame."""
    rng = np.random.default_rng(3)
    c3d = ezc3d.c3d()
    c3d["parameters"]["POINT"]["RATE"]["value"] = [100.0]
    c3d["parameters"]["POINT"]["LABELS"]["value"] = ["A", "B", "C"]
    c3d["parameters"]["ANALOG"]["RATE"]["value"] = [1000.0]
    c3d["parameters"]["ANALOG"]["LABELS"]["value"] = ["E1", "E2"]
    points = np.ones((4, 3, frames))
    points[:3] = rng.uniform(-1000, 1000, (3, 3, frames))
    c3d["data"]["points"] = points
    c3d["data"]["analogs"] = rng.uniform(-1, 1, (1, 2, 10 * frames))
    c3d.write(str(path))
    return path


def analog_values_per_frame(path: Path) -> int:
    """Channels × samples per frame, from ezc3d's analog array (1 × channels × samples)."""
    c3d = ezc3d.c3d(str(path))
    analogs, frames = c3d["data"]["analogs"], c3d["data"]["points"].shape[2]
    return analogs.shape[1] * analogs.shape[2] // frames


@pytest.mark.parametrize("name", ["analog", "Qualisys.c3d", "FP_Type1.c3d"])
def test_files_with_analog_data_complete_and_cut(name: str, tmp_path: Path) -> None:
    source = analog_trial(tmp_path / "a.c3d") if name == "analog" else shared_c3d(name)
    frames, points = ezc3d_frames(source), ezc3d.c3d(str(source))["data"]["points"].shape[1]
    frame = (4 * points + analog_values_per_frame(source)) * 4
    if name == "analog":
        assert frame == (4 * 3 + 20) * 4
    layout = read_layout(source)
    assert (layout.frames, layout.frame_bytes, layout.truncated) == (frames, frame, False)
    assert read_trial(source).warnings == ()
    start = data_start_byte(source)
    for k, r in ((1, 0), (frames // 3, 7), (frames - 1, frame - 1)):
        path = cut(source, tmp_path / "cut.c3d", start + k * frame + r)
        assert ezc3d_frames(path) == k
        message = input_error(path)
        assert f"announces {frames} frames" in message and f"the data hold {k}:" in message
        assert read_trial(path, accept_truncated=True).n_frames == k


# C3D files as DEC and MIPS processors and integer data write them, recoded from an ezc3d file
# (Intel, floats) with the record layout of the C3D User Guide; ezc3d reads DEC and integer
# files back (MIPS it refuses), which checks the recoding.

PROCESSOR_BYTE = {"Intel": 84, "DEC": 85, "MIPS": 86}


def int8(byte: int) -> int:
    """A byte read as a signed 8-bit integer."""
    return byte - 256 if byte > 127 else byte


def float_bytes(values: np.ndarray, processor: str) -> bytes:
    values = np.asarray(values, dtype=float)
    if processor == "MIPS":
        return values.astype(">f4").tobytes()
    if processor == "Intel":
        return values.astype("<f4").tobytes()
    # VAX F: the IEEE bits of 4 × value (exponent bias 128, hidden bit ½) in swapped 16-bit words
    ieee = np.frombuffer((4.0 * values).astype("<f4").tobytes(), np.uint8).reshape(-1, 4)
    return ieee[:, [2, 3, 0, 1]].tobytes()


def recoded(raw: bytes, processor: str, points: int, frames: int,
            integer_scale: float | None = None) -> bytes:
    """An Intel float C3D rewritten for ``processor``, with 16-bit integer data scaled by
    ``integer_scale`` when given (residual word 0, or -1 for a gap)."""
    words = ">i2" if processor == "MIPS" else "<i2"
    out = bytearray(raw)
    for at in (2, 4, 6, 8, 10, 16, 18):  # header words
        out[at:at + 2] = np.frombuffer(raw[at:at + 2], "<u2").astype(words.replace("i", "u"))\
            .tobytes()
    for at in (12, 20):  # header floats: scale, rate
        value = np.frombuffer(raw[at:at + 4], "<f4")
        if at == 12 and integer_scale is not None:
            value = np.array([integer_scale])
        out[at:at + 4] = float_bytes(value, processor)
    section = (raw[0] - 1) * 512
    out[section + 3] = PROCESSOR_BYTE[processor]
    pos, groups = section + 4, {}
    while True:  # group and parameter records: name length, id, name, offset to the next, …
        length, group = abs(int8(raw[pos])), int8(raw[pos + 1])
        if length == 0:
            break
        name = raw[pos + 2:pos + 2 + length].decode()
        at = pos + 2 + length
        offset = int(np.frombuffer(raw[at:at + 2], "<i2")[0])
        out[at:at + 2] = np.array([offset]).astype(words).tobytes()
        if group < 0:
            groups[-group] = name
        else:
            kind, n_dims = int8(raw[at + 2]), raw[at + 3]
            data = at + 4 + n_dims
            count = int(np.prod(list(raw[at + 4:data]))) if n_dims else 1
            if kind == 2:
                values = np.frombuffer(raw[data:data + 2 * count], "<i2")
                out[data:data + 2 * count] = values.astype(words).tobytes()
            elif kind == 4:
                values = np.frombuffer(raw[data:data + 4 * count], "<f4")
                if (groups[group], name) == ("POINT", "SCALE") and integer_scale is not None:
                    values = np.array([integer_scale])
                out[data:data + 4 * count] = float_bytes(values, processor)
        if offset == 0:
            break
        pos = at + offset
    start = (int(np.frombuffer(raw[16:18], "<u2")[0]) - 1) * 512
    data = np.frombuffer(raw[start:start + frames * points * 16], "<f4").reshape(-1, 4)
    if integer_scale is None:
        out[start:start + data.size * 4] = float_bytes(data, processor)
        return bytes(out)
    ints = np.round(data / integer_scale).astype(int)
    ints[:, 3] = np.where(data[:, 3] < 0, -1, 0)
    body = ints.astype(words).tobytes()
    body += bytes(-len(body) % 512)
    return bytes(out[:start]) + body


FORMATS = [("Intel", None), ("DEC", None), ("MIPS", None), ("Intel", 0.1), ("DEC", 0.1),
           ("MIPS", 0.1)]  # 0.1 mm: the five-bar's ±1.5 m stay inside 16 bits


@pytest.mark.parametrize(("processor", "scale"), FORMATS,
                         ids=[f"{p}-{'int' if s else 'float'}" for p, s in FORMATS])
def test_processor_types_and_integer_data(trials: dict[str, Synth], tmp_path: Path,
                                          processor: str, scale: float | None) -> None:
    synth = trials["five_bar"]
    raw = recoded(synth.path.read_bytes(), processor, 9, 100, scale)
    path = tmp_path / "recoded.c3d"
    path.write_bytes(raw)
    layout = read_layout(path)
    frame = 9 * 4 * (2 if scale else 4)
    assert (layout.processor, layout.float_data, layout.points, layout.frames,
            layout.frame_bytes, layout.truncated) == (processor, scale is None, 9, 100, frame,
                                                      False)
    start = data_start_byte(synth.path)
    if processor != "MIPS":  # ezc3d reads the recoded file back as the original (mm → m)
        trial = read_trial(path)
        np.testing.assert_allclose(trial.markers, synth.markers, rtol=0,
                                   atol=1e-12 if scale is None else 0.51 * scale * 1e-3)
    for held in (1, 40, 99):
        size = start + held * frame + frame // 2
        message = input_error(cut(raw, tmp_path / "cut.c3d", size))
        assert "announces 100 frames (1–100)" in message and f"the data hold {held}:" in message
        if processor != "MIPS":
            assert ezc3d_frames(tmp_path / "cut.c3d") == held


def test_dec_and_mips_floats_decode_known_values() -> None:
    """VAX F 1.0 is the longword 0x00004080 (bytes 80 40 00 00); −2.5 is 20 C1 00 00."""
    dec = decode_floats(bytes([0x80, 0x40, 0, 0, 0x20, 0xC1, 0, 0, 0, 0, 0, 0]), "DEC")
    np.testing.assert_array_equal(dec, [1.0, -2.5, 0.0])
    np.testing.assert_array_equal(decode_floats(bytes([0x3F, 0x80, 0, 0]), "MIPS"), [1.0])
    np.testing.assert_array_equal(decode_floats(bytes([0, 0, 0x80, 0x3F]), "Intel"), [1.0])


def test_more_than_65535_frames(tmp_path: Path) -> None:
    """ezc3d writes POINT:FRAMES 65535 (-1) past 65535 frames and reads 65535 back: without
    TRIAL or LONG_FRAMES the count is lost (one line); with them, the count is known, a cut is
    detected, and the frames ezc3d drops are read from the data section (tests/test_long_c3d.py),
    not lost to a shorter trial."""
    n = 70000
    c3d = ezc3d.c3d()
    c3d["parameters"]["POINT"]["RATE"]["value"] = [100.0]
    c3d["parameters"]["POINT"]["LABELS"]["value"] = ["A"]
    points = np.ones((4, 1, n))
    points[0, 0] = np.arange(n)
    c3d["data"]["points"] = points
    bare = tmp_path / "bare.c3d"
    c3d.write(str(bare))
    message = input_error(bare)
    assert "65535" in message and "split the trial" in message
    first, last = 100000, 100000 + n - 1  # 32-bit frame numbers: low word, high word
    c3d.add_parameter("TRIAL", "ACTUAL_START_FIELD", [first % 65536, first // 65536])
    c3d.add_parameter("TRIAL", "ACTUAL_END_FIELD", [last % 65536, last // 65536])
    trial = tmp_path / "trial.c3d"
    c3d.write(str(trial))
    layout = read_layout(trial)
    assert (layout.frames, layout.first_frame, layout.last_frame) == (n, first, last)
    assert not layout.truncated
    whole = read_trial(trial)
    assert whole.markers.shape == (n, 1, 3)
    np.testing.assert_allclose(whole.markers[:, 0, 0], np.arange(n) * 1e-3, rtol=1e-7)
    start = data_start_byte(trial)
    message = input_error(cut(trial, tmp_path / "cut.c3d", start + 40000 * 16 + 5))
    assert f"announces {n} frames ({first}–{last})" in message, message
    assert "the data hold 40000:" in message
    c3d.add_parameter("POINT", "LONG_FRAMES", [float(n - 1)])  # wins over TRIAL
    long = tmp_path / "long.c3d"
    c3d.write(str(long))
    assert read_layout(long).frames == n - 1


def test_point_frames_not_the_header_range_is_the_count(five_bar_300: Path,
                                                        tmp_path: Path) -> None:
    """The header's words 4–5 may be the raw frame numbers; POINT:FRAMES (300) is the master
    copy of the count (C3D User Guide), and ezc3d reads 300 frames either way."""
    raw = bytearray(five_bar_300.read_bytes())
    assert np.frombuffer(bytes(raw[6:10]), "<u2").tolist() == [1, 300]
    start, frame = data_start_byte(five_bar_300), 9 * POINT_BYTES
    for last in (200, 400):
        raw[8:10] = np.array([last], "<u2").tobytes()
        path = tmp_path / f"last{last}.c3d"
        path.write_bytes(bytes(raw))
        assert ezc3d_frames(path) == 300
        assert read_trial(path).n_frames == 300
        message = input_error(cut(bytes(raw), tmp_path / "cut.c3d", start + 250 * frame))
        assert "POINT:FRAMES announces 300 frames" in message and "hold 250:" in message


# ---- truncated TRC ------------------------------------------------------------------------


def test_trc_with_fewer_rows_than_num_frames(trials: dict[str, Synth], tmp_path: Path) -> None:
    synth = trials["pendulum"]
    text = "\n".join(trc_lines(tmp_path, synth))
    header, rows = 6, text.split("\n")[6:]
    assert text.split("\n")[2].split("\t")[2] == "100"  # NumFrames
    path = tmp_path / "short.trc"
    # whole rows missing (the copy stopped at a line end)
    path.write_text("\n".join(text.split("\n")[:header + 60]) + "\n", encoding="utf-8")
    message = input_error(path)
    assert "announces 100 frames (NumFrames" in message and "the data hold 60:" in message
    assert read_trial(path, accept_truncated=True).n_frames == 60
    # a cut inside the last field of row 50: that row's last value would be wrong, it is dropped
    cut_at = len("\n".join(text.split("\n")[:header + 50])) - 2
    assert rows[49][-3:].strip("\t").replace(".", "").isdigit()
    path.write_text(text[:cut_at], encoding="utf-8")
    assert "the data hold 49:" in input_error(path)
    trial = read_trial(path, accept_truncated=True)
    assert trial.n_frames == 49 and len(trial.warnings) == 1
    np.testing.assert_allclose(trial.markers, synth.markers[:49], rtol=6e-9, atol=1e-300)
    one_error_line(run_cli("solve", PENDULUM, path, "-o", tmp_path / "o.h5"), str(path),
                   "100 frames", "the data hold 49:", "--accept-truncated")
    complete = tmp_path / "complete.trc"
    complete.write_text(text, encoding="utf-8")
    assert read_trial(complete).warnings == ()


# ---- the other commands that read trials --------------------------------------------------


def test_perturb_calibrate_and_sweep_refuse_a_cut_trial_unless_told(five_bar_300: Path,
                                                                    tmp_path: Path) -> None:
    trial = cut(five_bar_300, tmp_path / "cut.c3d", 5000)
    target = tmp_path / "p.c3d"
    one_error_line(run_cli("perturb", trial, target, "--level", "30"), str(trial), "hold 24:")
    assert not target.exists()
    result = run_cli("perturb", trial, target, "--level", "30", "--accept-truncated")
    solved(result)
    assert "fccgrb: warning: " in result.stderr and "only 24" in result.stderr
    assert read_trial(target).n_frames == 24
    template = MODELS / "lower_limb.yaml"
    one_error_line(run_cli("calibrate", template, trial, "-o", tmp_path / "m.yaml"),
                   str(trial), "hold 24:")
    config = tmp_path / "sweep.yaml"
    config.write_text(yaml.safe_dump({
        "name": "cut", "table": "table2", "model": str(FIVE_BAR), "trial": {"file": "cut.c3d"},
        "cells": [{"method": "nrm-wls", "tol": 1e-10, "level": 0}]}), encoding="utf-8")
    out = tmp_path / "sweep.h5"
    one_error_line(run_cli("sweep", config, "-o", out), str(trial), "hold 24:")
    assert not out.exists()
    result = run_cli("sweep", config, "-o", out, "--accept-truncated")
    solved(result)
    assert "only 24" in result.stderr
    with h5py.File(out, "r") as h5:
        (cell,) = h5["cells"].values()
        assert "only 24" in str(cell["runs/run"].attrs["warnings"][0])


def test_messages_count_time_on_the_trial_files_clock():
    """A trial whose first frame is at 2 s (a C3D's first frame, a TRC's first Time): its
    warnings give the times its events and exports use, not the time since its first frame."""
    import fccgrb_cli as fc
    from fccgrb_cli.core.stretches import clocked
    from fccgrb_cli.model import load_model
    from fccgrb_cli.pipeline.synth import synthesize
    from fccgrb_cli.trial.record import Trial

    assert clocked("x (t = 0.100 s) and t = 0.200–0.300 s", 2.0) == \
        "x (t = 2.100 s) and t = 2.200–2.300 s"
    assert clocked("t = 0.100 s", 0.0) == "t = 0.100 s"
    model = load_model(FIVE_BAR)
    truth = synthesize(model, duration=0.5, rate=100.0)
    markers = truth.markers.copy()
    markers[10:13] = np.nan  # frames 10–12 without markers: flagged
    trial = Trial("late.trc", tuple(truth.labels), markers, truth.rate, start=2.0)
    with pytest.raises(InputError, match=r"frame index 10 \(t = 2\.100 s\)"):
        fc.solve(model, trial)
    run = fc.solve(model, trial, skip_unsolvable=True)
    said = " ".join((*run.result.messages, *run.warnings))
    assert "t = 2.100 s" in said and "t = 0.100 s" not in said
    assert run.angles.time[0] == pytest.approx(2.0)  # the API's times: the same clock

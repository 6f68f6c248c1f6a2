"""A lab's marker names: `--map FILE.yaml` beside inline `--map NAME=LABEL`, and an error for a
label not found that names the file's closest labels."""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest
from cli_helpers import one_error_line, run_cli

import fccgrb_cli as fc
from fccgrb_cli.trial.c3d import write_markers

ROOT = Path(__file__).resolve().parents[1]
MODEL = ROOT / "configs" / "models" / "five_bar.yaml"
TRIAL = ROOT / "sample_data" / "five_bar.c3d"
LAB = {"P1": "LAB_base", "P4": "LAB_elbow", "P9": "LAB_tip"}


@pytest.fixture(scope="module")
def renamed(tmp_path_factory) -> Path:
    """The sample trial with three markers under a lab's own names."""
    trial = fc.read_trial(TRIAL)
    out = tmp_path_factory.mktemp("maps") / "lab.c3d"
    write_markers(out, [LAB.get(n, n) for n in trial.labels], trial.markers, trial.rate)
    return out


def _theta(path: Path) -> np.ndarray:
    with h5py.File(path) as h5:
        (group,) = h5["runs"].values()
        return group["theta"][()]


def test_a_map_file_solves_as_the_same_pairs_inline(renamed: Path, tmp_path: Path):
    table = tmp_path / "lab.yaml"
    table.write_text("".join(f"{k}: {v}\n" for k, v in LAB.items()), encoding="utf-8")
    by_file, inline = tmp_path / "file.h5", tmp_path / "inline.h5"
    common = ["solve", MODEL, renamed, "--no-dynamics"]
    assert run_cli(*common, "--map", table, "-o", by_file).exit_code == 0
    pairs = ",".join(f"{k}={v}" for k, v in LAB.items())
    assert run_cli(*common, "--map", pairs, "-o", inline).exit_code == 0
    np.testing.assert_array_equal(_theta(by_file), _theta(inline))
    assert np.isfinite(_theta(by_file)).all()


def test_without_the_map_the_error_names_the_closest_labels(renamed: Path):
    result = run_cli("solve", MODEL, renamed, "-o", "never.h5")
    line = one_error_line(result, str(renamed), "P1 (closest:", "no marker follows: LAB_base")
    assert "P4 (closest:" in line and "--map FILE.yaml" in line
    assert not Path("never.h5").exists()


def test_a_map_naming_no_model_marker_suggests_the_model_names(renamed: Path):
    one_error_line(run_cli("solve", MODEL, renamed, "--map", "P10=LAB_tip", "-o", "x.h5"),
                   "--map: expected marker names of the model (P1, P2", "P10 (closest: P1")


@pytest.mark.parametrize(("text", "expected"), [
    ("P1: [LAB_base]\n", "expected a mapping of model marker names to trial labels"),
    ("P1: LAB_base\n  P4: : x\n", "invalid YAML"),
])
def test_a_malformed_map_file_is_one_line(renamed: Path, tmp_path: Path, text: str,
                                          expected: str):
    table = tmp_path / "bad.yaml"
    table.write_text(text, encoding="utf-8")
    one_error_line(run_cli("solve", MODEL, renamed, "--map", table, "-o", tmp_path / "x.h5"),
                   str(table), expected)


def test_a_missing_map_file_is_one_line(renamed: Path, tmp_path: Path):
    one_error_line(run_cli("solve", MODEL, renamed, "--map", tmp_path / "none.yaml", "-o",
                           tmp_path / "x.h5"), "none.yaml", "label map not found")


def test_a_file_without_points_says_so():
    """A C3D with no 3D points at all (Theia's rotations-only files, an analog-only capture):
    one line saying the file holds none and naming the markers the model wants, instead of a
    'closest: none' for each of them."""
    from fccgrb_cli.trial.labels import match_labels
    from fccgrb_cli.trial.record import Trial

    model = fc.load_model(ROOT / "configs" / "models" / "pendulum.yaml")
    empty = Trial("rotations.c3d", (), np.zeros((50, 0, 3)), 100.0)
    with pytest.raises(fc.InputError, match=r"^rotations\.c3d: the file holds no marker "
                                            r"trajectories.*P1, P2, P3$"):
        match_labels(model, empty, {})

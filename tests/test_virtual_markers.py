"""Virtual markers (model/virtual.py, io/virtual.py): ``mid(A, B)`` and ``mean(A, B, ...)`` of a
trial's labels, named in a label map or a model file's ``virtual_markers`` section.

The references are built here: a trial whose marker P1 is replaced by two markers placed
symmetrically about it (so their midpoint is P1 exactly) solves to the same angles as the
original, by either route.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from cli_helpers import one_error_line, run_cli

import fccgrb_cli as fc
from fccgrb_cli.core.errors import InputError
from fccgrb_cli.model.virtual import canonical
from fccgrb_cli.pipeline.options import SolveOptions
from fccgrb_cli.trial.record import Trial, write_trial
from fccgrb_cli.trial.virtual import with_virtual

ROOT = Path(__file__).resolve().parents[1]
MODEL = ROOT / "configs" / "models" / "five_bar.yaml"
TRIAL = ROOT / "sample_data" / "five_bar.c3d"


def test_mid_and_mean_frame_by_frame_with_gaps():
    rng = np.random.default_rng(4)
    markers = rng.normal(size=(20, 3, 3))
    markers[5, 1] = np.nan
    trial = Trial("t.c3d", ("A", "B", "C"), markers, 100.0)
    out = with_virtual(trial, {"--map X": "mid( A , B )", "--map Y": "mean(A,B,C)"})
    assert out.labels == ("A", "B", "C", "mid(A,B)", "mean(A,B,C)")
    np.testing.assert_allclose(out.markers[:, 3], 0.5 * (markers[:, 0] + markers[:, 1]))
    np.testing.assert_allclose(out.markers[:, 4], markers.sum(axis=1) / 3)
    assert np.isnan(out.markers[5, 3]).all() and np.isnan(out.markers[5, 4]).all()
    assert np.isfinite(out.markers[4, 3:]).all()


@pytest.mark.parametrize("text,message", [
    ("mid(A)", "mid takes exactly 2 markers"),
    ("mid(A,B,C)", "mid takes exactly 2 markers"),
    ("mean(A)", "mean takes at least 2 markers"),
    ("max(A,B)", "expected a function of mid, mean"),
    ("mid(A,)", "expected marker labels"),
    ("mid(A,mid(B,C))", "expected marker labels"),
    ("mid(A,A)", "expected different markers"),
    ("mid A,B", "expected a virtual marker"),
])
def test_malformed_expressions_are_refused_naming_where(text, message):
    with pytest.raises(InputError, match=message) as caught:
        canonical(text, "--map SACR")
    assert str(caught.value).startswith("--map SACR: ")


def test_unknown_label_names_the_trial_and_the_definition():
    trial = Trial("t.c3d", ("A", "B"), np.zeros((2, 2, 3)), 100.0)
    with pytest.raises(InputError, match=r"t\.c3d: expected the marker Q \(used by --map X"):
        with_virtual(trial, {"--map X": "mid(A,Q)"})


def test_map_value_with_commas_inside_parentheses():
    options = SolveOptions.from_mapping({"map": "SACR=mid(LPSI,RPSI),RASI=R_IAS"})
    assert options.mapping == (("SACR", "mid(LPSI,RPSI)"), ("RASI", "R_IAS"))


@pytest.fixture(scope="module")
def split_trial(tmp_path_factory) -> tuple[Path, fc.Run]:
    """The sample trial with P1 replaced by P1a, P1b 40 mm either side of it."""
    trial = fc.read_trial(TRIAL)
    k = trial.labels.index("P1")
    offset = np.array([0.02, -0.03, 0.0])
    markers = np.concatenate([np.delete(trial.markers, k, axis=1),
                              trial.markers[:, k:k + 1] + offset,
                              trial.markers[:, k:k + 1] - offset], axis=1)
    labels = [label for label in trial.labels if label != "P1"] + ["P1a", "P1b"]
    path = tmp_path_factory.mktemp("virtual") / "split.trc"
    write_trial(path, labels, markers, trial.rate, units="m")
    reference = fc.solve(fc.load_model(MODEL), trial, dynamics=False)
    return path, reference


def test_solve_through_a_mapped_virtual_marker(split_trial):
    path, reference = split_trial
    run = fc.solve(fc.load_model(MODEL), fc.read_trial(path), dynamics=False,
                   mapping={"P1": "mid(P1a,P1b)"})
    np.testing.assert_allclose(run.result.theta, reference.result.theta, atol=1e-8)


def test_solve_through_a_model_files_virtual_marker(split_trial, tmp_path):
    path, reference = split_trial
    text = MODEL.read_text(encoding="utf-8") + "\nvirtual_markers:\n  P1: mid(P1a, P1b)\n"
    model = tmp_path / "five_bar_virtual.yaml"
    model.write_text(text, encoding="utf-8")
    run = fc.solve(fc.load_model(model), fc.read_trial(path), dynamics=False)
    np.testing.assert_allclose(run.result.theta, reference.result.theta, atol=1e-8)
    bad = tmp_path / "bad.yaml"
    bad.write_text(MODEL.read_text(encoding="utf-8") + "\nvirtual_markers:\n  P1: mid(P1a)\n",
                   encoding="utf-8")
    one_error_line(run_cli("check", bad), "bad.yaml: virtual_markers.P1: mid takes exactly 2")
    one_error_line(run_cli("solve", MODEL, path, "--map", "P1=mid(P1a,P1c)", "-o",
                           tmp_path / "x.h5"), "expected the marker P1c", "--map P1")

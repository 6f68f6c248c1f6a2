"""``fccgrb perturb`` then ``fccgrb solve`` is judged like ``fccgrb solve --perturb``: the
artefact level is recorded in the perturbed file (a C3D parameter, a TRC header key), read
back with the trial, and allowed for by the fit check as the run's own perturbation is, so the
same frames are trusted. Without the record the same markers are judged a poor fit (the guard
that this test can fail).

Independent reference: the run that perturbs its markers itself, on the same unperturbed
trial with the same level and seed.
"""

from __future__ import annotations

from pathlib import Path

import ezc3d
import numpy as np
import pytest
from cli_helpers import run_cli

from fccgrb_cli.core.errors import InputError
from fccgrb_cli.results.runs import read_runs
from fccgrb_cli.trial.record import read_trial

ROOT = Path(__file__).resolve().parents[1]
MODEL = ROOT / "configs" / "models" / "five_bar.yaml"
TRIAL = ROOT / "sample_data" / "five_bar.c3d"


def ok(result):
    assert result.exit_code == 0, result.output + result.stderr
    return result


def trusted(path: Path) -> np.ndarray:
    (run,) = read_runs(path).values()
    return run.trusted


@pytest.fixture(scope="module")
def judged(tmp_path_factory):
    folder = tmp_path_factory.mktemp("perturbed")
    ok(run_cli("solve", MODEL, TRIAL, "--perturb", "30", "-o", folder / "self.h5"))
    out = {"self": trusted(folder / "self.h5")}
    for ending in ("c3d", "trc"):
        target = folder / f"p.{ending}"
        ok(run_cli("perturb", TRIAL, target, "--level", "30"))
        ok(run_cli("solve", MODEL, target, "-o", folder / f"{ending}.h5"))
        out[ending] = trusted(folder / f"{ending}.h5")
    c3d = ezc3d.c3d(str(folder / "p.c3d"))
    del c3d["parameters"]["FCCGRB"]["ARTEFACT_MM"]
    c3d.write(str(folder / "bare.c3d"))
    ok(run_cli("solve", MODEL, folder / "bare.c3d", "-o", folder / "bare.h5"))
    out["bare"] = trusted(folder / "bare.h5")
    return folder, out


def test_perturb_then_solve_trusts_the_frames_solve_perturb_trusts(judged):
    _, runs = judged
    assert runs["self"].all()
    np.testing.assert_array_equal(runs["c3d"], runs["self"])
    np.testing.assert_array_equal(runs["trc"], runs["self"])
    assert (~runs["bare"]).sum() > 10  # the same markers, their level not known: poor fit


def test_the_level_reads_back_and_adds_up(judged, tmp_path):
    folder, _ = judged
    assert read_trial(folder / "p.c3d").artefact_m == pytest.approx(0.030)
    assert read_trial(folder / "p.trc").artefact_m == pytest.approx(0.030)
    assert read_trial(TRIAL).artefact_m == 0.0
    ok(run_cli("perturb", folder / "p.trc", tmp_path / "twice.c3d", "--level", "7.5"))
    assert read_trial(tmp_path / "twice.c3d").artefact_m == pytest.approx(0.0375)


@pytest.mark.parametrize("value", ["-5", "nan", "lots"])
def test_a_bad_recorded_level_names_the_file_and_key(judged, tmp_path, value):
    folder, _ = judged
    lines = (folder / "p.trc").read_text(encoding="utf-8").split("\n")
    lines[2] = lines[2].rsplit("\t", 1)[0] + "\t" + value
    bad = tmp_path / "bad.trc"
    bad.write_text("\n".join(lines), encoding="utf-8")
    with pytest.raises(InputError, match=r"bad\.trc: line 3: FccgrbArtefactMM: expected"):
        read_trial(bad)

"""Trials of a few frames: solved, or refused in one line naming the file and
the frames needed; never a traceback, never a rate that reads as a body at rest.

A 2-frame C3D with force plates crashed the plate events (``IndexError`` in
``gait/events.py``: the noise window was longer than the trial). The frames here are cut from
``../shared/data/c3d/Qualisys.c3d`` (frame index 60 on: plate 1 loaded by the left foot) with
their analog samples (``lab_frames.cut_c3d``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from cli_helpers import one_error_line, run_cli
from lab_frames import cut_c3d

import fccgrb_cli as fc
from fccgrb_cli.gait.events import plate_events
from fccgrb_cli.solvers.rates import central_derivatives

ROOT = Path(__file__).resolve().parents[1]
GAIT = ROOT.parent / "shared" / "data" / "c3d" / "Qualisys.c3d"
needs_gait = pytest.mark.skipif(not GAIT.exists(), reason=f"{GAIT} is absent (a user's clone)")


@pytest.fixture(scope="module")
def personal(tmp_path_factory) -> Path:
    model = fc.calibrate(fc.load_model(ROOT / "configs" / "models" / "lower_limb.yaml"),
                         fc.read_trial(GAIT), mass=67)
    path = tmp_path_factory.mktemp("tiny") / "personal.yaml"
    path.write_text(model.text, encoding="utf-8")
    return path


def test_derivatives_of_too_few_samples_are_unknown_not_zero():
    """y = 3t² sampled at dt = 0.5: a first difference from two samples, the second derivative
    (6) from three; what cannot be known is NaN."""
    t = np.arange(4) * 0.5
    y = 3 * t**2
    d1, d2 = central_derivatives(y[:1], 0.5)
    assert np.isnan(d1).all() and np.isnan(d2).all()
    d1, d2 = central_derivatives(y[:2], 0.5)
    np.testing.assert_allclose(d1, [(y[1] - y[0]) / 0.5] * 2)
    assert np.isnan(d2).all()
    d1, d2 = central_derivatives(y[:3], 0.5)
    np.testing.assert_allclose(d2, [6.0] * 3)
    np.testing.assert_allclose(d1, 6 * t[:3])  # exact for a parabola


@needs_gait
def test_plate_events_of_a_two_frame_file(tmp_path: Path):
    """Plate 1 loaded in both frames: a contact under way at the first frame and not ended at
    the last gives no event, and no crash."""
    trial = cut_c3d(GAIT, tmp_path / "two.c3d", 60, 62)
    assert plate_events(trial, 200.0, {"foot_l": np.ones(2, bool), "foot_r": np.zeros(2, bool)}) \
        is None


@needs_gait
@pytest.mark.parametrize("frames", [1, 2, 4, 12])
def test_a_tiny_trial_is_solved_and_says_what_it_lacks(personal, tmp_path: Path, frames: int):
    """Kinematics of every frame; the inverse dynamics skipped below 10 frames (the shortest
    stretch it runs on, stretches.SHORTEST) with one warning naming the file and the frames it
    needs; no velocity of zero where none is known."""
    trial = cut_c3d(GAIT, tmp_path / f"t{frames}.c3d", 60, 60 + frames)
    out = tmp_path / "r.h5"
    result = run_cli("solve", personal, trial, "-o", out)
    assert result.exit_code == 0, (result.output, result.exception)
    assert "Traceback" not in result.output
    warned = [line for line in result.stderr.splitlines() if "inverse dynamics needs" in line]
    run = next(iter(fc.read_results(out).values()))
    assert run.result.converged.all() and len(run.result.time) == frames
    if frames < 10:
        assert warned == [f"fccgrb: warning: {trial}: {frames} frame{'s' * (frames > 1)}; the "
                          "inverse dynamics needs at least 10 (a stretch of solved frames long "
                          "enough for its rates); skipped"]
        assert run.dynamics is None
        assert np.isnan(run.result.theta_dd).all() == (frames < 3)
        assert np.isnan(run.result.theta_d).all() == (frames == 1)
    else:
        assert not warned and run.dynamics is not None


@needs_gait
def test_a_tiny_trial_refused_names_the_file_and_the_frames_needed(personal, tmp_path: Path):
    two = cut_c3d(GAIT, tmp_path / "two.c3d", 60, 62)
    one_error_line(run_cli("solve", personal, two, "--dynamics", "-o", tmp_path / "a.h5"),
                   f"{two}: 2 frames; the inverse dynamics needs at least 10")
    nine = cut_c3d(GAIT, tmp_path / "nine.c3d", 60, 69)
    one_error_line(run_cli("solve", personal, nine, "--filter-cutoff", "6", "-o",
                           tmp_path / "b.h5"),
                   f"{nine}: 9 frames; --filter-cutoff needs at least 10")
    assert not (tmp_path / "a.h5").exists() and not (tmp_path / "b.h5").exists()
    ten = cut_c3d(GAIT, tmp_path / "ten.c3d", 60, 70)
    assert run_cli("solve", personal, ten, "--filter-cutoff", "6", "-o",
                   tmp_path / "c.h5").exit_code == 0

"""Singular positions, exactly: mechanisms sampled exactly at their change points (not only
near them), at sampling steps whose neighbours of a change point are well conditioned, solved
by every method from exact markers (TRC). Every frame at a change point is flagged; no trusted
frame lies on the other assembly branch (its model points within 1 mm of the exact markers);
no trusted moment is more than 10× the true peak; a model posed at a change point is refused
for that reason.

Mechanisms, generated here from the shipped ones: the parallelogram four-bar (change points at
crank 0° and 180°), at 6° and 2.4° a frame, and an isosceles slider-crank (crank = rod, so at
crank ±90° the slider may also stay at the pivot: a change point). Independent references: the
exact markers ``fccgrb synth`` writes beside the trial, the parallelogram's input torque in
closed form (Lagrange), the change points' angles by geometry.
"""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest
from cli_helpers import one_error_line, run_cli

import fccgrb_cli as fc
from fccgrb_cli.pipeline.options import METHODS
from fccgrb_cli.solvers.quality import SINGULAR

ROOT = Path(__file__).resolve().parents[1]
MODELS = ROOT / "configs" / "models"
PARALLELOGRAM_MOTION = "    motion: {mean: 90, rate: 120, terms: [{amplitude: 10, frequency: 1}]}"
SLIDER_ROD = ("A: [0, 0, 0], B: [0.25, 0, 0], M2: [0.08, 0.02, 0.01], M3: [0.18, -0.02, 0.01]",
              "A: [0, 0, 0], B: [0.08, 0, 0], M2: [0.03, 0.02, 0.01], M3: [0.06, -0.02, 0.01]")


def parallelogram(rate: float) -> str:
    text = (MODELS / "parallelogram.yaml").read_text(encoding="utf-8")
    assert PARALLELOGRAM_MOTION in text
    return text.replace(PARALLELOGRAM_MOTION, f"    motion: {{mean: 60, rate: {rate:g}}}")


def isosceles_slider_crank() -> str:
    text = (MODELS / "slider_crank.yaml").read_text(encoding="utf-8")
    for old, new in (SLIDER_ROD, ("    com: [0.125, 0, 0]", "    com: [0.04, 0, 0]"),
                     ("    pose: {r: [0.33, 0, 0]", "    pose: {r: [0.16, 0, 0]"),
                     ("terms: [{amplitude: 20, frequency: 2}]}", "}")):
        assert old in text
        text = text.replace(old, new)
    return text


# name → (model text, duration s, crank angles of the change points mod 360, deg)
MECHANISMS = {
    "parallelogram-6deg": (lambda: parallelogram(600), 0.7, (0.0, 180.0)),
    "parallelogram-2.4deg": (lambda: parallelogram(240), 1.5, (0.0, 180.0)),
    "isosceles-slider-crank": (isosceles_slider_crank, 1.0, (90.0, 270.0)),
}


@pytest.fixture(scope="module")
def made(tmp_path_factory):
    """Each mechanism's model file and exact-marker trial (TRC), with its truth."""
    out = {}
    for name, (text, duration, points) in MECHANISMS.items():
        folder = tmp_path_factory.mktemp(name)
        model, trial = folder / "model.yaml", folder / "trial.trc"
        model.write_text(text(), encoding="utf-8")
        result = run_cli("synth", model, "-o", trial, "--duration", duration)
        assert result.exit_code == 0, result.output + result.stderr
        with h5py.File(folder / "trial.truth.h5") as h5:
            theta = np.degrees(h5["theta"][()][:, 0])
            markers = h5["markers"][()]
        at = np.zeros(len(theta), dtype=bool)
        for point in points:
            at |= np.abs((theta - point + 180.0) % 360.0 - 180.0) < 1e-6
        assert at.sum() >= 2, name  # the trial holds the change points exactly
        out[name] = (model, trial, at, markers)
    return out


def closed_form_peak(model: fc.Model, run: fc.Run) -> float:
    """The parallelogram's input torque on its branch, τ = J θ̈ + g S cos θ (tests/
    test_checks.py derives it), at its largest over the run's frames."""
    from test_checks import parallelogram_torque

    return float(np.abs(parallelogram_torque(model, run.result.theta[:, 0],
                                             run.result.theta_dd[:, 0])).max())


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("name", list(MECHANISMS))
def test_change_points_flagged_and_trusted_frames_on_the_branch(made, name, method):
    model_path, trial_path, at, exact = made[name]
    model = fc.load_model(model_path)
    run = fc.solve(model, fc.read_trial(trial_path), method=method)
    flags = run.result.flags
    assert ((flags[at] & SINGULAR) > 0).all(), np.flatnonzero(at & ((flags & SINGULAR) == 0))
    labels = list(model.marker_labels)
    tracked = [labels.index(tp.marker) for tp in model.tracked_points]
    off = np.linalg.norm(run.model_points - exact[:, tracked], axis=2).max(axis=1)
    trusted = run.trusted
    assert trusted.sum() >= 0.5 * len(trusted)
    assert off[trusted].max() < 1e-3, np.flatnonzero(trusted & (off >= 1e-3))
    if name.startswith("parallelogram"):
        tau, ok = run.moments.values[:, 0], run.moments_trusted[:, 0]
        assert np.abs(tau[ok]).max() <= 10 * closed_form_peak(model, run)


def test_a_model_posed_at_a_change_point_is_refused_for_that_reason(tmp_path):
    """The parallelogram with its four links in line (crank at 0°): `check` refuses, saying
    the pose is a singular position, not that an angle is missing; posed off it, it passes."""
    text = (MODELS / "parallelogram.yaml").read_text(encoding="utf-8")
    in_line = {
        "    pose: {r: [0, 0, 0], u: [0, 1, 0], v: [-1, 0, 0], w: [0, 0, 1]}":
            "    pose: {r: [0, 0, 0], u: [1, 0, 0], v: [0, 1, 0], w: [0, 0, 1]}",
        "    pose: {r: [0, 0.20, 0], u: [1, 0, 0], v: [0, 1, 0], w: [0, 0, 1]}":
            "    pose: {r: [0.20, 0, 0], u: [1, 0, 0], v: [0, 1, 0], w: [0, 0, 1]}",
        "    pose: {r: [0.40, 0, 0], u: [0, 1, 0], v: [-1, 0, 0], w: [0, 0, 1]}":
            "    pose: {r: [0.40, 0, 0], u: [1, 0, 0], v: [0, 1, 0], w: [0, 0, 1]}",
    }
    for old, new in in_line.items():
        assert old in text
        text = text.replace(old, new)
    path = tmp_path / "in_line.yaml"
    path.write_text(text, encoding="utf-8")
    line = one_error_line(run_cli("check", path), "in_line.yaml: bodies' poses",
                          "singular position", "2 degrees of freedom there and 1 near it")
    assert "angular coordinates" not in line
    assert run_cli("check", MODELS / "parallelogram.yaml").exit_code == 0

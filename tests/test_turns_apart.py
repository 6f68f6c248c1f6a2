"""Signed angles of frames solved apart keep one count of turns.

A frame solved from a fresh guess — a parallel worker's first frame (``--parallel
--parallel-init chunks``), the first frame after a gap — comes back with its signed angle in
(−π, π]; ``solvers/turns.py`` moves it by whole turns onto the count of the frames before. The
oracle is the crank-rocker's prescribed motion, θ(t) = mean + rate·t + Σ amplitude·sin(2π·f·t +
phase), evaluated here from the model file's own numbers (``configs/models/crank_rocker.yaml``;
docs/signed_angles.md), on the exact markers ``fccgrb synth`` writes.

Gaps are generated on both sides of the threshold that matters: the crank turning less, or
more, than half a turn across the gap at the rate it had before it. Below, the count follows
from the last frame alone; above, it rests on that rate carried across the gap, and a warning
names the gap.
"""

from __future__ import annotations

from functools import cache
from pathlib import Path

import numpy as np
import pytest
import yaml
from cli_helpers import run_cli

import fccgrb_cli as fc
from fccgrb_cli.solvers.turns import counted
from fccgrb_cli.trial.record import Trial
from fccgrb_cli.trial.truth import read_truth, truth_path

ROOT = Path(__file__).resolve().parents[1]
CRANK = ROOT / "configs" / "models" / "crank_rocker.yaml"
TOL_DEG = 1e-3  # the optimizers stop at tol 1e-10 on exact markers a few 1e-6° off


def prescribed(time: np.ndarray) -> np.ndarray:
    """The crank angle (rad) the model file prescribes, from its YAML numbers (deg, Hz)."""
    spec = next(a for a in yaml.safe_load(CRANK.read_text(encoding="utf-8"))["angles"]
                if a["name"] == "crank")["motion"]
    degrees = spec.get("mean", 0.0) + spec.get("rate", 0.0) * time
    for term in spec.get("terms", []):
        degrees = degrees + term["amplitude"] * np.sin(
            2 * np.pi * term["frequency"] * time + np.radians(term.get("phase", 0.0)))
    return np.radians(degrees)


@cache
def exact_trial(folder: str) -> Trial:
    path = Path(folder) / "crank.c3d"
    assert run_cli("synth", CRANK, "-o", path, "--duration", "3").exit_code == 0
    return fc.read_trial(path)


@pytest.fixture(scope="module")
def trial(tmp_path_factory) -> Trial:
    return exact_trial(str(tmp_path_factory.mktemp("turns")))


def test_the_oracle_is_the_synthesized_motion(trial: Trial):
    """The closed form above is what `synth` drove (its truth file), through three turns."""
    theta = read_truth(truth_path(trial.path)).theta[:, 0]
    np.testing.assert_allclose(theta, prescribed(trial.time), atol=1e-9)
    assert np.degrees(theta[-1]) > 3 * 360 - 30


def test_parallel_chunks_count_the_turns_of_every_chunk(trial: Trial):
    """Two workers: the second chunk starts from a fresh guess in the second turn."""
    run = fc.solve(fc.load_model(CRANK), trial, method="cno-sqp", parallel=True,
                   parallel_init="chunks", workers=2, dynamics=False, events="none")
    error = np.degrees(np.abs(run.result.theta[:, 0] - prescribed(trial.time)))
    assert error.max() < TOL_DEG, error.max()
    assert run.trusted.all()


def _gaps(trial: Trial, over_half_turn: bool, count: int, seed: int) -> list[tuple[int, int]]:
    """Gaps [a, b) whose crank turns (at the rate of the two frames before, from the oracle)
    less than 170° or more than 190° across, and whose carried rate misses the true angle
    after them by less than 120° (what the rule can know)."""
    rng = np.random.default_rng(seed)
    theta = prescribed(trial.time)
    out: list[tuple[int, int]] = []
    while len(out) < count:
        a = int(rng.integers(30, trial.n_frames - 120))
        b = a + int(rng.integers(5, 90))
        rate = theta[a - 1] - theta[a - 2]
        carried = np.degrees(abs(rate) * (b - (a - 1)))
        missed = np.degrees(abs(theta[a - 1] + rate * (b - (a - 1)) - theta[b]))
        if missed < 120 and (carried > 190 if over_half_turn else carried < 170):
            out.append((a, b))
    return out


@pytest.mark.parametrize("over_half_turn", [False, True], ids=["under-half-turn", "over"])
def test_a_fresh_guess_after_a_gap_keeps_counting(trial: Trial, over_half_turn: bool):
    """Every marker gone for frames [a, b): goal attainment leaves them unsolved and starts
    afresh at b. The angle after the gap is the prescribed one; over half a turn a warning
    names the gap, under it none does."""
    model = fc.load_model(CRANK)
    for a, b in _gaps(trial, over_half_turn, 3, seed=21 + over_half_turn):
        markers = trial.markers.copy()
        markers[a:b] = np.nan
        gapped = Trial(trial.path, trial.labels, markers, trial.rate)
        run = fc.solve(model, gapped, method="mo-tc", skip_unsolvable=True, dynamics=False,
                       events="none")
        solved = run.result.converged
        assert not solved[a:b].any() and solved[b:].all(), (a, b)
        error = np.degrees(np.abs(run.result.theta[solved, 0] -
                                  prescribed(trial.time)[solved]))
        assert error.max() < TOL_DEG, (a, b, error.max())
        warned = [m for m in run.result.messages if "half a turn or more" in m]
        assert len(warned) == over_half_turn, (a, b, warned)
        if warned:
            assert warned[0].startswith(f"frame indices {a}:{b} ")


def test_the_count_of_generated_angles_solved_apart():
    """The rule on its own, against angles written here: random smooth motions of three
    signed angles, each frame wrapped into (−π, π] at random (as fresh guesses give them),
    random gaps whose values are garbage; every solved frame comes back to the motion."""
    rng = np.random.default_rng(8)
    for _ in range(20):
        n = int(rng.integers(40, 200))
        t = np.arange(n)
        speed = rng.uniform(-0.5, 0.5, 3)  # rad per frame: under a quarter turn
        truth = rng.uniform(-np.pi, np.pi, 3) + np.outer(t, speed) + \
            0.2 * np.sin(np.outer(t, rng.uniform(0.01, 0.05, 3)))
        solved = np.ones(n, bool)
        a = int(rng.integers(3, n - 10))
        b = a + int(rng.integers(1, 8))
        solved[a:b] = False
        raw = np.angle(np.exp(1j * truth))  # in (−π, π]
        raw[~solved] = rng.uniform(-50, 50, (int((~solved).sum()), 3))  # stale guesses
        out, _ = counted(raw, solved)
        first = np.round(truth[0] / (2 * np.pi)) * 2 * np.pi  # the first frame's turn
        np.testing.assert_allclose(out[solved], (truth - first)[solved], atol=1e-12)

"""``--smooth auto`` through a whole solve (fccgrb_cli/pipeline/smoothing.py), against independent
checks:
the topological equations and the rates' consistency (Φ_q q̇ = ν, Φ_q q̈ = γ) evaluated on every
frame of the result; the moments against the truth-driven ones and the predicted standard
deviations against a small Monte-Carlo over noise seeds (the 100-seed check is
``python benchmarks/smoothing.py --monte-carlo 100``); a gap bridged by the prior; a long
trial in spans against the whole trial at once; the smoother's own filter against its transfer
function; the results file, the CSV export and the options that switch it off."""

from __future__ import annotations

import numpy as np
import pytest

import fccgrb_cli as fc
from fccgrb_cli.pipeline.smoothing import chain_coordinates
from fccgrb_cli.pipeline.synth import synthesize
from fccgrb_cli.results.export import write_csv
from fccgrb_cli.solvers.batched import Stacked
from fccgrb_cli.solvers.smooth import trial as smooth_trial
from fccgrb_cli.solvers.smooth.prior import response
from fccgrb_cli.solvers.smooth.signal import smoothed_signal
from fccgrb_cli.system import Drive, compile_system
from fccgrb_cli.trial.record import Trial

FIVE_BAR = "configs/models/five_bar.yaml"


@pytest.fixture(scope="module")
def five_bar():
    model = fc.load_model(FIVE_BAR)
    return model, synthesize(model, duration=0.75, rate=200.0)


def _trial(synth, markers: np.ndarray) -> Trial:
    return Trial("synthesized.c3d", synth.labels, markers, synth.rate)


def _noisy(synth, sigma: float, seed: int) -> np.ndarray:
    return synth.markers + np.random.default_rng(seed).normal(scale=sigma,
                                                              size=synth.markers.shape)


def _truth_moments(model, synth) -> np.ndarray:
    from fccgrb_cli.dynamics.inverse import inverse_dynamics

    system = compile_system(model, angles="driver")
    return inverse_dynamics(system, synth.result).joint_moments


def test_smoothed_motion_keeps_the_topology_and_consistent_rates(five_bar, tmp_path) -> None:
    model, synth = five_bar
    run = fc.solve(model, _trial(synth, _noisy(synth, 1e-3, 0)), smooth="auto")
    assert run.uncertainty is not None and any("smoothed" in n for n in run.notes)
    mixed = compile_system(model, angles="coordinate", track=True)
    top = mixed.masks()["topology"]
    r = run.result
    for f in range(r.n_frames):
        phi, J = mixed.evaluate(r.q[f], Drive(ref=np.zeros((mixed.n_targets, 3))))
        assert np.abs(phi[top]).max() < 1e-10
        assert np.abs(J[top] @ r.qd[f]).max() < 1e-9  # ν = 0 on the topology (MCR too)
        gamma = mixed.gamma(r.q[f], r.qd[f], Drive(ref=np.zeros((mixed.n_targets, 3))))
        assert np.abs(J[top] @ r.qdd[f] - gamma[top]).max() < 1e-8
    np.testing.assert_allclose(r.theta, r.q[:, -len(r.angle_names):])
    u = run.uncertainty
    for sd in (u.theta_sd, u.theta_d_sd, u.theta_dd_sd, u.moments_sd):
        assert sd.shape == r.theta.shape and np.all(sd > 0) and np.isfinite(sd).all()
    path = tmp_path / "run.h5"
    fc.write_results(run, path)
    back = fc.read_results(path)[run.name].uncertainty
    for key in ("theta_sd", "theta_d_sd", "theta_dd_sd", "moments_sd", "cutoffs_hz"):
        np.testing.assert_array_equal(getattr(back, key), getattr(u, key))
    assert back.noise_m == u.noise_m and back.coordinates == u.coordinates
    write_csv(run, tmp_path / "run.csv")
    header = (tmp_path / "run.csv").read_text().splitlines()[0].split(",")
    assert "J3_w sd [deg]" in header and "J3_w_moment sd [N·m]" in header


def test_moments_and_their_standard_deviations_against_seeds(five_bar) -> None:
    """Twelve noise seeds at 1 mm: the smoothed moments beat the central differences tenfold,
    and per angle the predicted standard deviation of the moment, the angle and its rate
    matches the seeds' scatter about the truth (median over frames within 35 %), the 95 %
    bands covering 85–99.5 %. The acceleration's is looser (within a factor of 2: on this
    0.75 s trial each seed's strength comes from 150 frames, and where it comes out low the
    smoother's bias, which its noise-part covariance leaves out, is the larger part of θ̈'s
    error); the 100-seed check on 3 s (``benchmarks/smoothing.py --monte-carlo 100``) holds
    every one of them to 25 %."""
    model, synth = five_bar
    truth = _truth_moments(model, synth)
    errors, sds, raw = [], [], []
    kinematics = {"theta": [], "theta_d": [], "theta_dd": []}
    for seed in range(12):
        trial = _trial(synth, _noisy(synth, 1e-3, seed))
        run = fc.solve(model, trial, smooth="auto")
        errors.append(run.dynamics.inverse.joint_moments - truth)
        sds.append(run.uncertainty.moments_sd)
        for key, rows in kinematics.items():
            rows.append((getattr(run.result, key) - getattr(synth.result, key),
                         getattr(run.uncertainty, f"{key}_sd")))
        if seed < 2:
            plain = fc.solve(model, trial, smooth="none")
            raw.append(plain.dynamics.inverse.joint_moments - truth)
    e, s = np.array(errors), np.array(sds)
    assert np.sqrt(np.mean(e**2)) < 0.1 * np.sqrt(np.mean(np.array(raw) ** 2))
    ratio = np.median(np.sqrt(np.mean(s**2, axis=0)) / np.sqrt(np.mean(e**2, axis=0)), axis=0)
    assert np.all(np.abs(ratio - 1.0) < 0.35), ratio
    cover = np.mean(np.abs(e) <= 1.96 * s)
    assert 0.85 < cover < 0.995, cover
    for key, rows in kinematics.items():
        e, s = (np.array(part) for part in zip(*rows, strict=True))
        ratio = np.median(np.sqrt(np.mean(s**2, axis=0)) / np.sqrt(np.mean(e**2, axis=0)),
                          axis=0)
        low, high = (0.5, 2.0) if key == "theta_dd" else (0.65, 1.35)
        assert np.all((ratio > low) & (ratio < high)), (key, ratio)


def test_a_gap_is_bridged_by_the_prior(five_bar) -> None:
    """Every marker missing over 30 frames (0.15 s): those frames stay unsolved and flagged,
    the smoother gives them positions that keep the topology, close to the truth within the
    uncertainty it gives them, which says they are bridged, not measured."""
    model, synth = five_bar
    markers = _noisy(synth, 1e-3, 3)
    markers[60:90] = np.nan
    run = fc.solve(model, _trial(synth, markers), skip_unsolvable=True, smooth="auto")
    r = run.result
    assert not r.trusted[60:90].any() and r.trusted[:55].all()
    assert np.isfinite(r.q).all() and run.dynamics is not None
    sd = run.uncertainty.theta_sd
    assert np.all(sd[75] > 1.3 * np.median(sd[20:50], axis=0))
    assert np.all(np.abs(r.theta - synth.result.theta)[60:90] < 4 * sd[60:90])
    system = compile_system(model, angles="driver")
    stacked = Stacked(system)
    body = r.q[:, :system.layout.n_body_q]
    phi = stacked.residual(body, stacked_drives(system, r.theta))
    assert np.abs(phi).max() < 1e-10


def stacked_drives(system, theta: np.ndarray):
    from fccgrb_cli.solvers.batched import Drives

    empty = np.zeros((len(theta), system.n_base_slots, 3))
    return Drives(theta, np.zeros_like(theta), np.zeros_like(theta), empty, empty, empty)


def test_a_long_trial_in_spans_equals_the_whole(monkeypatch) -> None:
    """Spans of 150 frames with the overlap the smoother's decay asks for against the whole
    trial at once (low noise: high cutoffs, a short overlap)."""
    model = fc.load_model(FIVE_BAR)
    synth = synthesize(model, duration=11.0, rate=100.0)
    markers = _noisy(synth, 5e-5, 1)
    mixed = compile_system(model, angles="coordinate", track=True)
    system = compile_system(model, angles="driver")
    from fccgrb_cli.solvers.nrm.solve import NrmSettings, solve_nrm

    nrm = solve_nrm(mixed, synth.result.time, markers, NrmSettings())
    use = np.ones(len(markers), bool)
    whole = smooth_trial.smooth_motion(system, synth.result.time, markers, use, nrm.q)
    overlap = smooth_trial._overlap(whole.strengths, 0.01)
    monkeypatch.setattr(smooth_trial, "span_frames", lambda n: 150)
    assert len(markers) > 150 + 2 * overlap
    parts = smooth_trial.smooth_motion(system, synth.result.time, markers, use, nrm.q)
    for key, tol in (("d", 1e-9), ("d_dd", 1e-8), ("q", 1e-9), ("covariance", 1e-5)):
        a, b = getattr(whole, key), getattr(parts, key)
        assert np.abs(a - b).max() < tol * np.abs(a).max(), key


def test_the_smoothers_filter_is_its_transfer_function() -> None:
    rate, cutoff = 200.0, 8.0
    t = np.arange(4000) / rate
    for f in (2.0, 6.0, 8.0, 12.0):
        signal = np.column_stack([np.sin(2 * np.pi * f * t), np.cos(2 * np.pi * f * t)])
        out = smoothed_signal(signal, rate, cutoff)
        middle = slice(1000, 3000)
        np.testing.assert_allclose(out[middle], response(f, cutoff) * signal[middle],
                                   atol=1e-10)


def test_what_switches_the_smoother_off(five_bar) -> None:
    model, synth = five_bar
    trial = _trial(synth, _noisy(synth, 1e-3, 0))
    assert fc.solve(model, trial, filter_cutoff=10.0, smooth="auto").uncertainty is None
    assert fc.solve(model, trial, smooth="none").uncertainty is None


def test_a_plate_takes_the_cutoffs_of_the_coordinates_that_move_its_body() -> None:
    model = fc.load_model("configs/models/lower_limb.yaml")
    names = (*(a.name for a in model.angles),
             *(f"pelvis.{p}.{x}" for p in ("r", "phi") for x in "xyz"))
    picked = {names[k] for k in chain_coordinates(model, "foot_r", names)}
    assert {"hip_flexion_r", "knee_flexion_r", "ankle_dorsiflexion_r", "pelvis.r.z"} <= picked
    assert not any(name.endswith("_l") for name in picked)


def test_the_smoother_weighs_the_markers_as_the_frames_solve_did() -> None:
    """The markers' relative weights are the ones the per-frame solve put on its tracking rows
    (its own row weights, solvers/nrm/problem.py, read here from the solver): a point's own
    weight or --tracking-weight for NRM-WLS, none for NRM-LS; the optimizers count a point
    without one as 1."""
    from fccgrb_cli.model import parse_model
    from fccgrb_cli.pipeline.options import SolveOptions
    from fccgrb_cli.pipeline.smoothing import marker_weights
    from fccgrb_cli.solvers.nrm.problem import row_weights

    with open(FIVE_BAR, encoding="utf-8") as handle:
        text = handle.read()
    text = text.replace("{marker: P3, point: B2.P3}", "{marker: P3, point: B2.P3, weight: 4.0e-3}")
    text = text.replace("{marker: P7, point: B3.P7}", "{marker: P7, point: B3.P7, weight: 1.0e-4}")
    model = parse_model(text, "five_bar_weighted.yaml")
    system = compile_system(model, angles="coordinate", track=True)
    tracking = system.masks()["tracking"]
    for weight in (1e-3, 2e-2):
        rows = row_weights(system, weight)[tracking][::3]
        got = marker_weights(model, SolveOptions(method="nrm-wls", tracking_weight=weight))
        np.testing.assert_allclose(got, rows, rtol=1e-12)
    assert marker_weights(model, SolveOptions(method="nrm-ls")) is None
    own = marker_weights(model, SolveOptions(method="cno-sqp"))
    assert own[2] == 4e-3 and own[6] == 1e-4 and own.count(1.0) == 7
    assert marker_weights(fc.load_model(FIVE_BAR), SolveOptions()) is None

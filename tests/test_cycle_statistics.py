"""Cycles over several different strides: time normalization, the mean ± SD
over the trusted strides, which strides an untrusted frame spoils, pooling trials.

Each generated trial has strides of different lengths with strikes between frames, and a curve
known in closed form on every stride: v(t) = a_j + c_j·p + b_j·sin(2πp), p the phase of the
stride (0 at its strike, 1 at the next), with a_{j+1} = a_j + c_j so that the curve is
continuous. The expected normalized curves, means and sample SDs are computed here from that
formula, not from the code; the only allowance is linear interpolation between frames (a
bound from the formula's own derivatives).
"""

from __future__ import annotations

import numpy as np
import pytest

from fccgrb_cli.gait.cycles import PARAMETERS, SAMPLES, Walk, pooled, side_cycles
from fccgrb_cli.gait.events import Events

RATE = 500.0


def _trial(rng: np.random.Generator, strides: int):
    """Strike times, the per-stride coefficients and the frame values of one side's curve."""
    lengths = rng.uniform(0.8, 1.4, strides)
    strikes = rng.uniform(0.05, 0.3) + np.concatenate([[0.0], np.cumsum(lengths)])
    a = np.empty(strides)
    b, c = rng.uniform(-30, 30, strides), rng.uniform(-10, 10, strides)
    a[0] = rng.uniform(-20, 20)
    for j in range(1, strides):
        a[j] = a[j - 1] + c[j - 1]
    time = np.arange(int(np.ceil((strikes[-1] + 0.3) * RATE))) / RATE
    values = np.full(len(time), np.nan)
    for j in range(strides):
        inside = (time >= strikes[j]) & (time <= strikes[j + 1])
        p = (time[inside] - strikes[j]) / lengths[j]
        values[inside] = a[j] + c[j] * p + b[j] * np.sin(2 * np.pi * p)
    values[time < strikes[0]] = a[0] + c[0] * (time[time < strikes[0]] - strikes[0]) / lengths[0]
    last = time > strikes[-1]
    values[last] = a[-1] + c[-1] + (c[-1] + 2 * np.pi * b[-1]) * \
        (time[last] - strikes[-1]) / lengths[-1]
    return strikes, lengths, (a, b, c), time, values


def _expected(coefficients, j: int, p: np.ndarray) -> np.ndarray:
    a, b, c = coefficients
    return a[j] + c[j] * p + b[j] * np.sin(2 * np.pi * p)


def _tolerance(coefficients, lengths: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Linear interpolation between frames dt apart: dt²/8·max|v''| inside a stride; at its
    ends (a kink between two strides' formulas) dt·max|v'|."""
    _, b, c = coefficients
    dt = 1.0 / RATE
    slope = (np.abs(c) + 2 * np.pi * np.abs(b)) / lengths
    curvature = (2 * np.pi) ** 2 * np.abs(b) / lengths**2
    inner = dt**2 / 8 * curvature.max() + 1e-9
    ends = dt * slope.max() * 2
    return np.where((p < 2 * dt / lengths.min()) | (p > 1 - 2 * dt / lengths.min()), ends,
                    inner)


def _cycles(strikes, time, values, trusted):
    events = Events("test", strikes, ("left",) * len(strikes), ("strike",) * len(strikes))
    walk = Walk(time, {}, np.array([1.0, 0, 0]), np.array([0, 0, 1.0]))
    return side_cycles("left", events, trusted, (("knee_flexion_l",), ("deg",),
                                                 values[:, None]), walk)


@pytest.mark.parametrize("seed", range(6))
def test_mean_and_sd_over_different_strides(seed: int):
    rng = np.random.default_rng(seed)
    strides = int(rng.integers(3, 8))
    strikes, lengths, coefficients, time, values = _trial(rng, strides)
    trusted = np.ones(len(time), bool)
    spoiled = set()
    for j in rng.choice(strides, size=int(rng.integers(0, strides - 1)), replace=False):
        # an untrusted frame whose value enters stride j's curve: the last frame at or
        # before its strike, or the first at or after the next strike, or one inside
        where = rng.integers(3)
        f = [int(np.floor(strikes[j] * RATE)), int(np.ceil(strikes[j + 1] * RATE)),
             int(rng.integers(np.ceil(strikes[j] * RATE), np.floor(strikes[j + 1] * RATE)))
             ][where]
        trusted[f] = False
        spoiled |= {k for k in range(strides)
                    if strikes[k] - 1 / RATE < f / RATE < strikes[k + 1] + 1 / RATE}
    cycles = _cycles(strikes, time, values, trusted)
    assert cycles.n == strides
    np.testing.assert_allclose(cycles.start, strikes[:-1])
    np.testing.assert_allclose(cycles.stop, strikes[1:])
    assert [k for k in range(strides) if not cycles.trusted[k]] == sorted(spoiled)
    p = np.linspace(0.0, 1.0, SAMPLES)
    for j in range(strides):
        error = np.abs(cycles.curves[j, :, 0] - _expected(coefficients, j, p))
        assert (error <= _tolerance(coefficients, lengths, p)).all(), (j, error.max())
        row = dict(zip([name for name, _ in PARAMETERS], cycles.parameters[j], strict=True))
        assert row["stride_time"] == pytest.approx(lengths[j])
        assert row["cadence"] == pytest.approx(120.0 / lengths[j])
    kept = [j for j in range(strides) if j not in spoiled]
    curves = np.array([_expected(coefficients, j, p) for j in kept])
    mean = curves.sum(axis=0) / len(kept)
    sd = np.sqrt(((curves - mean) ** 2).sum(axis=0) / (len(kept) - 1)) if len(kept) > 1 \
        else np.full(SAMPLES, np.nan)
    bound = _tolerance(coefficients, lengths, p)
    np.testing.assert_array_less(np.abs(cycles.mean()[:, 0] - mean), bound)
    if len(kept) > 1:
        # the SD moves at most by the curves' own interpolation error
        np.testing.assert_array_less(np.abs(cycles.sd()[:, 0] - sd),
                                     bound * np.sqrt(len(kept) / (len(kept) - 1)) * 2)
    else:
        assert np.isnan(cycles.sd()).all()


def test_an_untrusted_frame_one_frame_outside_a_stride_spoils_nothing():
    """The frame just before the last frame at or before the strike (and just after the first
    at or after the next strike) enters no normalized sample: the stride stays trusted."""
    rng = np.random.default_rng(3)
    strikes, _, _, time, values = _trial(rng, 3)
    for f, spoiled in ((int(np.floor(strikes[1] * RATE)) - 1, [0]),
                       (int(np.floor(strikes[1] * RATE)), [0, 1]),
                       (int(np.ceil(strikes[1] * RATE)) + 1, [1]),
                       (int(np.ceil(strikes[3] * RATE)) + 1, [])):
        trusted = np.ones(len(time), bool)
        trusted[f] = False
        cycles = _cycles(strikes, time, values, trusted)
        assert [k for k in range(3) if not cycles.trusted[k]] == spoiled, f


def test_pooled_trials_average_every_trusted_stride():
    rng = np.random.default_rng(11)
    per_trial, expected = [], []
    p = np.linspace(0.0, 1.0, SAMPLES)
    for _ in range(3):
        strikes, lengths, coefficients, time, values = _trial(rng, int(rng.integers(2, 5)))
        trusted = np.ones(len(time), bool)
        trusted[int(np.ceil(strikes[0] * RATE)) + 2] = False  # the trial's first stride
        per_trial.append({"left": _cycles(strikes, time, values, trusted)})
        expected += [_expected(coefficients, j, p) for j in range(1, len(lengths))]
    both = pooled(per_trial)["left"]
    assert both.n == sum(t["left"].n for t in per_trial)
    assert int(both.trusted.sum()) == len(expected)
    inner = slice(2, -2)  # the ends: a kink between strides' formulas, within dt·|v'|
    np.testing.assert_allclose(both.mean()[inner, 0], np.mean(expected, axis=0)[inner],
                               atol=1e-3)
    np.testing.assert_allclose(both.sd()[inner, 0], np.std(expected, axis=0, ddof=1)[inner],
                               atol=2e-3)
    np.testing.assert_allclose(both.mean()[:, 0], np.mean(expected, axis=0), atol=0.05)

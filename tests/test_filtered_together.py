"""Signals filtered together, one call of the filter for many columns (the loop's cost is per
sample, not per column): a trial's loads, the classical drive's angles and floating base, the
reduction's prefiltered run, the markers of the kinematic gait events. Each column is filtered
alone, so the values must be those of one call per signal, to the bit, in C order (the compiled
kernels take them), on generated cases; a trial too short for the filter is still one line
naming the option."""

from __future__ import annotations

from dataclasses import fields
from pathlib import Path

import numpy as np
import pytest

from fccgrb_cli.core.errors import InputError
from fccgrb_cli.dynamics.loads import ExternalLoad, lowpassed
from fccgrb_cli.dynamics.reduction import Stage, prefiltered
from fccgrb_cli.gait import events
from fccgrb_cli.model import load_model
from fccgrb_cli.signals.butterworth import frames_needed, lowpass
from fccgrb_cli.solvers.ad.baseline import drivers_from
from fccgrb_cli.solvers.result import KinematicResult
from fccgrb_cli.system import compile_system

ROOT = Path(__file__).resolve().parents[1]


def _load(rng: np.random.Generator, name: str, frames: int, loaded: bool) -> ExternalLoad:
    force = rng.normal(size=(frames, 3)) * 300.0
    if loaded:  # contact on one stretch, none elsewhere
        start = int(rng.integers(0, frames // 2))
        force[:start] = 0.0
        force[start + int(rng.integers(5, frames // 2)):] = 0.0
    else:
        force[:] = 0.0
    return ExternalLoad(name, "foot", force, rng.normal(size=(frames, 3)),
                        rng.normal(size=(frames, 3)) * 10.0)


@pytest.mark.parametrize("seed", range(12))
def test_loads_filtered_together_equal_each_alone(seed: int) -> None:
    rng = np.random.default_rng(seed)
    frames = int(rng.integers(40, 400))
    loads = [_load(rng, f"plate {k}", frames, bool(rng.random() < 0.8))
             for k in range(int(rng.integers(1, 5)))]
    rate, cutoff, order = float(rng.choice([100.0, 200.0, 1000.0])), 6.0, int(rng.integers(1, 5))
    together = lowpassed(loads, rate, cutoff, order)
    assert len(together) == len(loads)
    for load, out in zip(loads, together, strict=True):
        alone = load.filtered(lambda signal: lowpass(signal, rate, cutoff, order))
        if not load.loaded().size:
            assert out is load  # never loaded: kept as it is
        for field in ("force", "moment", "point"):
            assert np.array_equal(getattr(out, field), getattr(alone, field)), field
            assert getattr(out, field).flags.c_contiguous, field
        assert (out.name, out.body) == (load.name, load.body)


@pytest.mark.parametrize("seed", range(6))
def test_the_drive_filters_angles_and_base_as_each_alone(seed: int) -> None:
    """drivers_from with a cutoff equals drivers_from without one on the angles and the base
    low-passed one by one beforehand."""
    rng = np.random.default_rng(seed)
    system = compile_system(load_model(ROOT / "configs" / "models" / "lower_limb.yaml"),
                            angles="driver")
    frames = int(rng.integers(30, 300))
    rate = float(rng.choice([100.0, 200.0]))
    time = np.arange(frames) / rate
    theta = rng.normal(size=(frames, len(system.model.angles))).cumsum(axis=0) * 0.01
    base = rng.normal(size=(frames, system.n_base_slots, 3)).cumsum(axis=0) * 0.01
    cutoff, order = float(rng.uniform(3.0, 12.0)), 2
    inside = drivers_from(system, time, theta, base, cutoff, order)
    flat = lowpass(base.reshape(frames, -1), rate, cutoff, order).reshape(base.shape)
    outside = drivers_from(system, time, lowpass(theta, rate, cutoff, order), flat, None, order)
    for field in fields(inside):
        a, b = getattr(inside, field.name), getattr(outside, field.name)
        assert np.array_equal(a, b), field.name
        assert a.flags.c_contiguous, field.name


@pytest.mark.parametrize("seed", range(4))
def test_loads_of_different_frames_are_each_filtered_as_alone(seed: int) -> None:
    """Loads of different lengths (not a trial's, but the function takes any): each group of
    one length is stacked, and each load comes out as filtered alone."""
    rng = np.random.default_rng(100 + seed)
    loads = [_load(rng, f"load {k}", int(rng.choice([60, 90, 150])), True) for k in range(4)]
    rate, cutoff, order = 200.0, 6.0, 2
    for load, out in zip(loads, lowpassed(loads, rate, cutoff, order), strict=True):
        alone = load.filtered(lambda signal: lowpass(signal, rate, cutoff, order))
        for field in ("force", "moment", "point"):
            assert np.array_equal(getattr(out, field), getattr(alone, field)), field


def _result(rng: np.random.Generator, frames: int, nq: int, angles: int,
            rate: float) -> KinematicResult:
    q = rng.normal(size=(frames, nq)).cumsum(axis=0) * 0.01
    theta = rng.normal(size=(frames, angles)).cumsum(axis=0) * 0.01
    ones = np.ones(frames)
    return KinematicResult("nrm-wls", 1e-10, np.arange(frames) / rate, q, q, q, theta, theta,
                           theta, tuple(f"a{k}" for k in range(angles)), ones, ones, ones, ones,
                           ones.astype(bool))


@pytest.mark.parametrize(("model", "seed"), [("lower_limb", 0), ("lower_limb", 1),
                                             ("five_bar", 2)])
def test_the_prefiltered_run_equals_angles_and_bases_each_alone(model: str, seed: int) -> None:
    """The reduction's prefiltered run: its angles and each floating base's coordinates as
    low-passed one by one, the other coordinates as they were."""
    rng = np.random.default_rng(seed)
    loaded = load_model(ROOT / "configs" / "models" / f"{model}.yaml")
    system = compile_system(loaded, angles="driver")
    frames, rate = int(rng.integers(30, 300)), float(rng.choice([100.0, 200.0]))
    result = _result(rng, frames, system.layout.nq, len(loaded.angles), rate)
    stage = Stage(rate, float(rng.uniform(3.0, 12.0)), int(rng.integers(1, 4)), 1e-10, "numpy")
    out = prefiltered(loaded, result, stage)
    q = result.q.copy()
    for base in loaded.floating_bases:
        block = system.layout.q_slice(base)
        q[:, block] = lowpass(q[:, block], stage.rate, stage.cutoff, stage.order)
    assert np.array_equal(out.q, q)
    assert np.array_equal(out.theta, lowpass(result.theta, stage.rate, stage.cutoff,
                                             stage.order))
    assert out.q.flags.c_contiguous and out.theta.flags.c_contiguous


@pytest.mark.parametrize("seed", range(4))
def test_the_event_markers_are_each_smoothed_as_alone(seed: int) -> None:
    """The kinematic events' markers (with gaps, bridged first): each the one call of the
    filter on that marker gives, to the bit, in C order; up to 12 frames, only bridged."""
    rng = np.random.default_rng(seed)
    rate = float(rng.choice([100.0, 200.0]))
    frames = int(rng.choice([8, 12, 13, int(rng.integers(14, 400))]))
    markers = {name: rng.normal(size=(frames, 3)).cumsum(axis=0) * 0.01
               for name in ("pelvis", "left_heel", "right_heel", "left_toe", "right_toe",
                            "extra")}
    for xyz in markers.values():
        gap = int(rng.integers(1, frames - 3))
        xyz[gap:gap + 2] = np.nan
    smooth = events.smoothed_markers(markers, rate, "synthetic")
    assert list(smooth) == list(markers)
    for name, xyz in markers.items():
        bridged = events.bridged(xyz)
        alone = bridged if frames <= 12 else lowpass(bridged, rate, min(6.0, 0.4 * rate), 2)
        assert np.array_equal(smooth[name], alone), name
        assert smooth[name].flags.c_contiguous, name


def test_a_trial_too_short_for_the_filter_is_one_line_naming_the_option() -> None:
    rng = np.random.default_rng(0)
    frames = frames_needed(2) - 1
    loads = [_load(rng, "plate 1", frames, False), _load(rng, "plate 2", frames, False)]
    loads[1].force[2:5] = 100.0
    expected = (f"--filter-cutoff: the trial has {frames} frames; the filter needs at least "
                f"{frames_needed(2)}")
    with pytest.raises(InputError) as error:
        lowpassed(loads, 100.0, 6.0, 2)
    assert str(error.value) == expected
    system = compile_system(load_model(ROOT / "configs" / "models" / "lower_limb.yaml"),
                            angles="driver")
    theta = np.zeros((frames, len(system.model.angles)))
    base = np.zeros((frames, system.n_base_slots, 3))
    with pytest.raises(InputError) as error:
        drivers_from(system, np.arange(frames) / 100.0, theta, base, 6.0, 2)
    assert str(error.value) == expected

"""Signals filtered together, one call of the filter for many columns (the loop's cost is per
sample, not per column): a trial's loads, the classical drive's angles and floating base. Each
column is filtered alone, so the values must be those of one call per signal, to the bit, in
C order (the compiled kernels take them), on generated cases."""

from __future__ import annotations

from dataclasses import fields
from pathlib import Path

import numpy as np
import pytest

from fccgrb_cli.dynamics.loads import ExternalLoad, lowpassed
from fccgrb_cli.model import load_model
from fccgrb_cli.signals.butterworth import lowpass
from fccgrb_cli.solvers.ad.baseline import drivers_from
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

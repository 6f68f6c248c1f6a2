"""The first frame's roll of a two-point segment (solvers/initial.py): a universal joint's arm
is perpendicular to the other body's at two rolls, and the guess must take the one nearest the
model's pose, not the one its coarse sampling happened to favour.

Expectations are built here: the roots of p · Rot(φ) R s = 0 found by bisection on a fine grid
of the rotated vector (Rodrigues' formula written in the test).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import brentq

from fccgrb_cli.solvers.initial import best_roll


def rodrigues(k: np.ndarray, phi: float) -> np.ndarray:
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(phi) * K + (1 - np.cos(phi)) * K @ K


def unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


@pytest.mark.parametrize("seed", range(8))
def test_best_roll_takes_the_nearest_perpendicular_roll(seed):
    """Arms not perpendicular to the roll axis: the two rolls that make them perpendicular are
    not half a turn apart, and 0.5° samples see different costs near each; the smaller |φ|
    must win."""
    rng = np.random.default_rng(seed)
    k = unit(rng.normal(size=3))
    R = rodrigues(unit(rng.normal(size=3)), rng.uniform(0, 3))
    while True:
        p, s = unit(rng.normal(size=3)), unit(rng.normal(size=3))

        def f(phi, p=p, s=s):
            return p @ rodrigues(k, phi) @ R @ s

        grid = np.linspace(-np.pi, np.pi, 20001)
        r = R @ s  # the rotated arm by Rodrigues' vector form, over the whole grid
        turned = (np.outer(np.cos(grid), r) + np.outer(np.sin(grid), np.cross(k, r))
                  + np.outer(1 - np.cos(grid), k * (k @ r)))
        values = turned @ p
        crossings = np.flatnonzero(np.sign(values[:-1]) != np.sign(values[1:]))
        if len(crossings) == 2:
            break
    roots = [brentq(f, grid[i], grid[i + 1], xtol=1e-14) for i in crossings]
    expected = min(roots, key=abs)
    assert np.allclose(best_roll(R, k, [(p, s)]), rodrigues(k, expected) @ R, atol=1e-9)


@pytest.mark.parametrize("seed", range(4))
def test_the_reference_picks_the_roll(seed):
    """With a reference rotation (the model pose as seen from the parent): the perpendicular
    roll nearest it, even the farther one from φ = 0; without pairs, the reference's own roll
    about the axis."""
    rng = np.random.default_rng(10 + seed)
    k = unit(rng.normal(size=3))
    R = rodrigues(unit(rng.normal(size=3)), rng.uniform(0, 3))
    turn = rng.uniform(-3, 3)
    assert np.allclose(best_roll(R, k, [], rodrigues(k, turn) @ R), rodrigues(k, turn) @ R,
                       atol=1e-12)
    p = unit(np.cross(k, rng.normal(size=3)))  # p ⟂ k: the two rolls are half a turn apart
    s = R.T @ unit(np.cross(k, p))             # ⟂ p at φ = 0 and at φ = π
    far = best_roll(R, k, [(p, s)], rodrigues(k, np.pi + 0.3) @ R)
    assert np.allclose(far, rodrigues(k, np.pi) @ R, atol=1e-9)
    assert np.allclose(best_roll(R, k, [(p, s)]), R, atol=1e-9)

"""The implausible-plate rule near its thresholds (trial/forceplates.py).

Plates are generated with known geometry — sides, a twist out of plane, a corner pushed along
a side (the diagonals' midpoints apart), a shear (corner angles off 90°), placed anywhere by a
random rotation and translation — with each measured quantity set a few per cent to either
side of its documented threshold, and the verdict expected from that quantity as generated.
The still-marker rule likewise: a marker standing on an unloaded plate, each of its conditions
(inside by 20 mm, within 80 mm above, slower than 0.1 m/s, for 0.25 s, under 10 N) generated
just met or just missed.
"""

from __future__ import annotations

import numpy as np
import pytest

from fccgrb_cli.trial.forceplates import (
    MIN_LOAD,
    STAND_HEIGHT,
    STAND_MARGIN,
    STAND_SPEED,
    STAND_TIME,
    plausibility,
    unloaded_under_a_foot,
)

QUIET = np.zeros((10, 3))


def _rotation(rng: np.random.Generator) -> np.ndarray:
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


def _placed(local: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray,
                                                                   np.ndarray]:
    """Corners given in the plate's own frame (x, y in plane, z normal), placed in the lab;
    also the rotation and translation used."""
    rotation, shift = _rotation(rng), rng.uniform(-5, 5, 3)
    return local @ rotation.T + shift, rotation, shift


def _rectangle(a: float, b: float) -> np.ndarray:
    return np.array([[0, 0, 0], [a, 0, 0], [a, b, 0], [0, b, 0]], dtype=float)


def _cases(threshold: float, seed: int, count: int = 4) -> list[tuple[float, bool]]:
    """Values 0.5–5 % below and above ``threshold``, and whether each exceeds it."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(count):
        e = rng.uniform(0.005, 0.05)
        out += [(threshold * (1 - e), False), (threshold * (1 + e), True)]
    return out


@pytest.mark.parametrize("seed", range(3))
def test_sides_between_a_tenth_and_three_metres(seed: int):
    rng = np.random.default_rng(seed)
    for bound, too_far in ((0.1, lambda s: s < 0.1), (3.0, lambda s: s > 3.0)):
        for side, _ in _cases(bound, seed + 10):
            other = rng.uniform(0.4, 0.8)
            corners, _, _ = _placed(_rectangle(side, other), rng)
            problem = plausibility(corners, QUIET)
            assert (problem is not None) == too_far(side), (side, problem)
            if problem is not None:
                assert problem.startswith("sides of 0.1–3 m")


@pytest.mark.parametrize("seed", range(3))
def test_corners_within_5_mm_of_one_plane(seed: int):
    """A twist: corners alternately d above and below their plane (d is each corner's distance
    from the best plane)."""
    rng = np.random.default_rng(seed)
    for d, off in _cases(0.005, seed + 20):
        local = _rectangle(rng.uniform(0.4, 0.9), rng.uniform(0.4, 0.9))
        local[:, 2] = d * np.array([1, -1, 1, -1])
        corners, _, _ = _placed(local, rng)
        problem = plausibility(corners, QUIET)
        assert (problem is not None) == off, (d, problem)
        if off:
            assert problem.startswith("four corners in one plane")


@pytest.mark.parametrize("seed", range(3))
def test_diagonals_meeting_within_5_cm(seed: int):
    """A long plate (2.5 m) whose third corner is pushed by m along its short side: the
    diagonals' midpoints are m apart while every angle stays within 1.2° of square."""
    rng = np.random.default_rng(seed)
    for m, off in _cases(0.05, seed + 30):
        local = _rectangle(2.5, rng.uniform(2.0, 2.4))
        local[2, 1] += m
        corners, _, _ = _placed(local, rng)
        problem = plausibility(corners, QUIET)
        assert (problem is not None) == off, (m, problem)
        if off:
            assert problem.startswith("four corners forming a rectangle")


@pytest.mark.parametrize("seed", range(3))
def test_right_angles_within_2_degrees(seed: int):
    """A parallelogram sheared by δ: two corners at 90° + δ, two at 90° − δ (midpoints still
    meet)."""
    rng = np.random.default_rng(seed)
    for delta, off in _cases(2.0, seed + 40):
        a, b = rng.uniform(0.4, 0.9), rng.uniform(0.4, 0.9)
        shear = b * np.array([np.sin(np.radians(delta)), np.cos(np.radians(delta)), 0.0])
        local = np.array([np.zeros(3), [a, 0, 0], np.array([a, 0.0, 0.0]) + shear, shear])
        corners, _, _ = _placed(local, rng)
        problem = plausibility(corners, QUIET)
        assert (problem is not None) == off, (delta, problem)
        if off:
            assert problem.startswith("right angles at the corners")


def test_forces_below_20_kN_and_corners_within_50_m():
    rng = np.random.default_rng(5)
    corners = _rectangle(0.6, 0.4)
    for force, off in _cases(2e4, 50):
        forces = np.zeros((10, 3))
        forces[rng.integers(10), rng.integers(3)] = force * rng.choice([-1, 1])
        assert (plausibility(corners, forces) is not None) == off, force
    for reach, off in _cases(50.0, 51):
        far = corners + np.array([reach - 0.6, 0.0, 0.0])  # the farthest corner at ``reach``
        problem = plausibility(far, QUIET)
        assert (problem is not None) == off, reach
        assert plausibility(np.where(np.eye(4, 3, dtype=bool), np.nan, corners), QUIET) \
            .startswith("finite corners")


def _standing(rng, *, inside: float, height: float, speed: float, seconds: float,
              force: float, rate: float = 100.0):
    """A plate anywhere; a marker ``inside`` m from its nearest edge and ``height`` m above it
    (negative: below), sliding at ``speed`` m/s for ``seconds`` while the plate reads ``force``
    N; before and after, the marker is far away and the plate loaded."""
    a, b = rng.uniform(0.4, 0.6), rng.uniform(0.5, 0.7)
    corners, rotation, shift = _placed(_rectangle(a, b), rng)
    still = round(seconds * rate)
    n = still + 40
    markers = np.full((n, 1, 3), np.nan)
    normal_force = np.full(n, 500.0)
    frames = np.arange(20, 20 + still)
    along = speed * (frames - 20) / rate  # from the edge at ``inside`` inwards along y
    local = np.column_stack([np.full(still, a / 2), inside + along, np.full(still, height)])
    markers[frames, 0] = local @ rotation.T + shift
    # one frame on each side, still on the plate: the speed at the run's ends is defined
    for f, y in ((19, inside - speed / rate), (20 + still, inside + speed * still / rate)):
        markers[f, 0] = np.array([a / 2, y, height]) @ rotation.T + shift
    normal_force[19:21 + still] = force
    return corners, normal_force, markers, rate


def test_a_still_marker_on_an_unloaded_plate_near_each_threshold():
    rng = np.random.default_rng(7)
    typical = {"inside": 0.1, "height": 0.03, "speed": 0.0, "seconds": 0.5, "force": 2.0}
    need = {"seconds": STAND_TIME + 0.02}  # a frame beyond ceil(0.25 s × 100 Hz) rounding
    for name, threshold, holds in (
            ("inside", STAND_MARGIN, lambda v: v >= STAND_MARGIN),
            ("height", STAND_HEIGHT, lambda v: v <= STAND_HEIGHT),
            ("height", -STAND_HEIGHT, lambda v: v >= -STAND_HEIGHT),
            ("speed", STAND_SPEED, lambda v: v < STAND_SPEED),
            ("force", MIN_LOAD, lambda v: v < MIN_LOAD),
            ("force", -MIN_LOAD, lambda v: v > -MIN_LOAD)):
        for value, _ in _cases(threshold, 60 + len(name), count=3):
            case = {**typical, **need, name: value}
            corners, force, markers, rate = _standing(rng, **case)
            problem = unloaded_under_a_foot(corners, force, markers, ["HEEL"], rate)
            assert (problem is not None) == holds(value), (name, value, problem)
            if problem is not None:
                assert "'HEEL' stands on the plate" in problem


def test_standing_a_quarter_second_or_more():
    """25 still frames at 100 Hz (0.25 s) are enough, 24 are not."""
    rng = np.random.default_rng(9)
    for frames, flagged in ((24, False), (25, True), (26, True), (12, False)):
        corners, force, markers, rate = _standing(
            rng, inside=0.1, height=0.02, speed=0.0, seconds=frames / 100.0, force=1.0)
        problem = unloaded_under_a_foot(corners, force, markers, ["TOE"], rate)
        assert (problem is not None) == flagged, (frames, problem)

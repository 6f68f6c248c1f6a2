"""Sub-frame timing of the gait events (gait/events.py).

* Plates: a force that rises linearly from zero at a random instant (between frames and between
  analog samples) and falls likewise, on a type-2 plate written from scratch. The strike is the
  force's crossing of the noise floor (2 N on a noiseless plate), T_on + 2 N / slope, and the
  off its last crossing: exact where the crossing lies a sample or more past the ramp's start
  (linear between samples), within a sample otherwise. A frame's mean (the old rule) put the
  strike up to a frame early.
* Markers (Zeni et al. 2008): heels and toes swinging as cosines about a pelvis walking at a
  constant speed, their extremes at random instants between frames; the parabola through three
  frames finds each within 0.1 ms (its own error, O((ω dt)²) of the offset, is 1e-5 s here).
* The file's EVENT section: times from the capture's start, shifted by a first frame other than
  1, and kept only within half a frame of the trial's first and last frames.
"""

from __future__ import annotations

from pathlib import Path

import ezc3d
import numpy as np
import pytest
from ezc3d import ezc3d as swig

from fccgrb_cli.gait.events import c3d_events, kinematic_events, plate_events

FLOOR = 2.0  # N: the noise band's least half-width, on a plate without noise


def _plate_trial(path: Path, force: np.ndarray, rate: float, per: int) -> Path:
    """One marker and one AMTI-style (type 2) plate 0.5 × 0.4 m whose vertical force on the
    subject is ``force`` (one value per analog sample, ``per`` a frame)."""
    n = len(force) // per
    c3d = ezc3d.c3d()
    c3d["parameters"]["POINT"]["RATE"]["value"] = [rate]
    c3d["parameters"]["POINT"]["LABELS"]["value"] = ["M"]
    c3d["parameters"]["POINT"]["UNITS"]["value"] = ["mm"]
    c3d["data"]["points"] = np.ones((4, 1, n))
    c3d["parameters"]["ANALOG"]["RATE"]["value"] = [rate * per]
    c3d["parameters"]["ANALOG"]["LABELS"]["value"] = ["Fx", "Fy", "Fz", "Mx", "My", "Mz"]
    analogs = np.zeros((1, 6, len(force)))
    analogs[0, 2] = -force  # the plate's own z points down (corners below): Fz < 0 pushes down

    def integers(name: str, values: list[int], dims: list[int]) -> None:
        parameter = swig.Parameter(name)  # ezc3d.add_parameter would store floats
        parameter.set(swig.VecInt(values), swig.VecUInt(dims))
        c3d["parameters"].add_parameter("FORCE_PLATFORM", parameter)

    c3d["data"]["analogs"] = analogs
    c3d.add_parameter("FORCE_PLATFORM", "USED", 1)
    integers("TYPE", [2], [1])
    corners = np.array([[500.0, 400, 0], [500, 0, 0], [0, 0, 0], [0, 400, 0]]).T[:, :, None]
    c3d.add_parameter("FORCE_PLATFORM", "CORNERS", corners)
    c3d.add_parameter("FORCE_PLATFORM", "ORIGIN", np.array([[0.0], [0.0], [-40.0]]))
    integers("CHANNEL", list(range(1, 7)), [6, 1])
    c3d.write(str(path))
    return path


@pytest.mark.parametrize("seed", range(4))
def test_plate_strike_and_off_between_samples(tmp_path: Path, seed: int):
    rng = np.random.default_rng(seed)
    rate, per = 100.0, int(rng.choice([4, 10, 20]))
    samples = int(rng.integers(120, 200)) * per
    t = np.arange(samples) / (rate * per)
    peak = rng.uniform(300, 900)
    rise, fall = rng.uniform(0.03, 0.3, 2)
    on = rng.uniform(0.15, 0.4)
    off = rng.uniform(on + rise + fall + 0.1, t[-1] - 0.15)
    force = peak * np.clip((t - on) / rise, 0, 1) * np.clip((off - t) / fall, 0, 1)
    path = _plate_trial(tmp_path / "plate.c3d", force, rate, per)
    events = plate_events(path, rate, {"foot_r": np.ones(samples // per, bool)})
    assert events.side == ("right", "right") and events.kind == ("strike", "off")
    sample = 1.0 / (rate * per)
    for found, crossing, lead in ((events.time[0], on + FLOOR / peak * rise, FLOOR / peak * rise),
                                  (events.time[1], off - FLOOR / peak * fall,
                                   FLOOR / peak * fall)):
        tolerance = 1e-9 if lead > sample else sample
        assert abs(found - crossing) <= tolerance, (found, crossing, lead, sample)


def test_a_bump_under_the_threshold_is_no_contact(tmp_path: Path):
    """The threshold (20 N on a frame's mean) decides whether there is a contact: a 19 N bump
    gives none, a 21 N one a strike and an off."""
    rate, per = 100.0, 10
    t = np.arange(150 * per) / (rate * per)
    for height, found in ((19.0, 0), (21.0, 2)):
        force = height * np.clip((t - 0.5) / 0.01, 0, 1) * np.clip((1.0 - t) / 0.01, 0, 1)
        path = _plate_trial(tmp_path / f"bump{height:g}.c3d", force, rate, per)
        events = plate_events(path, rate, {"foot_l": np.ones(150, bool)})
        assert (0 if events is None else len(events)) == found


@pytest.mark.parametrize("seed", range(3))
def test_zeni_extremes_between_frames(seed: int):
    rng = np.random.default_rng(seed)
    rate = 100.0
    time = np.arange(int(rng.integers(400, 600))) / rate
    speed, stride = rng.uniform(1.0, 1.5), rng.uniform(0.9, 1.2)
    pelvis = np.column_stack([speed * time, np.zeros_like(time), np.ones_like(time)])
    markers = {"pelvis": pelvis}
    phases = {"left": rng.uniform(0, stride)}
    phases["right"] = phases["left"] + stride / 2
    for side, phase in phases.items():
        swing = 0.4 * np.cos(2 * np.pi * (time - phase) / stride)
        heel = pelvis + np.column_stack([swing, np.zeros_like(time), -np.ones_like(time)])
        markers[f"{side}_heel"] = heel
        markers[f"{side}_toe"] = heel + np.array([0.15, 0.0, 0.0])
    events = kinematic_events(markers, rate, np.array([0.0, 0.0, 1.0]), "synthetic")
    inner = (time[-1] - 0.3, 0.3)
    for side, phase in phases.items():
        for kind, shift in (("strike", 0.0), ("off", stride / 2)):
            found = events.of(side, kind)
            found = found[(found > inner[1]) & (found < inner[0])]
            k = np.round((found - phase - shift) / stride)
            expected = phase + shift + k * stride
            assert len(found) >= 2
            np.testing.assert_allclose(found, expected, atol=1e-4)


def test_file_events_from_a_later_first_frame_and_at_the_trial_edges(tmp_path: Path):
    """A trial captured from frame 101 (100 Hz, 50 frames: t = 0 is the capture's 1.00 s): an
    event at 1.234 s of the capture is at 0.234 s of the trial; events up to half a frame
    outside the first and last frames are kept, further ones are not."""
    rate, n, first = 100.0, 50, 101
    start = (first - 1) / rate
    inside = [(start + 0.234, "Left", "Foot Strike", True),
              (start - 0.49 / rate, "Right", "Foot Off", True),
              (start - 0.51 / rate, "Right", "Foot Strike", False),
              (start + (n - 1 + 0.49) / rate, "Left", "Foot Off", True),
              (start + (n - 1 + 0.51) / rate, "Left", "Foot Strike", False)]
    c3d = ezc3d.c3d()
    c3d["parameters"]["POINT"]["RATE"]["value"] = [rate]
    c3d["parameters"]["POINT"]["LABELS"]["value"] = ["M"]
    c3d["data"]["points"] = np.ones((4, 1, n))
    c3d["header"]["points"]["first_frame"] = first - 1  # ezc3d counts from 0
    for t, context, label, _ in inside:
        c3d.add_event([0, t], context=context, label=label)
    c3d.write(str(tmp_path / "late.c3d"))
    events = c3d_events(tmp_path / "late.c3d", n, rate)
    kept = sorted((t - start, context.lower()) for t, context, _, keep in inside if keep)
    np.testing.assert_allclose(events.time, [t for t, _ in kept], atol=1e-6)
    assert events.side == tuple(side for _, side in kept)

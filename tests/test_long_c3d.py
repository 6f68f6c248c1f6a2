"""Trials past 65,535 frames (5.5 minutes at 200 Hz): ezc3d counts frames in a 16-bit word and
stops there; the frames after are read from the file's data section itself
(io/c3d_header.read_points), with the count from TRIAL:ACTUAL_START_FIELD/ACTUAL_END_FIELD as
the C3D standard gives it."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from fccgrb_cli.trial.c3d import save
from fccgrb_cli.trial.c3d_header import read_layout
from fccgrb_cli.trial.record import read_trial

FRAMES = 70_000


def long_file(path: Path, markers: np.ndarray, rate: float) -> None:
    """Markers (frames × 2 × 3, m) as a float C3D in mm with the frame range in
    TRIAL:ACTUAL_START_FIELD/ACTUAL_END_FIELD (two 16-bit words each, low first)."""
    import ezc3d

    c3d = ezc3d.c3d()
    point = c3d["parameters"]["POINT"]
    point["RATE"]["value"], point["LABELS"]["value"] = [rate], ["A", "B"]
    point["UNITS"]["value"] = ["mm"]
    points = np.ones((4, 2, len(markers)))
    points[:3] = np.transpose(markers * 1e3, (2, 1, 0))
    c3d["data"]["points"] = points
    c3d.add_parameter("TRIAL", "ACTUAL_START_FIELD", [1, 0])
    c3d.add_parameter("TRIAL", "ACTUAL_END_FIELD", [len(markers) & 0xFFFF, len(markers) >> 16])
    save(c3d, path)


def test_every_frame_of_a_long_trial_is_read(tmp_path: Path) -> None:
    t = np.arange(FRAMES)
    markers = np.zeros((FRAMES, 2, 3))
    markers[:, 0, 0] = t * 1e-5                      # 0.7 m by the end: a frame's own value
    markers[:, 0, 1] = 0.1 * np.sin(t / 100)
    markers[:, 1, 2] = 1.0 + 1e-6 * (t % 1000)
    markers[123, 1] = np.nan                         # gaps before and after frame 65,535
    markers[69_000, 0] = np.nan
    path = tmp_path / "long.c3d"
    long_file(path, markers, 200.0)
    assert read_layout(path).frames == FRAMES
    trial = read_trial(path)
    assert trial.markers.shape == (FRAMES, 2, 3) and trial.labels == ("A", "B")
    assert trial.rate == 200.0
    gaps = np.isnan(trial.markers)
    assert gaps.sum() == 6 and gaps[123, 1].all() and gaps[69_000, 0].all()
    # float32 millimetres: 0.7 m to 6e-8 m; the last frame is the last frame's own value
    assert np.nanmax(np.abs(trial.markers - markers)) < 1e-7
    assert abs(trial.markers[-1, 0, 0] - (FRAMES - 1) * 1e-5) < 1e-7

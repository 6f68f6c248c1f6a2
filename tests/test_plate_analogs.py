"""``trial.plate_analogs``: force platforms from the analog channels in numpy, against ezc3d's own
extraction (``extract_forceplat_data=True``) of the same files: generated C3D files of platform
types 1, 2 and 4 (random corners, origins, calibration matrices and channels, written by ezc3d)
and the shared recorded files; and what it leaves to ezc3d."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

ezc3d = pytest.importorskip("ezc3d")

from fccgrb_cli.trial.plate_analogs import platforms  # noqa: E402

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
RECORDED = [DATA / "c3d" / "Qualisys.c3d", DATA / "c3d" / "FP_Type1.c3d",
            DATA / "c3d" / "plugin_gait" / "HC030A05.c3d",
            DATA / "c3d" / "plugin_gait" / "btk_lowerbody_3fp" / "PiG_Motion3_FF.c3d",
            DATA / "opensim" / "c3d_walking" / "walking2.c3d"]
KEYS = ("corners", "origin", "force", "moment", "center_of_pressure", "Tz")


def assert_as_ezc3d(path: Path) -> None:
    theirs = ezc3d.c3d(str(path), extract_forceplat_data=True)["data"]["platform"]
    mine = platforms(ezc3d.c3d(str(path)))
    assert mine is not None and len(mine) == len(theirs)
    for k, (a, b) in enumerate(zip(mine, theirs, strict=True)):
        for unit in ("unit_force", "unit_moment", "unit_position"):
            assert a[unit] == b[unit], (k, unit)
        for key in KEYS:
            expected = np.asarray(b[key], dtype=float)
            got = np.asarray(a[key], dtype=float)
            assert got.shape == expected.shape, (k, key)
            scale = max(float(np.nanmax(np.abs(expected[np.isfinite(expected)]), initial=0.0)),
                        1.0)
            finite = np.isfinite(expected)
            assert np.array_equal(np.isfinite(got), finite), (k, key)
            assert np.abs(got[finite] - expected[finite]).max(initial=0.0) <= 1e-9 * scale, \
                (k, key)


@pytest.mark.parametrize("path", RECORDED, ids=lambda p: p.name)
def test_recorded_files_as_ezc3d(path: Path) -> None:
    if not path.exists():
        pytest.skip(f"{path}: the shared data folder is not here")
    assert_as_ezc3d(path)


def generated(path: Path, kinds: list[int], seed: int, empty_calibration: bool = False) -> Path:
    rng = np.random.default_rng(seed)
    frames, per_frame = 20, 4
    c3d = ezc3d.c3d()
    c3d["parameters"]["POINT"]["RATE"]["value"] = [100.0]
    c3d["parameters"]["POINT"]["LABELS"]["value"] = ("M1",)
    c3d["parameters"]["POINT"]["UNITS"]["value"] = ["mm"]
    c3d["data"]["points"] = np.vstack([rng.normal(size=(3, 1, frames)), np.ones((1, 1, frames))])
    n = 6 * len(kinds)
    c3d["parameters"]["ANALOG"]["RATE"]["value"] = [100.0 * per_frame]
    c3d["parameters"]["ANALOG"]["LABELS"]["value"] = tuple(f"A{k}" for k in range(n))
    analogs = rng.normal(size=(1, n, frames * per_frame)) * 50.0
    for k in range(len(kinds)):
        analogs[0, 6 * k + 2] += 300.0 + 100.0 * k  # a normal force away from zero
    analogs[0, 2, 3] = 0.0  # and one sample without load: ezc3d's inf and NaN
    c3d["data"]["analogs"] = analogs
    corners = np.zeros((3, 4, len(kinds)))
    for k in range(len(kinds)):
        turn = rng.uniform(0.0, 2.0 * np.pi)
        R = np.array([[np.cos(turn), -np.sin(turn), 0.0], [np.sin(turn), np.cos(turn), 0.0],
                      [0.0, 0.0, 1.0]])
        local = np.array([[250.0, 300.0, 0.0], [-250.0, 300.0, 0.0], [-250.0, -300.0, 0.0],
                          [250.0, -300.0, 0.0]]).T
        corners[:, :, k] = R @ local + rng.normal(size=(3, 1)) * 400.0
    origins = rng.normal(size=(3, len(kinds))) * 20.0
    origins[2] = rng.choice([-1.0, 1.0], size=len(kinds)) * rng.uniform(10.0, 50.0, len(kinds))
    calibration = np.eye(6)[:, :, None] + rng.normal(size=(6, 6, len(kinds))) * 0.05
    group = c3d["parameters"]["FORCE_PLATFORM"]  # ezc3d's own, integers kept INT
    group["USED"]["value"] = np.array([len(kinds)])
    group["TYPE"]["value"] = np.array(kinds)
    group["CHANNEL"]["value"] = np.arange(1, n + 1).reshape(len(kinds), 6).T
    group["CORNERS"]["value"] = corners
    group["ORIGIN"]["value"] = origins
    group["CAL_MATRIX"]["value"] = np.zeros((6, 6, 0)) if empty_calibration else calibration
    c3d.write(str(path))
    return path


@pytest.mark.parametrize("seed", range(6))
def test_generated_platforms_as_ezc3d(tmp_path: Path, seed: int) -> None:
    kinds = [[1], [2], [4], [2, 4], [4, 1, 2], [1, 2, 4, 4]][seed]
    assert_as_ezc3d(generated(tmp_path / "plates.c3d", kinds, seed))


def test_type_4_without_its_calibration_left_to_ezc3d(tmp_path: Path) -> None:
    path = generated(tmp_path / "plates.c3d", [4], 0, empty_calibration=True)
    with pytest.raises(Exception, match="CAL_MATRIX"):
        ezc3d.c3d(str(path), extract_forceplat_data=True)
    assert platforms(ezc3d.c3d(str(path))) is None


def test_kistler_and_incomplete_parameters_left_to_ezc3d(tmp_path: Path) -> None:
    path = generated(tmp_path / "plates.c3d", [2], 0)
    c3d = ezc3d.c3d(str(path))
    c3d["parameters"]["FORCE_PLATFORM"]["TYPE"]["value"] = np.array([3])
    assert platforms(c3d) is None
    c3d = ezc3d.c3d(str(path))
    del c3d["parameters"]["FORCE_PLATFORM"]["CORNERS"]
    assert platforms(c3d) is None


def test_coincident_corners_give_nan_as_ezc3d_without_a_warning(tmp_path: Path) -> None:
    path = generated(tmp_path / "plates.c3d", [2, 1], 0)
    c3d = ezc3d.c3d(str(path))
    c3d["parameters"]["FORCE_PLATFORM"]["CORNERS"]["value"] = np.zeros((3, 4, 2))
    c3d.write(str(path))
    theirs = ezc3d.c3d(str(path), extract_forceplat_data=True)["data"]["platform"]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        mine = platforms(ezc3d.c3d(str(path)))
    assert mine is not None
    for a, b in zip(mine, theirs, strict=True):
        assert np.isnan(a["force"]).all() and np.isnan(np.asarray(b["force"])).all()

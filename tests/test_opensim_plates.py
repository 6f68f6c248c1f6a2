"""Force plates as OpenSim reads them: on opensim-core's walking2.c3d and walking5.c3d (Vicon
Nexus, treadmill, 250 Hz markers, 2000 Hz analog, two type-2 plates; ../shared/data, never
copied), fccgrb's plate reading equals OpenSim 4.5's C3D adapter output stored beside them:

* every analog sample (``plate_samples``, SI): force, centre of pressure and free moment equal
  ``std_cop_walking*_grfs.sto`` (N, mm, N·mm) to the 8 decimals it prints; the centre of
  pressure and free moment carried to the plate's centre equal ``std_walking*_grfs.sto``'s
  moments there (the two files agree with each other through fccgrb's numbers);
* every point frame (``read_force_plates``, what the inverse dynamics gets) at the reference's
  rows that fall on a frame's time, where the plate is loaded: forces within 0.5 % of the
  plate's peak normal force, centre of pressure within 2 mm, free moment within 0.25 N·m (the
  frame's value is the samples averaged over a window centred on the frame's time; OpenSim's is
  the one sample at that time); where fccgrb counts the plate unloaded (the force pressing the
  subject below 20 N), OpenSim's pressing force is below 20 N too.

The comparison is shown to fail on a flipped axis, a mm/m slip and a one-frame delay."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from fccgrb_cli.opensim.storage import read_storage
from fccgrb_cli.trial.forceplates import plate_file, plate_samples, read_force_plates
from fccgrb_cli.trial.record import read_trial

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "opensim" / "c3d_walking"
TRIALS = ("walking2", "walking5")
pytestmark = pytest.mark.skipif(not DATA.is_dir(), reason=f"{DATA} absent")

ANALOG_RATE = 2000.0   # Hz, the files' ANALOG:RATE
THRESHOLD = 20.0       # N, fccgrb's default plate threshold
FORCE_TOL = 0.005      # of the plate's peak normal force
COP_TOL = 2e-3         # m
FREE_TOL = 0.25        # N·m


def _reference(trial: str, kind: str = "std_cop"):
    """The reference's samples: their analog indices and, per plate, f (N), p (m), m (N·m)."""
    table = read_storage(DATA / f"{kind}_{trial}_grfs.sto")
    index = np.rint(table.time * ANALOG_RATE).astype(int)
    assert np.allclose(index / ANALOG_RATE, table.time, atol=1e-7)
    plates = []
    for k in (1, 2):
        f, p, m = (np.column_stack([table.column(f"{c}{k}_{a}") for a in (1, 2, 3)])
                   for c in "fpm")
        plates.append((f, p * 1e-3, m * 1e-3))
    return index, plates


@pytest.mark.parametrize("trial", TRIALS)
def test_every_sample_equals_opensims(trial):
    index, reference = _reference(trial)
    found = plate_file(DATA / f"{trial}.c3d")
    assert len(found.plates) == 2
    for raw, (f, p, m) in zip(found.plates, reference, strict=True):
        force, cop, free = plate_samples(raw)
        np.testing.assert_allclose(force[index], f, rtol=0, atol=1e-6)
        np.testing.assert_allclose(cop[index], p, rtol=0, atol=1e-9)
        np.testing.assert_allclose(free[index], m, rtol=0, atol=1e-8)


@pytest.mark.parametrize("trial", TRIALS)
def test_moments_at_the_plate_centre_equal_opensims(trial):
    """M_o = (p − o) × f + free moment, with o the plate's centre (fccgrb's corners' mean)."""
    index, _ = _reference(trial)
    _, at_origin = _reference(trial, "std")
    plates = read_force_plates(DATA / f"{trial}.c3d", read_trial(DATA / f"{trial}.c3d").n_frames)
    for plate, raw, (f, o, m) in zip(plates, plate_file(DATA / f"{trial}.c3d").plates,
                                     at_origin, strict=True):
        centre = plate.corners.mean(axis=0)
        np.testing.assert_allclose(o, np.tile(centre, (len(o), 1)), rtol=0, atol=1e-6)
        force, cop, free = (x[index] for x in plate_samples(raw))
        np.testing.assert_allclose(force, f, rtol=0, atol=1e-6)
        np.testing.assert_allclose(np.cross(cop - centre, force) + free, m, rtol=0, atol=1e-6)


def _disagreements(trial: str, plates) -> list[str]:
    """Where fccgrb's frames and OpenSim's rows at those frames' times differ beyond the
    tolerances, in words (empty: they agree)."""
    index, reference = _reference(trial)
    per = 8  # analog samples per point frame (2000 / 250 Hz)
    on_frame = index % per == 0
    frame = index[on_frame] // per
    normal = np.array([0.0, 0.0, 1.0])  # the lab's vertical (Z up), the subject pushed upwards
    out = []
    for plate, (f, p, m) in zip(plates, reference, strict=True):
        f, p, m = f[on_frame], p[on_frame], m[on_frame]
        loaded = np.abs(plate.force[frame]).any(axis=1)
        peak = np.abs(f @ normal).max()
        if loaded.sum() < 4:
            out.append(f"plate {plate.number}: {loaded.sum()} loaded frames at the rows")
        worst = np.abs(plate.force[frame][loaded] - f[loaded]).max(initial=0)
        if worst > FORCE_TOL * peak:
            out.append(f"plate {plate.number}: force off by {worst:.3g} N")
        worst = np.abs(plate.cop[frame][loaded] - p[loaded]).max(initial=0)
        if worst > COP_TOL:
            out.append(f"plate {plate.number}: centre of pressure off by {1e3 * worst:.3g} mm")
        worst = np.abs(plate.free_moment[frame][loaded] - m[loaded]).max(initial=0)
        if worst > FREE_TOL:
            out.append(f"plate {plate.number}: free moment off by {worst:.3g} N·m")
        if (f[~loaded] @ normal >= THRESHOLD).any() or plate.force[frame][~loaded].any():
            out.append(f"plate {plate.number}: unloaded frames disagree")
    return out


def _plates(trial: str):
    path = DATA / f"{trial}.c3d"
    return read_force_plates(path, read_trial(path).n_frames, THRESHOLD)


@pytest.mark.parametrize("trial", TRIALS)
def test_frames_equal_opensims_rows(trial):
    plates = _plates(trial)
    assert [p.problem for p in plates] == [None, None]
    assert _disagreements(trial, plates) == []


@pytest.mark.parametrize("mutation", ["flipped x", "swapped x and y", "mm for m", "N·mm for N·m",
                                      "one frame late", "free moment reversed"])
def test_the_comparison_catches_slips(mutation):
    plates = _plates("walking2")
    slipped = []
    for plate in plates:
        force, cop, free = plate.force.copy(), plate.cop.copy(), plate.free_moment.copy()
        if mutation == "flipped x":
            force[:, 0] *= -1
        elif mutation == "swapped x and y":
            force = force[:, [1, 0, 2]]
        elif mutation == "mm for m":
            cop = cop * 1e3
        elif mutation == "N·mm for N·m":
            free = free * 1e3
        elif mutation == "one frame late":
            force, cop, free = (np.roll(x, 1, axis=0) for x in (force, cop, free))
        else:
            free = -free
        slipped.append(replace(plate, force=force, cop=cop, free_moment=free))
    assert _disagreements("walking2", slipped)


def test_an_offset_pulling_the_subject_is_no_contact():
    """walking5's plate 2 reads about −20 N along the vertical between steps (an offset, the
    subject pulled down): not a load, however large its magnitude."""
    found = plate_file(DATA / "walking5.c3d")
    force, _, _ = plate_samples(found.plates[1])
    assert force[:, 2].min() < -THRESHOLD  # the offset, beyond the threshold's magnitude
    plate = _plates("walking5")[1]
    loaded = np.abs(plate.force).any(axis=1)
    assert (plate.force[loaded, 2] >= THRESHOLD).all()
    assert (plate.force[~loaded] == 0).all()


@pytest.mark.parametrize("trial", TRIALS)
def test_frames_are_the_wrench_averaged_over_the_frames_window(trial):
    """Each loaded frame's centre of pressure and free moment are those of the force and the
    moment about the plate's centre averaged over the frame's window (samples 8 j − 4 … 8 j + 4,
    the ends at half weight), by the plate's own formulas: for the surface z = 0, p − o =
    (−M_y / f_z, M_x / f_z, 0) and τ = M_z − ((p − o) × f)_z."""
    found = plate_file(DATA / f"{trial}.c3d")
    for plate, raw in zip(_plates(trial), found.plates, strict=True):
        force, cop, free = plate_samples(raw)
        centre = plate.corners.mean(axis=0)
        assert np.allclose(cop[:, 2], centre[2]) and np.allclose(plate.corners[:, 2], centre[2])
        moment = np.cross(cop - centre, force) + free
        weight = np.r_[0.5, np.ones(7), 0.5]
        loaded = np.flatnonzero(np.abs(plate.force).any(axis=1))
        loaded = loaded[(loaded > 0) & (loaded < len(plate.force) - 1)]
        for j in loaded:
            window = slice(8 * j - 4, 8 * j + 5)
            f = weight @ force[window] / weight.sum()
            m = weight @ moment[window] / weight.sum()
            arm = np.array([-m[1] / f[2], m[0] / f[2], 0.0])
            np.testing.assert_allclose(plate.force[j], f, rtol=1e-12, atol=1e-9)
            np.testing.assert_allclose(plate.cop[j] - centre, arm, rtol=0, atol=1e-9)
            np.testing.assert_allclose(plate.free_moment[j], [0, 0, m[2] - np.cross(arm, f)[2]],
                                       rtol=0, atol=1e-9)

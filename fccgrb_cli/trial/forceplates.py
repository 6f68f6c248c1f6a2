"""Force platforms from C3D (ezc3d's platform data): ground reaction force on the subject,
centre of pressure and free moment, in the global frame, SI, resampled to the point rate."""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from fccgrb_cli.core.errors import InputError
from fccgrb_cli.trial.c3d_file import ezc3d_read
from fccgrb_cli.trial.plate_analogs import platforms

_LENGTH = {"mm": 1e-3, "m": 1.0, "cm": 1e-2}
_MOMENT = {"Nmm": 1e-3, "Nm": 1.0, "N.mm": 1e-3, "N.m": 1.0}
MIN_LOAD = 10.0      # N: the least normal force a foot standing on a plate puts on it
STAND_MARGIN = 0.02  # m inside the plate's outline (not a marker stuck on a plate corner)
STAND_HEIGHT = 0.08  # m above the plate's surface (heel, metatarsal and toe markers)
STAND_SPEED = 0.1    # m/s: still, as a stance foot's markers are and a swinging foot's are not
STAND_TIME = 0.25    # s: how long it must stand there unloaded


@dataclass(frozen=True)
class ForcePlate:
    """Plate ``number`` (1-based, as in FORCE_PLATFORM): force (frames × 3, N), centre of
    pressure (frames × 3, m), free moment (frames × 3, N·m), corners (4 × 3, m); ``problem``
    says why the plate is implausible (None when it looks like a plate)."""

    number: int
    force: np.ndarray
    cop: np.ndarray
    free_moment: np.ndarray
    corners: np.ndarray
    problem: str | None


def _windows(samples: int, n_frames: int) -> tuple[np.ndarray, np.ndarray]:
    """Each point frame's analog samples and weights (frames × window): the window centred on
    the frame's own time. Sample ``per·j`` is taken with frame j (C3D; OpenSim times them so),
    so an even ``per`` takes samples per·j − per/2 … per·j + per/2 with half weights at both
    ends, an odd one per·j − (per−1)/2 … per·j + (per−1)/2; indices outside the record get
    weight 0. (Averaging samples per·j … per·j + per − 1 instead would delay every load by
    (per − 1)/2 samples: 1.75 ms at 2000/250 Hz, 33 N at a heel strike of walking2.c3d.)"""
    per = samples // n_frames if n_frames else 0
    if per < 1:
        raise InputError(f"force platform data has {samples} samples for {n_frames} frames")
    half = per // 2
    offsets = np.arange(-half, half + 1)
    weights = np.ones(len(offsets))
    if per % 2 == 0:
        weights[[0, -1]] = 0.5
    index = per * np.arange(n_frames)[:, None] + offsets
    inside = (index >= 0) & (index < per * n_frames)
    return np.clip(index, 0, samples - 1), np.where(inside, weights, 0.0)


def _mean(signal: np.ndarray, index: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Weighted mean of ``signal`` (samples × 3) over each frame's window → frames × 3; samples
    that are NaN are left out, a frame with none left is NaN."""
    values = signal[index]                                   # frames × window × 3
    w = np.where(np.isnan(values), 0.0, weights[..., None])
    total = w.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(total != 0, (np.nan_to_num(values) * w).sum(axis=1) / total, np.nan)


def plate_samples(raw: RawPlate) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One plate's force on the subject (N), centre of pressure (m) and free moment (N·m) at
    every analog sample (samples × 3 each, global frame), as ezc3d computes them from the
    channels and the file's calibration, in SI."""
    length = _LENGTH.get(raw.unit_position.strip(), 1e-3)
    moment = _MOMENT.get(raw.unit_moment.strip().replace(" ", ""), 1e-3)
    return raw.force.T, raw.cop.T * length, np.nan_to_num(raw.free.T) * moment


def _frames(raw: RawPlate, n_frames: int, normal: np.ndarray
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Force, centre of pressure and free moment per point frame (frames × 3 each): the
    samples averaged over each frame's centred window (``_windows``), the centre of pressure
    weighted by the normal force (which makes it the centre of pressure of the averaged forces
    and moments) and the free moment taken about it."""
    force, cop, free = plate_samples(raw)
    index, weights = _windows(len(force), n_frames)
    mean_force = _mean(force, index, weights)
    pressing = weights * (force @ normal)[index]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        mean_cop = _mean(cop, index, pressing)
    # each sample's couple about the frame's centre of pressure, its normal part
    arm = cop[index] - mean_cop[:, None, :]
    twist = (np.cross(arm, force[index]) @ normal)[..., None] * normal
    mean_free = _mean(free, index, weights) + np.nan_to_num(
        (twist * weights[..., None]).sum(axis=1) / weights.sum(axis=1)[:, None])
    return mean_force, mean_cop, mean_free


def plausibility(corners: np.ndarray, force: np.ndarray) -> str | None:
    """What a force plate would have that these corners and forces lack ("expected …, got …"),
    or None when they look like a plate: finite corners near the origin, sides of 0.1–3 m (from
    a 0.3 m wide sensor to an instrumented-treadmill belt), forming a planar rectangle (opposite
    corners' midpoints within 5 cm, every corner within 5 mm of the corners' plane, every angle
    within 2° of 90°), and forces below 20 kN."""
    if not np.isfinite(corners).all() or np.abs(corners).max() > 50.0:
        return ("finite corners within 50 m of the origin, got coordinates up to "
                f"{np.nanmax(np.abs(corners)):.3g} m")
    edges = np.roll(corners, -1, axis=0) - corners
    sides = np.linalg.norm(edges, axis=1)
    if sides.min() < 0.1 or sides.max() > 3.0:
        return f"sides of 0.1–3 m, got {', '.join(f'{s:.3g}' for s in sides)} m"
    skew = np.linalg.norm(corners[0] + corners[2] - corners[1] - corners[3])
    if skew > 0.05:
        return f"four corners forming a rectangle, got diagonals {skew:.3g} m apart at the middle"
    centred = corners - corners.mean(axis=0)
    off_plane = np.linalg.svd(centred, compute_uv=False)[2] / 2.0  # each corner's distance
    if off_plane > 0.005:
        return f"four corners in one plane, got corners {1e3 * off_plane:.3g} mm off their plane"
    previous = np.roll(edges, 1, axis=0)
    cosines = np.abs(np.sum(edges * previous, axis=1)) / (sides * np.roll(sides, 1))
    if cosines.max() > np.sin(np.radians(2.0)):
        worst = np.degrees(np.arccos(np.clip(cosines.max(), 0.0, 1.0)))
        return (f"right angles at the corners (within 2°), got an angle {90 - worst:.3g}° off "
                "a right angle")
    if not np.isfinite(force).all() or np.abs(force).max() > 2e4:
        return (f"finite forces below 20 kN, got {np.nanmax(np.abs(force)):.3g} N (the "
                "calibration looks wrong)")
    return None


def unloaded_under_a_foot(corners: np.ndarray, normal_force: np.ndarray, markers: np.ndarray,
                          labels: list[str], rate: float) -> str | None:
    """A plate that reads nothing under a foot standing on it ("expected …, got …"), or None.

    A marker *stands* on a plate in a frame where it lies at least ``STAND_MARGIN`` inside the
    plate's outline, at most ``STAND_HEIGHT`` above its surface (heel, toe and metatarsal
    markers of a foot on the plate do; a swinging foot passes, it does not stay) and moves
    slower than ``STAND_SPEED``. A foot on the ground carries part of the body's weight (a
    quiet-standing adult puts hundreds of N on each foot; even a toe touch exceeds 10 N), so a
    plate whose normal force stays below ``MIN_LOAD`` while some marker stands on it for
    ``STAND_TIME`` or longer cannot be measuring (its calibration, zeroing or channel mapping is
    wrong). ``markers`` is frames × markers × 3 (m, NaN where missing), ``normal_force`` the
    force along the plate's normal per frame (N)."""
    e1, e2 = corners[1] - corners[0], corners[3] - corners[0]
    l1, l2 = np.linalg.norm(e1), np.linalg.norm(e2)
    rel = markers - corners[0]
    s1, s2 = rel @ (e1 / l1), rel @ (e2 / l2)  # along the plate's sides, m
    with np.errstate(invalid="ignore"):
        inside = (s1 >= STAND_MARGIN) & (s1 <= l1 - STAND_MARGIN) & \
            (s2 >= STAND_MARGIN) & (s2 <= l2 - STAND_MARGIN)
        low = np.abs(rel @ plate_normal(corners)) <= STAND_HEIGHT
    speed = np.full(inside.shape, np.inf)
    if len(markers) > 2:
        speed[1:-1] = np.linalg.norm(markers[2:] - markers[:-2], axis=2) * rate / 2.0
    with np.errstate(invalid="ignore"):
        standing = inside & low & (speed < STAND_SPEED)
    quiet = np.abs(normal_force) < MIN_LOAD
    if rate <= 0:
        return None
    need = max(int(np.ceil(STAND_TIME * rate)), 1)
    best, best_marker, best_start = 0, -1, 0
    for k in range(standing.shape[1]):
        run = standing[:, k] & quiet
        edges = np.flatnonzero(np.diff(np.concatenate([[0], run.astype(int), [0]])))
        for start, stop in zip(edges[::2], edges[1::2], strict=True):
            if stop - start > best:
                best, best_marker, best_start = stop - start, k, start
    if best < need:
        return None
    window = slice(best_start, best_start + best)
    peak = float(np.abs(normal_force[window]).max())
    label = labels[best_marker] if best_marker < len(labels) else f"point {best_marker + 1}"
    return (f"a normal force of at least {MIN_LOAD:g} N while the marker "
            f"'{label}' stands on the plate, got at most {peak:.3g} N over "
            f"{best / rate:.3g} s from frame index {best_start} (its calibration, zeroing or "
            "channels look wrong)")


@dataclass(frozen=True)
class RawPlate:
    """One platform as ezc3d extracts it, in the file's units: corners (4 × 3), force, centre
    of pressure and free moment Tz per analog sample (3 × samples each)."""

    corners: np.ndarray
    force: np.ndarray
    cop: np.ndarray
    free: np.ndarray
    unit_position: str
    unit_moment: str


@dataclass(frozen=True)
class PlateFile:
    """What the stages read of a C3D's platforms: each plate's raw data, and the file's own
    markers (frames × markers × 3, m; NaN where missing), labels and point rate."""

    plates: tuple[RawPlate, ...]
    markers: np.ndarray
    labels: list[str]
    rate: float


def plate_file(path: str | Path) -> PlateFile:
    """The file's platforms, read once per file and process: the lab's axes, the loads and the
    gait events each ask for them. Platforms of types 1, 2 and 4 are computed from the analog
    channels of the file's ordinary read (``trial.plate_analogs``: what ezc3d's extraction
    gives, 110 ms faster on a gait trial); other types by ezc3d's extraction. Keyed by the
    file's identity (its resolved path, inode, size and modification time), so a file rewritten
    in between is read again; the arrays are read-only."""
    import os

    real = os.path.realpath(path)
    stat = os.stat(real)
    return _read_plate_file(real, (stat.st_ino, stat.st_size, stat.st_mtime_ns), str(path))


@lru_cache(maxsize=1)
def _read_plate_file(real: str, identity: tuple[int, int, int], shown: str) -> PlateFile:
    """plate_file's read (``identity`` in the key only; ``shown``: the path as the user gave
    it, for messages)."""
    try:  # types 1, 2 and 4 from the markers' own read; the others by ezc3d's extraction
        c3d = ezc3d_read(real, False)
        found = platforms(c3d)
        if found is None:
            c3d = ezc3d_read(real, True)
            found = c3d["data"].get("platform", [])
    except Exception as exc:  # ezc3d raises plain RuntimeErrors for unreadable platform data
        reason = str(exc).strip() or exc.__class__.__name__
        raise InputError(f"{shown}: cannot read the force platforms ({reason})") from None
    plates = tuple(_raw_plate(raw) for raw in found)
    point = c3d["parameters"]["POINT"]
    unit = str(point["UNITS"]["value"][0]).strip() if point.get("UNITS", {}).get("value") \
        else "mm"
    xyz = np.asarray(c3d["data"]["points"][:3], dtype=float) * _LENGTH.get(unit, 1e-3)
    xyz = np.transpose(xyz, (2, 1, 0))  # 3 × markers × frames → frames × markers × 3
    xyz[(xyz == 0).all(axis=2)] = np.nan
    labels = [str(x).strip() for x in point["LABELS"]["value"]]
    return PlateFile(plates, _frozen(xyz), labels, float(point["RATE"]["value"][0]))


def _raw_plate(raw: dict) -> RawPlate:
    """One platform of ezc3d's extraction, its arrays read-only."""
    corners, force, cop, free = (_frozen(np.asarray(raw[key], dtype=float)) for key in
                                 ("corners", "force", "center_of_pressure", "Tz"))
    return RawPlate(corners, force, cop, free, str(raw["unit_position"]),
                    str(raw["unit_moment"]))


def _frozen(values: np.ndarray) -> np.ndarray:
    values.flags.writeable = False
    return values


def read_force_plates(path: str | Path, n_frames: int, threshold: float = 20.0
                      ) -> list[ForcePlate]:
    """Every plate of the file; frames whose force pressing the subject away from the plate is
    below ``threshold`` N carry no load (the centre of pressure is then undefined and set to
    the plate centre). A force pulling the subject towards the plate is an unloaded plate's
    offset (walking5.c3d's plate 2 reads −24 N between steps), not a contact."""
    found = plate_file(path)
    markers = found.markers[:n_frames]
    plates = []
    for k, raw in enumerate(found.plates, start=1):
        corners = raw.corners.T * _LENGTH.get(raw.unit_position.strip(), 1e-3)
        normal = pressed(plate_normal(corners), raw.force.T)
        force, cop, free = _frames(raw, n_frames, normal)
        problem = plausibility(corners, force)
        if problem is None:
            problem = unloaded_under_a_foot(corners, force @ normal, markers,
                                            found.labels, found.rate)
        loaded = force @ normal >= threshold if problem is None else \
            np.zeros(n_frames, dtype=bool)
        centre = corners.mean(axis=0) if np.isfinite(corners).all() else np.zeros(3)
        force[~loaded] = 0.0
        free[~loaded] = 0.0
        cop[~loaded] = centre
        plates.append(ForcePlate(k, force, cop, free, corners, problem))
    return plates


def pressed(normal: np.ndarray, force: np.ndarray) -> np.ndarray:
    """The plate's normal turned the way its force pushes the subject (``force``: samples × 3,
    on the subject): the sign of its largest normal force, which a foot's push gives."""
    along = force @ normal
    if not np.isfinite(along).any():
        return normal
    peak = along[np.nanargmax(np.abs(along))]
    return normal if peak >= 0 else -normal


def plate_normal(corners: np.ndarray) -> np.ndarray:
    """The plate's unit normal (from its diagonals): the direction of the 'vertical' force; the
    global z for corners that make no plane (an implausible plate, refused by ``plausibility``)."""
    n = np.cross(corners[2] - corners[0], corners[3] - corners[1])
    length = np.linalg.norm(n)
    return n / length if np.isfinite(length) and length > 0 else np.array([0.0, 0.0, 1.0])

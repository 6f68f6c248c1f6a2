"""Force platforms from C3D (ezc3d's platform data): ground reaction force on the subject,
centre of pressure and free moment, in the global frame, SI, resampled to the point rate."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fccgrb_cli.errors import InputError

_LENGTH = {"mm": 1e-3, "m": 1.0, "cm": 1e-2}
_MOMENT = {"Nmm": 1e-3, "Nm": 1.0, "N.mm": 1e-3, "N.m": 1.0}


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


def _blocks(signal: np.ndarray, n_frames: int) -> np.ndarray:
    """Average analog samples (3 × samples) over each point frame → frames × 3."""
    samples = signal.shape[1]
    per = samples // n_frames if n_frames else 0
    if per < 1:
        raise InputError(f"force platform data has {samples} samples for {n_frames} frames")
    return np.nanmean(signal[:, : per * n_frames].reshape(3, n_frames, per), axis=2).T


def plausibility(corners: np.ndarray, force: np.ndarray) -> str | None:
    """What a force plate would have that these corners and forces lack ("expected …, got …"),
    or None when they look like a plate."""
    if not np.isfinite(corners).all() or np.abs(corners).max() > 50.0:
        return ("finite corners within 50 m of the origin, got coordinates up to "
                f"{np.nanmax(np.abs(corners)):.3g} m")
    sides = np.linalg.norm(np.roll(corners, -1, axis=0) - corners, axis=1)
    if sides.min() < 0.1 or sides.max() > 3.0:
        return f"sides of 0.1–3 m, got {', '.join(f'{s:.3g}' for s in sides)} m"
    skew = np.linalg.norm(corners[0] + corners[2] - corners[1] - corners[3])
    if skew > 0.05:
        return f"four corners forming a rectangle, got diagonals {skew:.3g} m apart at the middle"
    if not np.isfinite(force).all() or np.abs(force).max() > 2e4:
        return (f"finite forces below 20 kN, got {np.nanmax(np.abs(force)):.3g} N (the "
                "calibration looks wrong)")
    return None


def read_force_plates(path: str | Path, n_frames: int, threshold: float = 20.0
                      ) -> list[ForcePlate]:
    """Every plate of the file; frames whose force normal to the plate is below ``threshold`` N
    carry no load (the centre of pressure is then undefined and set to the plate centre)."""
    import ezc3d

    try:
        c3d = ezc3d.c3d(str(path), extract_forceplat_data=True)
    except Exception as exc:  # ezc3d raises plain RuntimeErrors for unreadable platform data
        reason = str(exc).strip() or exc.__class__.__name__
        raise InputError(f"{path}: cannot read the force platforms ({reason})") from None
    plates = []
    for k, raw in enumerate(c3d["data"].get("platform", []), start=1):
        length = _LENGTH.get(str(raw["unit_position"]).strip(), 1e-3)
        moment = _MOMENT.get(str(raw["unit_moment"]).strip().replace(" ", ""), 1e-3)
        corners = np.asarray(raw["corners"], dtype=float).T * length
        force = _blocks(np.asarray(raw["force"], dtype=float), n_frames)
        cop = _blocks(np.asarray(raw["center_of_pressure"], dtype=float), n_frames) * length
        free = _blocks(np.nan_to_num(np.asarray(raw["Tz"], dtype=float)), n_frames) * moment
        problem = plausibility(corners, force)
        loaded = np.abs(force @ _normal(corners)) >= threshold if problem is None else \
            np.zeros(n_frames, dtype=bool)
        centre = corners.mean(axis=0) if np.isfinite(corners).all() else np.zeros(3)
        force[~loaded] = 0.0
        free[~loaded] = 0.0
        cop[~loaded] = centre
        plates.append(ForcePlate(k, force, cop, free, corners, problem))
    return plates


def _normal(corners: np.ndarray) -> np.ndarray:
    """The plate's unit normal (from its diagonals): the direction of the 'vertical' force."""
    n = np.cross(corners[2] - corners[0], corners[3] - corners[1])
    return n / np.linalg.norm(n)

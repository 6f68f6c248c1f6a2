"""A trial's force platforms as the external loads of the inverse dynamics: each plate the
model assigns to a body, and every other plate's contacts given to the nearest contact body
(``dynamics.contact``)."""

from __future__ import annotations

import numpy as np

from fccgrb_cli.core.errors import InputError
from fccgrb_cli.dynamics.contact import MAX_DISTANCE, assign
from fccgrb_cli.dynamics.loads import ExternalLoad
from fccgrb_cli.model import Model
from fccgrb_cli.trial.record import Trial


def plate_loads(model: Model, trial: Trial, warnings: list[str],
                contact_points: dict[str, np.ndarray] | None = None,
                notes: list[str] | None = None) -> list[ExternalLoad]:
    """The trial's force platforms as external loads: those ``loads.force_plates`` assigns to a
    body, and every other plate's contacts to the nearest of ``loads.contact``'s bodies (whose
    point positions, frames × points × 3, are ``contact_points``)."""
    if not model.force_plates and not model.contact_bodies:
        return []
    if not trial.path.lower().endswith(".c3d"):
        if not model.force_plates:
            return []
        raise InputError(f"{model.source}: loads.force_plates: expected a C3D trial with force "
                         f"platforms, got {trial.path}")
    from fccgrb_cli.trial.c3d_header import read_parameters
    from fccgrb_cli.trial.forceplates import read_force_plates

    used = read_parameters(trial.path).get("FORCE_PLATFORM:USED")
    none = used is not None and used.values.size and not used.values[0]
    # FORCE_PLATFORM:USED 0: ezc3d would find no plate after loading every frame's points
    plates = {} if none else {p.number: p for p in read_force_plates(
        trial.path, trial.n_frames, model.plate_threshold)}
    loads = []
    for k, assignment in enumerate(model.force_plates):
        plate = plates.get(assignment.plate)
        key = f"loads.force_plates[{k}].plate"
        if plate is None:
            raise InputError(f"{model.source}: {key}: expected a plate of {trial.path} "
                             f"(it has {len(plates)}), got {assignment.plate}")
        if plate.problem is not None:
            raise InputError(f"{trial.path}: FORCE_PLATFORM plate {plate.number}: expected "
                             f"{plate.problem} (assigned by {model.source} {key})")
        if not np.abs(plate.force).any():
            warnings.append(f"{trial.path}: force plate {plate.number} carries no load above "
                            f"{model.plate_threshold:g} N in any frame")
        loads.append(ExternalLoad(f"plate{plate.number}", assignment.body, plate.force,
                                  plate.cop, plate.free_moment))
    assigned = {a.plate for a in model.force_plates}
    for number, plate in plates.items():
        if number in assigned or not model.contact_bodies:
            continue
        if plate.problem is not None:
            warnings.append(f"{trial.path}: FORCE_PLATFORM plate {number} ignored: expected "
                            f"{plate.problem}")
            continue
        loads.extend(_contact_loads(plate, contact_points or {}, trial.path, warnings,
                                    notes if notes is not None else []))
    return loads


def _contact_loads(plate, contact_points: dict[str, np.ndarray], path: str,
                   warnings: list[str], notes: list[str]) -> list[ExternalLoad]:
    """One plate's loads, each contact given to the nearest contact body."""
    loaded = np.abs(plate.force).any(axis=1)
    mask: dict[str, np.ndarray] = {}
    for c in assign(loaded, plate.cop, contact_points):
        if c.body is None:
            warnings.append(f"{path}: force plate {plate.number}, frame indices {c.start}:"
                            f"{c.stop}: no contact body within {1e3 * MAX_DISTANCE:.0f} mm of "
                            f"the centre of pressure (nearest {1e3 * c.distance:.0f} mm); load "
                            "ignored")
            continue
        notes.append(f"force plate {plate.number}, frame indices {c.start}:{c.stop} → {c.body} "
                     f"(centre of pressure {1e3 * c.distance:.0f} mm from its nearest point)")
        mask.setdefault(c.body, np.zeros(len(loaded), dtype=bool))[c.start:c.stop] = True
    out = []
    for body, frames in mask.items():
        keep = frames[:, None]
        name = f"plate{plate.number}" if len(mask) == 1 else f"plate{plate.number}_{body}"
        out.append(ExternalLoad(name, body, np.where(keep, plate.force, 0.0), plate.cop,
                                np.where(keep, plate.free_moment, 0.0)))
    return out

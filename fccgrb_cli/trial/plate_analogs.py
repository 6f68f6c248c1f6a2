"""Force platforms of types 1, 2 and 4 from a C3D file's analog channels, as ezc3d extracts them
(its ``ForcePlatforms`` module), in numpy over all samples at once.

ezc3d computes each platform's force, centre of pressure and free moment in C++, but its Python
binding then copies them out one sample at a time (four calls per sample): 110 ms of a 340-frame
gait trial's 155 ms read, a fifth of a study's trial. The same arithmetic here, per platform
(C3D specification; ``FORCE_PLATFORM`` parameters):

* the platform's axes from its corners c₀…c₃ (in the lab): x along c₀ − c₁, z = x × (c₀ − c₃),
  y = z × x, each made unit; R = [x y z];
* its origin o (the transducer's, from the surface's centre, in the platform's axes) with the
  sign that puts it below the surface (o_z ≤ 0), its x and y zero for type 1;
* type 2: the six channels are F and M in the platform's axes; type 4: the calibration matrix
  times the six channels; M about the surface's centre: M + F × o; then
  CoP = (−M_y/F_z, M_x/F_z, 0), the free moment T = M + F × CoP, and in the lab R F, R M,
  R CoP + the corners' mean, R T;
* type 1: the channels are F, CoP_x, CoP_y and T_z in the platform's axes: R F, R CoP + the
  corners' mean, R T, and M = (R F) × (R CoP) − R T.

Type 3 (Kistler, eight channels and a centre-of-pressure correction) and the others are left
to ezc3d (:func:`platforms` returns None), as is any file whose platform parameters are not
complete: ezc3d then says what is missing. ``tests/test_plate_analogs.py`` compares the two on
generated files of every type handled and on the shared C3D files.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["platforms"]

HANDLED = (1, 2, 4)


def platforms(c3d: Any) -> list[dict] | None:
    """Every used platform of an ezc3d object (read without ezc3d's extraction) as ezc3d's
    extraction gives it (``corners`` 3 × 4, ``origin``, ``force``, ``moment``,
    ``center_of_pressure``, ``Tz`` 3 × samples; the units ``unit_force``, ``unit_moment``,
    ``unit_position``), or None where some platform is not one this module computes."""
    parameters = c3d["parameters"]
    group = parameters.get("FORCE_PLATFORM", {})
    try:
        used = int(_flat(group["USED"])[0])
        types = _flat(group["TYPE"]).astype(int)
        corners = _flat(group["CORNERS"])
        origins = _flat(group["ORIGIN"])
        channel = np.asarray(group["CHANNEL"]["value"])
    except (KeyError, IndexError, ValueError, TypeError):
        return None
    if used < 0 or len(types) < used or len(corners) < 12 * used or len(origins) < 3 * used \
            or channel.ndim != 2 or channel.shape[1] < used or channel.shape[0] < 6:
        return None
    analogs = np.asarray(c3d["data"]["analogs"], dtype=float)
    if analogs.ndim != 3 or analogs.shape[0] != 1:
        return None
    analogs = analogs[0]
    units = _units(parameters)
    out = []
    for k in range(used):
        kind = int(types[k])
        indices = channel[:6, k].astype(int) - 1
        if kind not in HANDLED or (indices < 0).any() or (indices >= len(analogs)).any():
            return None
        calibration = _calibration(group, k) if kind == 4 else None
        if kind == 4 and calibration is None:
            return None
        at = corners[12 * k:12 * (k + 1)].reshape(4, 3).T  # 3 × 4, a corner a column
        origin = origins[3 * k:3 * (k + 1)].copy()
        if kind == 1:
            origin[:2] = 0.0
        if origin[2] > 0.0:
            origin = -origin
        out.append({**units, "corners": at, "origin": origin,
                    **_loads(kind, analogs[indices], calibration, origin, _axes(at),
                             at.mean(axis=1))})
    return out


def _flat(parameter: dict) -> np.ndarray:
    """A numeric parameter's values in the file's order (ezc3d shapes them column-major)."""
    return np.asarray(parameter["value"], dtype=float).ravel(order="F")


def _units(parameters: dict) -> dict[str, str]:
    """ezc3d's units: POINT:UNITS for positions (m when absent), FORCE_PLATFORM:UNITS for
    forces (N when absent), their concatenation for moments."""
    def first(group: str, default: str) -> str:
        value = parameters.get(group, {}).get("UNITS", {}).get("value")
        return str(value[0]) if value is not None and len(value) else default

    position, force = first("POINT", "m"), first("FORCE_PLATFORM", "N")
    return {"unit_force": force, "unit_moment": force + position, "unit_position": position}


def _calibration(group: dict, k: int) -> np.ndarray | None:
    """Platform k's 6 × 6 calibration matrix (the identity for an empty parameter, as
    ezc3d), or None where the parameter does not hold it."""
    if "CAL_MATRIX" not in group:
        return None
    value = np.asarray(group["CAL_MATRIX"]["value"], dtype=float)
    if value.ndim < 3 or value.shape[2] <= k:
        return None
    if value.size == 0:
        return np.eye(6)
    if value.shape[0] * value.shape[1] < 36:
        return None
    flat = value.ravel(order="F")
    skip = value.shape[0] * value.shape[1]
    return flat[skip * k:skip * k + 36].reshape(6, 6).T  # (i, j) = flat[j·6 + i]


def _axes(corners: np.ndarray) -> np.ndarray:
    """R = [x y z] of the platform from its corners (3 × 4)."""
    x = corners[:, 0] - corners[:, 1]
    y = corners[:, 0] - corners[:, 3]
    z = np.cross(x, y)
    y = np.cross(z, x)
    with np.errstate(divide="ignore", invalid="ignore"):  # coincident corners: NaN, as ezc3d
        return np.column_stack([v / np.linalg.norm(v) for v in (x, y, z)])


def _loads(kind: int, channels: np.ndarray, calibration: np.ndarray | None,
           origin: np.ndarray, R: np.ndarray, centre: np.ndarray) -> dict[str, np.ndarray]:
    """Force, moment, centre of pressure and free moment (3 × samples each, in the lab)."""
    if kind == 1:
        force = R @ channels[0:3]
        zero = np.zeros(channels.shape[1])
        cop = R @ np.vstack([channels[3], channels[4], zero])
        free = R @ np.vstack([zero, zero, channels[5]])
        moment = np.cross(force, cop, axis=0) - free
        return {"force": force, "moment": moment, "center_of_pressure": cop + centre[:, None],
                "Tz": free}
    data = calibration @ channels if calibration is not None else channels
    force_raw = data[0:3]
    moment_raw = data[3:6] + np.cross(force_raw, origin[:, None], axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):  # no load: ezc3d's inf and NaN too
        cop_raw = np.vstack([-moment_raw[1] / force_raw[2], moment_raw[0] / force_raw[2],
                             np.zeros(data.shape[1])])
        free = moment_raw + np.cross(force_raw, cop_raw, axis=0)
        return {"force": R @ force_raw, "moment": R @ moment_raw,
                "center_of_pressure": R @ cop_raw + centre[:, None], "Tz": R @ free}

"""C3D marker files through ezc3d: POINT:UNITS, POINT:RATE and POINT:LABELS honoured."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from fccgrb_cli.io.atomic import atomic_path

UNIT_SCALE = {"m": 1.0, "mm": 1e-3, "cm": 1e-2}


def write_markers(path: str | Path, labels: list[str], markers_m: np.ndarray, rate: float,
                  units: str = "mm", description: str = "") -> None:
    """Write markers (frames × markers × 3, metres) as C3D points in ``units`` at ``rate`` Hz."""
    import ezc3d

    if units not in UNIT_SCALE:
        raise ValueError(f"units must be one of {sorted(UNIT_SCALE)}, got {units!r}")
    c3d = ezc3d.c3d()
    c3d["parameters"]["POINT"]["RATE"]["value"] = [float(rate)]
    c3d["parameters"]["POINT"]["LABELS"]["value"] = list(labels)
    c3d["parameters"]["POINT"]["UNITS"]["value"] = [units]
    n_frames, n_markers, _ = markers_m.shape
    points = np.ones((4, n_markers, n_frames))
    points[:3] = np.transpose(markers_m / UNIT_SCALE[units], (2, 1, 0))
    c3d["data"]["points"] = points
    if description:
        c3d.add_parameter("FCCGRB", "SOURCE", [description])
    save(c3d, path)


def save(c3d, path: str | Path) -> None:
    """Write an ezc3d object to ``path`` atomically."""
    with atomic_path(path) as tmp:
        # ezc3d picks the format from the name: give the temporary file a .c3d ending
        staged = tmp.with_suffix(".c3d")
        try:
            c3d.write(str(staged))
            staged.replace(tmp)
        finally:
            if staged.exists():
                staged.unlink()

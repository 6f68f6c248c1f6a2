"""C3D marker files through ezc3d: POINT:UNITS, POINT:RATE and POINT:LABELS honoured.

A trial past 65,535 frames is written the way long files are written: ezc3d stores POINT:FRAMES
as a 16-bit word (-1, i.e. 65535, once the count overflows it) and the header's last frame as
65535, so the true count goes where readers look for it (C3D User Guide; Vicon Nexus and
C3Dserver write both): TRIAL:ACTUAL_START_FIELD and TRIAL:ACTUAL_END_FIELD, the first and last
frame as two 16-bit words each (low word first), and POINT:LONG_FRAMES, the count as a float.
ezc3d itself reads no more than 65,535 frames; ``trial.c3d_header`` reads the rest.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from fccgrb_cli.core import scratch
from fccgrb_cli.core.atomic import atomic_path, cannot_write
from fccgrb_cli.core.errors import InputError

UNIT_SCALE = {"m": 1.0, "mm": 1e-3, "cm": 1e-2}
# where `fccgrb perturb` records the soft-tissue-artefact level it added (mm): C3D, TRC header
ARTEFACT_PARAMETER = "FCCGRB:ARTEFACT_MM"
ARTEFACT_TRC_KEY = "FccgrbArtefactMM"
WORD = 0xFFFF


def write_markers(path: str | Path, labels: list[str], markers_m: np.ndarray, rate: float,
                  units: str = "mm", description: str = "", artefact_mm: float = 0.0) -> None:
    """Write markers (frames × markers × 3, metres; NaN: a gap) as C3D points in ``units`` at
    ``rate`` Hz; ``artefact_mm`` (the artefact level added to them, when not 0) is recorded as
    the parameter ``ARTEFACT_PARAMETER``."""
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
    if artefact_mm:
        c3d.add_parameter(*ARTEFACT_PARAMETER.split(":"), [float(artefact_mm)])
    long_frames(c3d, n_frames)
    save(c3d, path)


def long_frames(c3d, n_frames: int, first: int = 1) -> None:
    """Past 65,535 frames: the frame range in TRIAL:ACTUAL_START_FIELD/ACTUAL_END_FIELD and the
    count in POINT:LONG_FRAMES (see the module's docstring)."""
    if n_frames <= WORD:
        return
    last = first + n_frames - 1
    c3d.add_parameter("TRIAL", "ACTUAL_START_FIELD", [first & WORD, first >> 16])
    c3d.add_parameter("TRIAL", "ACTUAL_END_FIELD", [last & WORD, last >> 16])
    c3d.add_parameter("POINT", "LONG_FRAMES", [float(n_frames)])


def save(c3d, path: str | Path) -> None:
    """Write an ezc3d object to ``path`` atomically. ezc3d does not report a failed write (a
    full disk leaves a short file behind a normal return): the file written is measured against
    the layout its own header announces before it is renamed into place."""
    from fccgrb_cli.trial.c3d_header import read_layout

    with atomic_path(path) as tmp:
        # ezc3d picks the format from the name: give the temporary file a .c3d ending
        staged = tmp.with_name(tmp.name + ".c3d")
        scratch.register(staged)
        try:
            c3d.write(str(staged))
            try:
                layout = read_layout(staged)
            except InputError:
                layout = None
            if layout is None or layout.truncated:
                size = staged.stat().st_size if staged.exists() else 0
                raise cannot_write(path, _short(size))
            staged.replace(tmp)
        finally:
            if staged.exists():
                staged.unlink()
            scratch.release(staged)


def _short(size: int) -> OSError:
    """The error of a C3D ezc3d left short: a full disk or the file size limit (which one,
    ezc3d does not say; the disk's free space tells)."""
    return OSError(0, f"the file written stops at byte {size}: the disk is full or "
                                 "the file size limit was reached")

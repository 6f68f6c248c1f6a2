"""A subject's measurements from a C3D file's ``PROCESSING`` group, where Vicon Nexus writes the
subject parameters a trial was processed with (Plug-in Gait's ``Bodymass``, ``LLegLength``,
``RKneeWidth``, ``MarkerDiameter``, ``LThighRotation``, ...: lengths in mm, angles in rad).

The parameters are read from the file's own bytes (``c3d_header.read_parameters``: no point data
is loaded), so this is cheap enough to call per subject in a batch.
"""

from __future__ import annotations

from pathlib import Path

from fccgrb_cli.core.errors import InputError
from fccgrb_cli.model.subject import SubjectMeasurements, from_vicon
from fccgrb_cli.trial.c3d_header import read_layout, read_parameters

GROUP = "PROCESSING"


def processing_measurements(path: str | Path) -> SubjectMeasurements:
    """The subject measurements in the ``PROCESSING`` group of the C3D file at ``path`` (SI; a
    quantity the group lacks is None, and ``present`` lists the keys found). A file without the
    group gives empty measurements; a value that is not a number in its plausible range is an
    InputError naming the file and the parameter."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: C3D file not found")
    read_layout(path)  # an InputError for a file that is not a C3D
    params = read_parameters(path)
    values: dict[str, float] = {}
    for key, param in params.items():
        group, _, name = key.partition(":")
        if group != GROUP or param.kind == -1 or param.values.size == 0:
            continue
        values[name] = float(param.values.ravel()[0])

    def fail(key: str, expected: str, got: float) -> None:
        raise InputError(f"{path}: {GROUP}:{key}: expected {expected}, got {got:g}")

    return from_vicon(values, f"{path} {GROUP}", fail=fail)

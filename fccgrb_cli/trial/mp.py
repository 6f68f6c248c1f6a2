"""A subject's measurements from Vicon's older subject file (``.mp``, Workstation and early
Nexus): one ``$Name = value`` line per parameter (``$Bodymass = 74``, ``$LKneeWidth = 102``
or ``$LeftKneeWidth = 102``), lengths in mm, angles in rad, the mass in kg. Blank lines and
lines that are not ``$`` assignments (comments, headers) are skipped; a value that is not a
number is an InputError naming the file, the line and the parameter.
"""

from __future__ import annotations

from pathlib import Path

from fccgrb_cli.core.errors import InputError
from fccgrb_cli.model.subject import SubjectMeasurements, from_vicon

MAX_BYTES = 1 << 20  # a subject file is a few hundred bytes; anything past 1 MiB is not one


def mp_measurements(path: str | Path) -> SubjectMeasurements:
    """The measurements an ``.mp`` file at ``path`` holds (SI; the keys found in ``present``),
    the sides spelt ``L``/``R`` or ``Left``/``Right``.

    Parameters
    ----------
    path : str or Path
        The ``.mp`` file.

    Returns
    -------
    SubjectMeasurements
        Body mass (kg), lengths (m), angles (rad); None where the file has no value.
    """
    path = Path(path)
    try:
        with path.open("rb") as stream:
            raw = stream.read(MAX_BYTES + 1)
    except FileNotFoundError:
        raise InputError(f"{path}: subject file not found") from None
    except OSError as exc:
        raise InputError(f"{path}: not readable ({exc.strerror})") from None
    if len(raw) > MAX_BYTES:
        raise InputError(f"{path}: expected a Vicon .mp subject file (a few kB), got more than "
                         f"{MAX_BYTES >> 20} MiB")
    text = raw.decode("utf-8", errors="replace")
    values: dict[str, float] = {}
    for number, line in enumerate(text.splitlines(), start=1):
        line = line.strip()
        if not line.startswith("$") or "=" not in line:
            continue
        name, _, written = (part.strip() for part in line[1:].partition("="))
        try:
            values[name] = float(written)
        except ValueError:
            raise InputError(f"{path}: line {number}: ${name}: expected a number, got "
                             f"{written!r}") from None

    def fail(key: str, expected: str, got: float) -> None:
        raise InputError(f"{path}: ${key}: expected {expected}, got {got:g}")

    short = from_vicon(values, str(path), fail)
    long = from_vicon(values, str(path), fail, prefixes=("Left", "Right"))
    return long.merged_over(short)

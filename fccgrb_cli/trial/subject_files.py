"""A subject's measurements from a file, chosen by its ending: a Vicon ``.vsk`` or ``.mp``, a C3D's
``PROCESSING`` group, or YAML holding a ``subject:`` section as a model file writes it (lengths
in m, angles in degrees unless ``units: {angle: rad}``)."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path
from typing import Any

import yaml

from fccgrb_cli.core.errors import InputError
from fccgrb_cli.model.subject import SubjectMeasurements, from_flags, from_yaml, yaml_keys
from fccgrb_cli.trial.mp import mp_measurements
from fccgrb_cli.trial.processing import processing_measurements
from fccgrb_cli.trial.vsk import vsk_measurements

ENDINGS = (".vsk", ".mp", ".c3d", ".yaml", ".yml")


def read_measurements(path: str | Path) -> SubjectMeasurements:
    """The measurements in the file at ``path`` (SI), by its ending (``ENDINGS``)."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".vsk":
        return vsk_measurements(path)
    if suffix == ".mp":
        return mp_measurements(path)
    if suffix == ".c3d":
        return processing_measurements(path)
    if suffix not in (".yaml", ".yml"):
        raise InputError(f"{path}: expected a subject file ending in {', '.join(ENDINGS)}")
    try:
        doc = yaml.safe_load(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError(f"{path}: subject file not found") from None
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as exc:
        raise InputError(f"{path}: not a readable YAML file ({exc.__class__.__name__})") \
            from None
    if not isinstance(doc, dict):
        raise InputError(f"{path}: expected a mapping with a subject: section")
    angle = (doc.get("units") or {}).get("angle", "deg") if isinstance(doc.get("units"), dict) \
        else "deg"
    if angle not in ("deg", "rad"):
        raise InputError(f"{path}: units.angle: expected 'deg' or 'rad', got {angle!r}")
    spec = doc.get("subject", doc)
    if not isinstance(spec, dict):
        raise InputError(f"{path}: subject: expected a mapping, got {spec!r}")
    spec = {k: v for k, v in spec.items() if k != "units"}
    unknown = sorted(str(k) for k in spec if k not in yaml_keys())
    if unknown:
        raise InputError(f"{path}: subject: expected only the keys {', '.join(sorted(yaml_keys()))}"
                         f"; got {', '.join(unknown)}")

    def fail(key: str, expected: str, got: Any) -> None:
        raise InputError(f"{path}: {key}: expected {expected}, got {got!r}")

    found = from_yaml(spec, math.pi / 180.0 if angle == "deg" else 1.0, fail)
    return replace(found, source=f"{path} subject")


def gathered(template: SubjectMeasurements, trial: str, files: tuple[str, ...],
             typed: dict[str, str | None]) -> SubjectMeasurements:
    """A Plug-in Gait calibration's measurements, each source over the ones before it: the
    static ``trial``'s PROCESSING group (a C3D), the template's subject section, the
    ``files`` (:func:`read_measurements`) in order, the ``typed`` values (field → text in mm /
    kg, ``left,right`` for a side each: ``model.subject.from_flags``)."""
    measured = template
    if trial.lower().endswith(".c3d"):
        measured = measured.merged_over(processing_measurements(trial))
    for path in files:
        measured = read_measurements(path).merged_over(measured)
    if any(v is not None for v in typed.values()):
        measured = from_flags(typed).merged_over(measured)
    return measured

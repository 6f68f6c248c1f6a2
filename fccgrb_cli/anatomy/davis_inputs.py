"""What a template without Plug-in Gait's own calibration (the lower-limb, Helen Hayes and
full-body templates) takes from the subject's measurements, read from the same sources and
in the same order as a Plug-in Gait template's (``trial.subject_files.gathered``: the static's
``PROCESSING`` group, the template's ``subject:`` section, ``--subject`` files, the typed
values): the body mass for every template, and for the Helen Hayes/Davis set the knee width,
the ankle width and the markers' diameter.

These templates take one width for both sides: where the sources give a width per side, the
mean of the sides given is used, and said when the sides differ. A width or diameter no
source gives is the :class:`~fccgrb_cli.anatomy.calibrate.Measurements` default, said too.
"""

from __future__ import annotations

from dataclasses import dataclass

from fccgrb_cli.anatomy.calibrate import DAVIS_LANDMARKS, LANDMARKS, Measurements
from fccgrb_cli.core.errors import InputError
from fccgrb_cli.model import Model
from fccgrb_cli.model.subject import Sided, SubjectMeasurements
from fccgrb_cli.trial.subject_files import gathered

SIDE_TOLERANCE = 0.0005  # m: sides further apart than this are said to differ


@dataclass(frozen=True)
class DavisInputs:
    """The body mass (kg, None when no source gives it), Davis' measurements (None for a
    template whose landmarks give the joint centres), and what to tell the user (defaults
    used, sides averaged, values read in another unit than written)."""

    mass: float | None
    measurements: Measurements | None
    warnings: tuple[str, ...]


def _one_width(value: Sided, vicon: str, warnings: list[str]) -> float | None:
    given = [v for v in (value.left, value.right) if v is not None]
    if not given:
        return None
    if value.left is not None and value.right is not None \
            and max(given) - min(given) > SIDE_TOLERANCE:  # both given, and they differ
        warnings.append(f"L{vicon} {1e3 * value.left:g} mm and R{vicon} {1e3 * value.right:g} "
                        f"mm: this template takes one width, their mean "
                        f"{1e3 * sum(given) / len(given):g} mm")
    return sum(given) / len(given)


def davis_inputs(measured: SubjectMeasurements, davis: bool) -> DavisInputs:
    """The mass and (for the Helen Hayes/Davis set, ``davis``) the measurements a template
    takes from ``measured``.

    Parameters
    ----------
    measured : SubjectMeasurements
        Every source merged, later over earlier (SI).
    davis : bool
        Whether the template builds its knee and ankle centres by Davis et al.'s chord.

    Returns
    -------
    DavisInputs
        Body mass (kg), widths and marker diameter (m), and the warnings to print.
    """
    warnings = list(measured.notes)
    if not davis:
        return DavisInputs(measured.body_mass, None, tuple(warnings))
    defaults = Measurements()
    values = {"knee_width": _one_width(measured.knee_width, "KneeWidth", warnings),
              "ankle_width": _one_width(measured.ankle_width, "AnkleWidth", warnings),
              "marker_diameter": measured.marker_diameter}
    absent = [name for name, value in values.items() if value is None]
    if absent:
        warnings.append("no " + ", ".join(f"--{name.replace('_', '-')}" for name in absent)
                        + f" (nor in {measured.source or 'any subject file'}): " + ", ".join(
                            f"{1e3 * getattr(defaults, name):g} mm" for name in absent)
                        + " used (an average adult's; give the subject's, measured)")
    chosen = {name: value for name, value in values.items() if value is not None}
    return DavisInputs(measured.body_mass, Measurements(**chosen), tuple(warnings))


def template_inputs(template: Model, trial: str, subject_files: tuple[str, ...],
                    typed: dict[str, str | None]) -> DavisInputs:
    """:func:`davis_inputs` for ``template`` from every source in order (the static ``trial``'s
    PROCESSING group when it is a C3D, the template's subject section, ``subject_files``, the
    ``typed`` values: field → text in mm / kg); widths typed for a template whose landmarks
    give the joint centres are an InputError naming the options."""

    def maps(names: tuple[str, ...]) -> bool:
        return all(name in template.landmarks for name in names)

    davis = maps(DAVIS_LANDMARKS) and not maps(LANDMARKS)
    widths = [f"--{k.replace('_', '-')}" for k, v in typed.items()
              if v is not None and k != "body_mass"]
    if widths and not davis:
        raise InputError(f"{', '.join(widths)}: expected only with a template of the Helen "
                         f"Hayes/Davis set (wands, lateral markers); {template.source} maps "
                         "medial epicondyles and malleoli, whose midpoints are the joint "
                         "centres")
    return davis_inputs(gathered(template.measurements, trial, subject_files, typed), davis)

"""A subject's calibration, one way for every caller: ``fccgrb calibrate``, the Python API's
``calibrate`` and a study's calibration jobs all call :func:`calibrate_subject`, so the same
template, static trial and measurements give the same personal model, whichever asked.

The template decides the method: a Plug-in Gait template (``calibration.method: plugin-gait``)
is personalized as Plug-in Gait does (``plugin_gait.calibration``), every other one — lower
limb, Helen Hayes, full body, upper limb — by ``anatomy.full_body.personalize`` (the lower
limb's ISB frames and joint centres, the upper body's where the template has one, the lab's
vertical). The subject's measurements come from the same sources in the same order for every
template (``trial.subject_files.gathered``): the static C3D's ``PROCESSING`` group, the
template's ``subject:`` section, subject files (``.vsk``, ``.mp``, C3D, YAML), then the values
typed, each over the ones before."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from fccgrb_cli.core.errors import InputError
from fccgrb_cli.model import Model, parse_model
from fccgrb_cli.system.structure import analyse
from fccgrb_cli.trial.record import Trial
from fccgrb_cli.trial.virtual import resolved

__all__ = ["Calibrated", "Choices", "Subject", "calibrate_subject"]


@dataclass(frozen=True)
class Subject:
    """The subject's measurements as a user gives them: ``mass`` (kg); ``knee_width``,
    ``ankle_width``, ``marker_diameter`` as text in mm (one number, or 'left,right' for a
    Plug-in Gait template); ``files``: subject files read after the static's PROCESSING group.
    None: read from those sources, else defaulted (with a warning)."""

    mass: float | None = None
    knee_width: str | None = None
    ankle_width: str | None = None
    marker_diameter: str | None = None
    files: tuple[str, ...] = ()

    @classmethod
    def from_mm(cls, mass: float | None = None, knee_width: float | None = None,
                ankle_width: float | None = None, marker_diameter: float | None = None,
                files: tuple[str, ...] = ()) -> Subject:
        """From numbers (mm; kg), as the API and a study's measurements give them."""
        def text(value: float | None) -> str | None:
            return None if value is None else f"{value:.17g}"

        return cls(mass, text(knee_width), text(ankle_width), text(marker_diameter), files)

    def typed(self) -> dict[str, str | None]:
        """Field → text (mm; kg), as ``trial.subject_files.gathered`` takes the typed values."""
        return {"knee_width": self.knee_width, "ankle_width": self.ankle_width,
                "marker_diameter": self.marker_diameter,
                "body_mass": None if self.mass is None else f"{self.mass:.17g}"}


@dataclass(frozen=True)
class Choices:
    """How to calibrate: frame indices [A, B) of the static (None: every frame), Plug-in Gait's
    foot-flat option (None: as the subject's recorded static offsets say, else flat;
    ``plugin_gait.calibration.Options``), the template's labels → the trial's (a virtual
    marker ``mid(A,B)`` allowed), the lab's vertical ('auto' or an axis such as '+z')."""

    frames: tuple[int, int] | None = None
    foot_flat: bool | None = None
    mapping: dict[str, str] = field(default_factory=dict)
    vertical: str = "auto"


@dataclass(frozen=True)
class Calibrated:
    """A calibration's outcome: the personal model's YAML ``text`` and ``model`` (parsed and
    its structure checked), the static's frame indices used, what to tell the user on stdout
    (``report``), the warnings (``warnings``: defaults standing for measurements, implausible
    geometry, the trial's own) and notes (``notes``: the lab's vertical as found)."""

    text: str
    model: Model
    frames: tuple[int, int]
    report: tuple[str, ...]
    warnings: tuple[str, ...]
    notes: tuple[str, ...] = ()


def calibrate_subject(template: Model, trial: Trial, subject: Subject = Subject(),
                      choices: Choices = Choices(), source: str | None = None) -> Calibrated:
    """Personalize ``template`` from the static ``trial`` and the ``subject``'s measurements.

    Parameters
    ----------
    template : Model
        A template with a ``calibration`` section.
    trial : Trial
        The static trial (or a walking trial, its frames averaged).
    subject : Subject
        The measurements typed or given (mm, kg) and subject files.
    choices : Choices
        Frames, foot flat, label map, vertical.
    source : str, optional
        What names the personal model in messages (default: the template calibrated on the
        trial).

    Returns
    -------
    Calibrated
        The personal model (m, kg, s) and what to tell the user.

    Raises
    ------
    InputError
        A landmark missing, a measurement out of range or given to a template that takes none,
        a subject file unreadable (one line naming it).
    """
    source = source or f"{template.source} calibrated on {trial.path}"
    trial, labels = resolved(template, trial, dict(choices.mapping),
                             {*template.marker_labels, *template.landmarks.values()})
    if template.calibration_method == "plugin-gait":
        text, frames, report, warnings = _plugin_gait(template, trial, subject, choices, labels)
        notes: tuple[str, ...] = ()
    else:
        text, frames, report, warnings, notes = _anatomical(template, trial, subject, choices,
                                                            labels, source)
    model = parse_model(text, source)
    analyse(model)
    return Calibrated(text, model, frames, report, (*trial.warnings, *warnings), notes)


def _plugin_gait(template: Model, trial: Trial, subject: Subject, choices: Choices,
                 labels: dict[str, str]) -> tuple:
    from fccgrb_cli.plugin_gait.calibration import Options, calibrate_plugin_gait
    from fccgrb_cli.trial.subject_files import gathered

    measured = gathered(template.measurements, trial.path, subject.files, subject.typed())
    result = calibrate_plugin_gait(template, trial, measured,
                                   Options(choices.frames, choices.foot_flat), labels)
    m = result.measurements
    flexion, rotation = m.static_plantar_flexion, m.static_rotation_offset
    assert flexion.left is not None and flexion.right is not None  # the calibration sets them
    assert rotation.left is not None and rotation.right is not None
    report = [f"measurements from {m.source or 'nowhere'}",
              *(f"  {note}" for note in result.notes),
              "segment lengths (mm): " + ", ".join(
                  f"{k} {1e3 * v:.0f}" for k, v in result.lengths.items()),
              "static foot offsets (deg): plantarflexion L/R "
              f"{np.degrees(flexion.left):.2f} / "
              f"{np.degrees(flexion.right):.2f}, rotation L/R "
              f"{np.degrees(rotation.left):.2f} / "
              f"{np.degrees(rotation.right):.2f}"
              f" ({'foot flat' if result.foot_flat else 'foot not flat'})"]
    warnings = list(result.warnings)
    if m.body_mass is None:
        warnings.append("no body mass (Bodymass or --mass): the model has no inertia (inverse "
                        "dynamics skipped)")
    return result.text, result.frames, tuple(report), tuple(warnings)


def _anatomical(template: Model, trial: Trial, subject: Subject, choices: Choices,
                labels: dict[str, str], source: str) -> tuple:
    from fccgrb_cli.anatomy.davis_inputs import template_inputs
    from fccgrb_cli.anatomy.full_body import personalize

    inputs = template_inputs(template, trial.path, subject.files, subject.typed())
    _template_labels(template, labels)
    result = personalize(template, trial, choices.frames, inputs.mass, inputs.measurements,
                         labels, choices.vertical)
    report = [f"pelvis width {1e3 * result.pelvis_width:.0f} mm, depth "
              f"{1e3 * result.pelvis_depth:.0f} mm; segment lengths (mm): " + ", ".join(
                  f"{k} {1e3 * v:.0f}" for k, v in result.lengths.items())]
    if result.measurements is not None:
        report.append(f"knee and ankle centres by Davis et al. (1991): "
                      f"{result.measurements.describe()}")
    warnings = [*(result.axes.warnings if result.axes is not None else ()), *inputs.warnings]
    if inputs.mass is None:
        warnings.append("no --mass (nor Bodymass in the static's PROCESSING or a subject "
                        "file): the model has no inertia (inverse dynamics skipped)")
    warnings += [f"{source}: implausible calibration: {w}; every frame solved with this model "
                 "is flagged" for w in result.warnings]
    notes = (result.axes.note(),) if result.axes is not None else ()
    return result.text, result.frames, tuple(report), tuple(warnings), notes


def _template_labels(template: Model, mapping: dict[str, str]) -> None:
    """``--map``: every name is a label the template uses (a marker or a landmark), and no two
    of its labels end on one trial label."""
    from fccgrb_cli.trial.labels import one_label_each

    known = dict.fromkeys([*template.marker_labels, *template.landmarks.values()])
    unknown = [name for name in mapping if name not in known]
    if unknown:
        raise InputError(f"--map: expected labels the template {template.source} uses (its "
                         f"markers and calibration.landmarks), got {', '.join(unknown)}")
    one_label_each({name: mapping.get(name, name) for name in known}, "template label")

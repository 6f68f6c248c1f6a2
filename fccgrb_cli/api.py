"""The Python API: a model, a trial, options in, a Run out, as the command line does it.

    >>> import fccgrb_cli as fc
    >>> model = fc.load_model("configs/models/five_bar.yaml")
    >>> trial = fc.read_trial("sample_data/five_bar.c3d")
    >>> run = fc.solve(model, trial, method="cno-sqp", perturb_mm=30)
    >>> run.angles["J3_w"]          # rad, one value per frame
    >>> fc.write_results(run, "results.h5")
    >>> fc.read_results("results.h5")[run.name].summary()

Like scipy.optimize's ``minimize`` there is one call and one result type (:class:`Run`), and
like Pinocchio the model is immutable and the algorithms are functions over it. Every option
of :func:`solve` is a field of :class:`SolveOptions`, documented there with its unit.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from fccgrb_cli.core.errors import InputError
from fccgrb_cli.model import Model
from fccgrb_cli.pipeline.options import SolveOptions, describe
from fccgrb_cli.pipeline.run import Run
from fccgrb_cli.trial.record import Trial


def load_model(source: str | Path | Mapping[str, Any]) -> Model:
    """A validated, immutable model from a YAML file's path, or from the mapping such a file
    holds (``yaml.safe_load`` of one; the README's "The model file" documents the keys).
    The structure is checked too: the joints must leave as many degrees of freedom as there
    are angles and distances (plus 6 per floating base; docs/formulation.md §2).

    Parameters
    ----------
    source : str, Path or Mapping
        A model file (``.yaml``), or the mapping such a file holds. Lengths in metres; angles
        in the file's ``units.angle`` (deg or rad).

    Returns
    -------
    Model
        The model: bodies, joints, angles and distances, tracked points, inertia and gravity
        (m/s²), frozen.

    Raises
    ------
    InputError
        The file cannot be read, a key is missing or malformed (the message names the file and
        the key), or the joints leave the coordinates undetermined.
    """
    import yaml

    from fccgrb_cli.model import load_model as load_file
    from fccgrb_cli.model import parse_model
    from fccgrb_cli.system.structure import analyse

    if isinstance(source, Mapping):
        model = parse_model(yaml.safe_dump(dict(source), sort_keys=False), "<model mapping>")
    else:
        model = load_file(source)
    analyse(model)
    return model


def read_trial(path: str | Path, *, accept_truncated: bool = False) -> Trial:
    """A marker trial from a C3D or TRC file (lengths converted to metres from its units).
    A file whose data end before its header's last frame is an error unless
    ``accept_truncated`` (then the trial carries a warning).

    Parameters
    ----------
    path : str or Path
        A ``.c3d`` or ``.trc`` file. A synthesized trial's truth file (``<stem>.truth.h5``,
        written by ``fccgrb synth``) beside it is read by :func:`solve`.
    accept_truncated : bool, optional
        Read the frames a truncated file holds instead of refusing it (default False).

    Returns
    -------
    Trial
        ``labels`` (n_markers), ``markers`` (n_frames × n_markers × 3, m, NaN in gaps),
        ``rate`` (Hz), ``n_frames``, ``start`` (s, the first frame's time on the file's clock),
        ``warnings``; a C3D's force plates and events are read from its file by :func:`solve`.

    Raises
    ------
    InputError
        The file is missing, unreadable, or inconsistent (the message names the file and the
        parameter or line).
    """
    from fccgrb_cli.trial.record import read_trial as read

    return read(str(path), accept_truncated)


def solve(model: Model, trial: Trial, options: SolveOptions | None = None,
          **changes: Any) -> Run:
    """Solve ``trial`` with ``model``: the kinematics by the chosen method, each frame's quality
    checks, then (when the model has inertia) the inverse dynamics. ``options`` (default
    :class:`SolveOptions`) with any field replaced by a keyword, e.g.
    ``solve(model, trial, method="cno-sqp", perturb_mm=30)``.

    Parameters
    ----------
    model : Model
        From :func:`load_model` or :func:`calibrate`.
    trial : Trial
        From :func:`read_trial`; its markers must include the model's tracked markers (by
        label, or through the ``mapping`` option).
    options : SolveOptions, optional
        Every option of the solve (default ``SolveOptions()``: NRM-WLS, no artefact).
    **changes
        Fields of :class:`SolveOptions` to replace, by name (listed below).

    Other Parameters
    ----------------
    {options}

    Returns
    -------
    Run
        The solved trial: ``angles`` (n_frames × n_angles, rad; m for distances), ``q``,
        ``qd``, ``qdd`` (n_frames × nq), ``moments`` (n_frames × n_angles, N·m; N for
        distances; None without dynamics), each frame's ``trusted`` flag, the clinical curves
        of a gait model (deg, N·m/kg) and ``summary()``.

    Raises
    ------
    InputError
        An unknown option or a value out of its range, markers the model needs missing from
        the trial, or a model and trial that cannot be solved (one line naming what).

    """
    from fccgrb_cli.pipeline.solve import solve_trial

    chosen = options or SolveOptions()
    if changes:
        known = {name for name in SolveOptions.__dataclass_fields__}
        unknown = sorted(set(changes) - known)
        if unknown:
            raise InputError(f"{unknown[0]}: expected one of {', '.join(sorted(known))}")
        chosen = SolveOptions.from_mapping({**_as_mapping(chosen), **changes}, "solve")
    return solve_trial(model, trial, chosen)


def _as_mapping(options: SolveOptions) -> dict[str, Any]:
    return {name: getattr(options, name) for name in SolveOptions.__dataclass_fields__}


def calibrate(template: Model, trial: Trial, *, mass: float | None = None,
              frames: tuple[int, int] | None = None, knee_width: float | None = None,
              ankle_width: float | None = None, marker_diameter: float | None = None,
              mapping: dict[str, str] | None = None) -> Model:
    """A lower-limb ``template`` personalized from a static trial or a stretch of a walking
    trial (frame indices [A, B), default all), as ``fccgrb calibrate`` does: segment frames,
    joint centres, marker positions and, with the subject's ``mass`` (kg), de Leva inertia.
    A Helen Hayes/Davis template (``configs/models/helen_hayes.yaml``) takes the subject's
    ``knee_width``, ``ankle_width`` and ``marker_diameter`` in mm (defaults 100, 70, 14: give
    the measured ones); ``mapping``: the template's label → the trial's (a virtual marker
    ``mid(A,B)`` allowed). A Plug-in Gait template (``configs/models/plugin_gait.yaml``) takes
    the subject's measurements from the trial's PROCESSING group and the template's subject
    section, the keywords (mm, kg) over both, with Plug-in Gait's foot-flat option where the
    recorded static offsets do not say otherwise (``plugin_gait.calibration.Options``;
    ``plugin_gait.calibration.calibrate_plugin_gait`` takes the other choices); any other
    template reads its mass (and a Helen Hayes one its widths) from the same sources in the
    same order (``anatomy.davis_inputs``). The personal
    model's gravity points down the trial's vertical, found from its plates and markers
    (``fccgrb_cli.anatomy.lab_axes``); where nothing in the trial tells, the template's own gravity
    stays, so a template loaded with the lab's gravity states it.

    Parameters
    ----------
    template : Model
        A template with a ``calibration`` section (``configs/models/lower_limb.yaml``,
        ``helen_hayes.yaml``, ``plugin_gait.yaml``, the full-body ones).
    trial : Trial
        A static trial, or a walking trial whose frames are averaged.
    mass : float, optional
        The subject's body mass (kg); without it the personal model has no inertia (a
        Plug-in Gait template takes it from the trial's PROCESSING group).
    frames : tuple of int, optional
        Frame indices [A, B) to calibrate on (default: every frame).
    knee_width, ankle_width, marker_diameter : float, optional
        The subject's measurements (mm), for Helen Hayes and Plug-in Gait templates.
    mapping : dict of str to str, optional
        The template's marker label → the trial's label.

    Plug-in Gait's foot-flat option, subject files and a stated vertical are
    ``pipeline.calibration.calibrate_subject``'s (``Subject``, ``Choices``), which this calls
    with their defaults, as ``fccgrb calibrate`` does.

    Returns
    -------
    Model
        The personal model: segment frames, joint centres and marker positions (m) from the
        trial, de Leva inertia with ``mass``, gravity (m/s²) along the trial's vertical.

    Raises
    ------
    InputError
        A landmark missing from the trial, implausible measurements, or a template without a
        calibration section (one line naming it).
    """
    from fccgrb_cli.pipeline.calibration import Choices, Subject, calibrate_subject

    subject = Subject.from_mm(mass, knee_width, ankle_width, marker_diameter)
    return calibrate_subject(template, trial, subject, Choices(frames, mapping=dict(mapping or {}))
                             ).model


def write_results(run: Run, path: str | Path, *, replace: bool = False) -> None:
    """Add ``run`` to the results file ``path`` (created when absent), atomically: the file
    ``fccgrb solve -o`` writes, which :func:`read_results` and every command read back.

    Parameters
    ----------
    run : Run
        From :func:`solve` (or :func:`read_results`).
    path : str or Path
        The results file (HDF5; layout in ``fccgrb_cli/results/storage.py``); its other runs
        are kept.
    replace : bool, optional
        Replace a run of the same name already in the file (default False: such a run is
        refused, as ``fccgrb solve`` refuses it without ``--replace``).

    Raises
    ------
    InputError
        The path is not a results file of this format, the run's name is not a valid run name,
        or a run of that name is there and ``replace`` is False; the file is then left as it
        was.
    """
    from fccgrb_cli.results.storage import write_runs

    write_runs(path, [run], "fccgrb_cli.write_results (Python API)", replace=replace)


def read_results(path: str | Path) -> dict[str, Run]:
    """Every run of a results file written by ``fccgrb solve`` or :func:`write_results`, by
    name, as the same Run objects :func:`solve` returns (arrays, options, warnings, dynamics).

    Parameters
    ----------
    path : str or Path
        A results file of format ``RESULTS_FORMAT``.

    Returns
    -------
    dict of str to Run
        Every run in the file, by its name, with the arrays bit for bit as written.

    Raises
    ------
    InputError
        The file is missing, not a results file, of another format version, or damaged (the
        message names the file, the run and what is missing).
    """
    from fccgrb_cli.results.runs import read_runs

    return read_runs(path)


solve.__doc__ = (solve.__doc__ or "").replace(
    "{options}", describe().replace("\n", "\n    "))

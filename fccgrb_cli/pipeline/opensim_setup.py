"""An OpenSim setup file run as OpenSim's tool runs it (``fccgrb solve --opensim-setup
SETUP.xml``): what the setup names becomes the solve's inputs and options.

An IK setup gives the model, the marker file (the trial), the task set's marker weights, the
time range and its ``accuracy`` (OpenSim: the solution's absolute accuracy), which becomes the
solve's tolerance on ‖Δq‖∞ (``--tol``, m and rad); an ID setup the model, the coordinates
file, the external loads, the coordinates' low-pass cutoff, ``coordinates_in_degrees`` (where
the file's header is silent) and the time range. What the command line states beside the setup
wins (a MODEL or TRIAL argument, ``--coordinates``, ``--loads``, ``--tasks``,
``--filter-cutoff``, ``--from``, ``--to``, ``--tol``); the setup fills the rest. Outputs stay
fccgrb's (``-o`` results file); the file the setup names for its output is said with the
export command that writes it."""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from fccgrb_cli.core.errors import InputError
from fccgrb_cli.opensim.setups import IDSetup, read_setup
from fccgrb_cli.pipeline.options import SolveOptions

__all__ = ["SetupInputs", "setup_inputs"]


@dataclass(frozen=True)
class SetupInputs:
    """The solve's inputs after the setup: the model, the trials or the coordinates file, the
    options, the coordinates' units when the setup states them, and notes to show."""

    model: str
    trials: tuple[str, ...]
    coordinates: str | None
    options: SolveOptions
    in_degrees: bool | None
    notes: tuple[str, ...]


def setup_inputs(path: str, model: str | None, trials: tuple[str, ...],
                 coordinates: str | None, options: SolveOptions,
                 typed: frozenset[str] = frozenset()) -> SetupInputs:
    """The setup ``path`` merged under what the command line gave (module docstring);
    ``typed``: the options typed on the command line (SolveOptions' field names), for those
    whose default cannot be told from a typed value."""
    setup = read_setup(path)
    chosen_model = model or _named(setup.model_file, path, "model_file")
    window: dict[str, Any] = {}  # SolveOptions fields
    if setup.time_range is not None:
        if options.time_from is None:
            window["time_from"] = setup.time_range[0]
        if options.time_to is None:
            window["time_to"] = setup.time_range[1]
    notes = []
    if isinstance(setup, IDSetup):
        given = coordinates or _named(setup.coordinates_file, path, "coordinates_file")
        extra: dict[str, Any] = dict(window)
        if options.loads is None and setup.external_loads_file is not None:
            extra["loads"] = str(setup.external_loads_file)
        if options.filter_cutoff is None and setup.lowpass_cutoff is not None:
            extra["filter_cutoff"] = setup.lowpass_cutoff
        if setup.forces_to_exclude:
            notes.append(f"{path}: forces_to_exclude {' '.join(setup.forces_to_exclude)}: "
                         "fccgrb applies none of a model's own forces (its ForceSet is left "
                         "out whatever the setup says)")
        if trials:
            raise InputError(f"--opensim-setup {path}: an inverse dynamics setup reads "
                             f"coordinates, not markers; got the trial {trials[0]}")
        out = setup.output_gen_force_file
        if out is not None:  # OpenSim adds the extension when the name has none
            out = out if out.suffix else out.with_suffix(".sto")
            notes.append(f"{path}: output_gen_force_file: write it with fccgrb export "
                         f"RESULTS.h5 --format sto -o {out}")
        return SetupInputs(chosen_model, (), given, replace(options, **extra),
                           setup.coordinates_in_degrees, tuple(notes))
    extra = dict(window)
    if not options.tasks and setup.tasks.markers:
        extra["tasks"] = tuple(setup.tasks.marker_weights().items())
    holds, said = setup.tasks.holds()
    if not options.hold and holds:
        extra["hold"] = holds
    notes += said
    if "tol" not in typed and setup.accuracy is not None:
        extra["tol"] = setup.accuracy
    if setup.output_motion_file is not None:
        notes.append(f"{path}: output_motion_file: write it with fccgrb export RESULTS.h5 "
                     f"--format mot -o {setup.output_motion_file}")
    if coordinates is not None:
        raise InputError(f"--opensim-setup {path}: an inverse kinematics setup reads "
                         f"markers; got --coordinates {coordinates}")
    chosen_trials = trials or (_named(setup.marker_file, path, "marker_file"),)
    return SetupInputs(chosen_model, chosen_trials, None, replace(options, **extra), None,
                       tuple(notes))


def _named(file: Path | None, setup: str, tag: str) -> str:
    if file is None:
        raise InputError(f"{setup}: {tag}: expected the file the tool reads (or give it on the "
                         "command line), got none")
    return str(file)

"""The inverse dynamics alone, from a coordinates file, as OpenSim's inverse dynamics tool runs
it (``fccgrb solve MODEL.osim --coordinates IK.mot [--loads LOADS.xml] [--filter-cutoff 6]``).

The file's columns are the model's coordinates by name (OpenSim's IK output, or fccgrb's own
``export --format mot``); a coordinate the file lacks keeps its default value, as the tool
does, and columns the model does not have are left out; both are said. Rotations are in degrees
when the header says ``inDegrees=yes`` or says nothing (OpenSim's IK writes degrees and its tool
assumes them), in radians when it says ``no``. The coordinates are low-passed as the tool does
(``signals.opensim_lowpass``) when a cutoff is given, differentiated through a quintic spline
(``dynamics.moving.coordinate_rates``), and the loads of an ExternalLoads file are applied at
the coordinates' times unfiltered, as the tool applies them. Every frame is the coordinates'
own: none is solved, so none fails; the run's kinematics are the coordinates and the bodies'
poses they give (docs/opensim.md)."""

from __future__ import annotations

import time as time_module

import numpy as np

from fccgrb_cli.core.errors import InputError
from fccgrb_cli.core.stretches import window
from fccgrb_cli.dynamics.convert import Dynamics
from fccgrb_cli.dynamics.moving import coordinate_inverse, coordinate_rates
from fccgrb_cli.model import Model
from fccgrb_cli.model.elements import in_metres
from fccgrb_cli.model.spatial import JointCoordinate
from fccgrb_cli.opensim.loads import external_loads, read_external_loads
from fccgrb_cli.opensim.storage import UNIFORM, Storage
from fccgrb_cli.pipeline.options import SolveOptions
from fccgrb_cli.pipeline.run import Run
from fccgrb_cli.solvers.quality import FLAG_DTYPE
from fccgrb_cli.solvers.result import KinematicResult
from fccgrb_cli.system import System, compile_system
from fccgrb_cli.system.compiled import Drive

__all__ = ["METHOD", "coordinates_run", "coordinates_run_name"]

METHOD = "coordinates"  # what a run of given coordinates records as its method
MIN_ROWS = 6  # a quintic spline's points


def coordinates_run(model: Model, coordinates: Storage, options: SolveOptions | None = None
                    ) -> Run:
    """The inverse dynamics of ``model`` along ``coordinates``, as a Run.

    Parameters
    ----------
    model
        A model with moving joints (an imported OpenSim model) and inertia on every body.
    coordinates
        The coordinates file (``opensim.storage.read_storage``): time (s), one column per
        coordinate (degrees or radians by its header; metres for translations).
    options
        ``loads`` (an ExternalLoads file), ``filter_cutoff`` (Hz) and ``name`` are read.

    Returns
    -------
    Run
        Kinematics from the coordinates (θ, θ̇, θ̈ and the bodies' poses), no markers, and the
        generalized forces (N·m, N) with the loads' power and the energies.

    Raises
    ------
    InputError
        A model without moving joints or inertia, a file without a coordinate of the model,
        too few rows, an unevenly sampled file with a cutoff, or loads that do not fit.
    """
    options = options or SolveOptions()
    source = coordinates.source
    if not model.moving_joints:
        raise InputError(f"--coordinates: {model.source}: expected an OpenSim model (its "
                         "coordinates are what the file gives); solve a trial's markers instead")
    if not model.has_inertia:
        raise InputError(f"--coordinates: {model.source}: expected mass and inertia on every "
                         "body (the inverse dynamics needs them)")
    if len(coordinates.time) < MIN_ROWS:
        raise InputError(f"{source}: {len(coordinates.time)} rows; the inverse dynamics needs "
                         f"at least {MIN_ROWS} (a quintic spline through them)")
    theta, notes = _columns(model, coordinates)
    time, said = _on_the_grid(coordinates)
    if options.filter_cutoff is not None and time is coordinates.time and len(said):
        raise InputError(f"{source}: --filter-cutoff: expected evenly spaced times ({said[0]})")
    notes += said
    system = compile_system(model, angles="coordinate")
    smooth, rate, acceleration = coordinate_rates(time, theta, options.filter_cutoff)
    keep = _rows(time, options, source)  # the whole file filtered, the range evaluated
    time, smooth, rate, acceleration = (v[keep] for v in (time, smooth, rate, acceleration))
    loads = []
    if options.loads is not None:
        found = read_external_loads(options.loads)
        loads = external_loads(found, time, [body.name for body in model.bodies])
        applied = ", ".join(f"{force.name} → {force.body}" for force in found.forces)
        notes += [f"external loads from {options.loads} ({found.datafile.name}): {applied}; "
                  "applied at the coordinates' times, not filtered (as OpenSim's tool does)",
                  *found.data.notes]
    started = time_module.perf_counter()
    (q, qd, qdd), inverse = coordinate_inverse(system, smooth, rate, acceleration, loads)
    wall = time_module.perf_counter() - started
    n = len(time)
    names = tuple(c.name for c in model.angles)
    result = KinematicResult(
        method=METHOD, tol=options.tol, time=time - time[0], q=q, qd=qd, qdd=qdd,
        theta=smooth, theta_d=rate, theta_dd=acceleration, angle_names=names,
        iterations=np.zeros(n, dtype=int), time_s=np.zeros(n),
        phi_norm=np.zeros(n), phi_top_max=np.abs(_topology(system, q)),
        converged=np.ones(n, dtype=bool), wall_s=wall, flags=np.zeros(n, dtype=FLAG_DTYPE))
    dynamics = Dynamics(kinematics=result, inverse=inverse, loads=tuple(loads),
                        cutoff=options.filter_cutoff)
    none = np.zeros((n, 0, 3))
    return Run(name=coordinates_run_name(options), options=options, result=result, labels=(),
               rate=1.0 / float(np.mean(np.diff(time))), reference=none, markers_input=none,
               model_points=none, ed=np.zeros((n, 0)), ed_input=np.zeros((n, 0)),
               truth_theta=None, form=",".join(sorted({b.form for b in model.bodies})),
               model_text=model.text, trial_path=source, dynamics=dynamics,
               notes=tuple(notes), start_time=float(time[0]),
               moment_flags=np.zeros(inverse.joint_moments.shape, dtype=FLAG_DTYPE))


def coordinates_run_name(options: SolveOptions) -> str:
    """The run's name: ``--name``, else ``id`` and the cutoff (``id-f6Hz``)."""
    cutoff = "" if options.filter_cutoff is None else f"-f{options.filter_cutoff:g}Hz"
    return options.name or f"id{cutoff}"


def _columns(model: Model, coordinates: Storage) -> tuple[np.ndarray, list[str]]:
    """θ (rows × coordinates, rad and m, in ``model.angles``' order) and the notes to give."""
    source = coordinates.source
    if coordinates.in_degrees is False:
        degrees = False
        notes = []
    else:
        degrees = True
        notes = [] if coordinates.in_degrees else [
            f"{source}: rotations read in degrees (the header has no inDegrees; OpenSim's IK "
            "writes degrees)"]
    present = [c for c in model.angles if coordinates.has(c.name)]
    if not present:
        raise InputError(f"{source}: expected columns named after {model.source}'s coordinates "
                         f"({', '.join(c.name for c in model.angles)[:200]}), found none")
    theta = np.empty((len(coordinates.time), len(model.angles)))
    missing = []
    for k, coordinate in enumerate(model.angles):
        if not coordinates.has(coordinate.name):
            assert isinstance(coordinate, JointCoordinate)  # an imported model's are all
            theta[:, k] = coordinate.default
            missing.append(coordinate.name)
            continue
        values = coordinates.column(coordinate.name)
        theta[:, k] = values if in_metres(coordinate) or not degrees else np.radians(values)
    if missing:
        notes.append(f"{source}: no column for {', '.join(missing)}: held at the model's "
                     "default values (as OpenSim's tool does)")
    known = {c.name for c in model.angles}
    extra = [name for name in coordinates.names if name not in known]
    if extra:
        notes.append(f"{source}: columns left out (not coordinates of {model.source}): "
                     f"{', '.join(extra)[:200]}")
    return theta, notes


def _rows(time: np.ndarray, options: SolveOptions, source: str) -> np.ndarray:
    """The rows within ``--from``/``--to`` (OpenSim's time_range: from the later of the first
    row and the range's start to the earlier of the last row and its end)."""
    keep = window(time, options.time_from, options.time_to)
    if keep.sum() < 2:
        raise InputError(f"{source}: --from/--to: expected at least 2 rows within the range, "
                         f"got {int(keep.sum())} (the file covers {time[0]:.6g}–"
                         f"{time[-1]:.6g} s)")
    return keep


def _on_the_grid(coordinates: Storage) -> tuple[np.ndarray, list[str]]:
    """The file's times, or the uniform grid from its first to its last when they lie on it
    but for their printed digits (a file written with 3 decimals at 60 Hz: 0.417, 0.433): a
    spline's accelerations through rounded times carry the rounding divided by the step
    squared, tens of newtons on a body's weight. Said in a note either way: times put on the
    grid, or times that are not uniform (taken as they are)."""
    time = coordinates.time
    if len(time) < 3:
        return time, []
    grid = np.linspace(time[0], time[-1], len(time))
    off = float(np.abs(time - grid).max())
    step = float(grid[1] - grid[0])
    if off <= 1e-4 * step:  # 8 printed decimals at 60 Hz: 5e-9 s, 3e-7 of a step
        return time, []
    if off > UNIFORM * step:
        return time, [f"{coordinates.source}: times not evenly spaced (up to {1e3 * off:.3g} ms "
                      f"from a uniform grid): taken as they are"]
    return grid, [f"{coordinates.source}: times rounded in the file (up to {1e3 * off:.3g} ms "
                  f"from a uniform {1.0 / step:.6g} Hz grid): taken on the grid"]


def _topology(system: System, q: np.ndarray) -> np.ndarray:
    """max |Φ| of the topological rows at each frame's pose (the forward kinematics' closure)."""
    return np.array([np.abs(system.residual(row, Drive())).max() if system.n_rows else 0.0
                     for row in q])

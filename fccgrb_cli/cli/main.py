"""The ``fccgrb`` command: thin wrappers over the library; bad input → one line, exit status 2."""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import sys
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, NoReturn

import click
import numpy as np

from fccgrb_cli import __version__
from fccgrb_cli.core import scratch
from fccgrb_cli.core.errors import InputError
from fccgrb_cli.core.inputs import refuse_inputs
from fccgrb_cli.core.params import Bounded, Widths
from fccgrb_cli.core.progress import Progress
from fccgrb_cli.model import Model, load_model
from fccgrb_cli.model.elements import in_metres
from fccgrb_cli.pipeline.options import (
    AXES,
    SEED_MAX,
    WORKERS_MAX,
    SolveOptions,
    click_options,
    from_cli,
)
from fccgrb_cli.system.structure import analyse, check_tracking

if TYPE_CHECKING:
    from concurrent.futures import Executor

    from fccgrb_cli.pipeline.run import Run

FORM = click.Choice(["model", "full", "reduced"])
VERTICALS = ("auto", *AXES)
ACCEPT_TRUNCATED = click.option(
    "--accept-truncated", is_flag=True,
    help="Use a trial whose data end before the last frame its header announces (an "
         "interrupted copy?) with the frames it holds, and warn (for solves also in the results "
         "file), instead of stopping with an error.")


def reports_input_errors(command: Callable) -> Callable:
    """Turn an InputError into one line on stderr and exit status 2 (no traceback)."""

    @functools.wraps(command)
    def wrapper(*args, **kwargs):
        try:
            return command(*args, **kwargs)
        except InputError as exc:
            click.echo(f"fccgrb: error: {exc}", err=True)
            sys.exit(2)

    return wrapper


def load_with_form(path: str, form: str = "model") -> Model:
    """Load a model and apply a body-form override ('model' keeps the file's forms)."""
    model = load_model(path)
    if form == "model":
        return model
    assert form in ("full", "reduced")  # the option's choices, checked by click
    return model.with_form("full" if form == "full" else "reduced")


def load_checked(path: str, form: str = "model") -> Model:
    """Load a model, apply a body-form override, and check that it determines its coordinates."""
    model = load_with_form(path, form)
    analyse(model)
    return model


def _one_line(error: click.ClickException) -> str:
    """A click error as one line: '--tol: expected …', or the usage error and where to look."""
    param = getattr(error, "param", None)
    missing = isinstance(error, click.MissingParameter)
    if isinstance(error, click.BadParameter) and param is not None and not missing:
        name = max(param.opts, key=len) if param.param_type_name == "option" and param.opts \
            else param.human_readable_name
        text = f"{name}: {error.message}"
    else:
        text = error.format_message()
        ctx = getattr(error, "ctx", None)
        if isinstance(error, click.UsageError) and ctx is not None:
            text += f" (see '{ctx.command_path} --help')"
    return " ".join(text.split())


class Main(click.Group):
    """The command group. While a command runs, SIGINT, SIGTERM and SIGHUP remove the files
    being written and end the process (``fccgrb_cli.core.scratch``); every error a user can cause,
    click's own included, is one line ``fccgrb: error: …`` and exit status 2 (130 for an
    interrupt)."""

    def main(self, args: Sequence[str] | None = None, prog_name: str | None = None,
             complete_var: str | None = None, standalone_mode: bool = True,
             **extra: Any) -> NoReturn:
        previous = scratch.install()
        try:
            code = self._invoke(args, prog_name, extra)
        finally:
            scratch.restore(previous)
        sys.exit(code)

    def _invoke(self, args, prog_name, extra: dict) -> int:
        try:
            value = super().main(args, prog_name or "fccgrb", standalone_mode=False, **extra)
        except InputError as error:
            click.echo(f"fccgrb: error: {error}", err=True)
            return 2
        except click.ClickException as error:
            click.echo(f"fccgrb: error: {_one_line(error)}", err=True)
            return 2
        except (click.exceptions.Abort, KeyboardInterrupt):
            scratch.remove_all()
            click.echo("fccgrb: error: interrupted; the files being written were removed",
                       err=True)
            return 130
        return value if isinstance(value, int) else 0


@click.group(cls=Main, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="fccgrb")
def main() -> None:
    """Kinematic and inverse dynamic analysis of spatial multibody systems with fully Cartesian
    coordinates, a generic rigid body and mixed coordinates (FCC-GRB + MC).

    Models are YAML files (see the README); trials are C3D files. SI units inside: metres,
    radians, seconds; conversions happen when files are read and written.
    """


@main.command()
@click.argument("model")
@click.option("--form", type=FORM, default="model", show_default=True,
              help="Body form for every body: fully-defined [r,u,v,w], reduced [r,u,v], or as "
                   "the model file says.")
@reports_input_errors
def check(model: str, form: str) -> None:
    """Validate MODEL and report its coordinates, rank and redundant constraints; a model that
    tracks markers must track enough to determine it (a floating base: 3 not on one line)."""
    loaded = load_with_form(model, form)
    report = analyse(loaded)
    check_tracking(loaded, report)
    click.echo(f"{model}: model {loaded.name!r} is valid")
    for line in report.lines():
        click.echo(f"  {line}")


@main.command()
@click.argument("model")
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False),
              help="Trial to write (.c3d or .trc, by its ending). The true angles go to "
                   "OUTPUT's stem + '.truth.h5'.")
@click.option("--duration", type=Bounded(float, 0, True, None, "s"), default=3.0,
              show_default=True, help="Length of the trial in seconds (duration × rate at most "
                                      "1,000,000 frames).")
@click.option("--rate", type=Bounded(float, 0, True, 1e5, "Hz"), default=100.0,
              show_default=True, help="Marker sampling rate in Hz.")
@click.option("--units", type=click.Choice(["mm", "m"]), default="mm", show_default=True,
              help="Length unit of the points (C3D POINT:UNITS, TRC Units).")
@click.option("--form", type=FORM, default="model", show_default=True,
              help="Body form used for the analysis (the points do not depend on it).")
@click.option("--tol", type=Bounded(float, 0, True, 1.0, "m and unitless"), default=1e-10,
              show_default=True, help="Newton–Raphson tolerance on ‖Δq‖∞ (m and unitless).")
@reports_input_errors
def synth(model: str, output: str, duration: float, rate: float, units: str, form: str,
          tol: float) -> None:
    """Synthesize a trial: drive MODEL with its prescribed angles (kinematic analysis with
    angular drivers) and write its tracked points to a C3D or TRC file, with the exact angles,
    rates and points in a truth file beside it (both files, or neither)."""
    from fccgrb_cli.core.atomic import check_target, transaction
    from fccgrb_cli.pipeline.synth import frame_count, synthesize
    from fccgrb_cli.trial.record import TRIAL_ENDINGS, write_trial
    from fccgrb_cli.trial.truth import Truth, truth_path, write_truth

    frame_count(duration, rate, "--duration × --rate")
    sidecar = truth_path(output)
    for path in (output, sidecar):
        refuse_inputs(path, [model])
    if Path(output).suffix.lower() not in TRIAL_ENDINGS:
        raise InputError(f"{output}: expected an output ending in .c3d or .trc")
    for path in (output, sidecar):
        check_target(path)
    loaded = load_checked(model, form)
    if not loaded.tracked_points:
        raise InputError(f"{model}: tracking.points: expected at least one tracked point to write")
    s = synthesize(loaded, duration, rate, tol, progress=Progress("synth"))
    r = s.result
    with transaction():
        write_trial(output, list(s.labels), s.markers, rate, units,
                    description=f"fccgrb {__version__} synth {Path(model).name}")
        write_truth(sidecar, Truth(
            time=r.time, theta=r.theta, theta_d=r.theta_d, theta_dd=r.theta_dd,
            angle_names=r.angle_names, q=r.q, form=",".join(sorted(set(s.system.layout.forms))),
            markers=s.markers, labels=s.labels, rate=rate, model_text=loaded.text))
    click.echo(f"wrote {output}: {r.n_frames} frames at {rate:g} Hz, {len(s.labels)} markers "
               f"({units}); truth in {sidecar}")
    click.echo(f"AD analysis: {r.iterations.mean():.2f} iterations/frame, "
               f"{1e3 * r.time_s.mean():.3f} ms/frame, max ‖Φ‖ {r.phi_norm.max():.2e}, "
               + _coordinate_ranges(loaded, r.theta))
    for warning in s.warnings:
        click.echo(f"fccgrb: warning: {warning}", err=True)


def _coordinate_ranges(model: Model, theta: np.ndarray) -> str:
    """'angles A..B deg' and, with distance coordinates, ', distances C..D mm'."""
    distance = np.array([in_metres(a) for a in model.angles], dtype=bool)
    parts = []
    for mask, what, convert, unit in ((~distance, "angles", np.degrees, "deg"),
                                      (distance, "distances", lambda d: 1e3 * d, "mm")):
        if mask.any():
            values = convert(theta[:, mask])
            parts.append(f"{what} {values.min():.1f}..{values.max():.1f} {unit}")
    return ", ".join(parts)


def _split(text: str | None) -> tuple[str, ...]:
    return tuple(part.strip() for part in (text or "").split(",") if part.strip())


def format_summary(row: dict) -> str:
    """A two-line table: header and values, numbers in a compact engineering form."""
    def fmt(value) -> str:
        if isinstance(value, str):
            return value
        if isinstance(value, int):
            return str(value)
        return f"{value:.3g}" if abs(value) < 1e4 else f"{value:.0f}"

    cells = [(key, fmt(value)) for key, value in row.items()]
    widths = [max(len(k), len(v)) for k, v in cells]
    head = "  ".join(k.rjust(w) for (k, _), w in zip(cells, widths, strict=True))
    body = "  ".join(v.rjust(w) for (_, v), w in zip(cells, widths, strict=True))
    return f"{head}\n{body}"


def _trial_paths(patterns: tuple[str, ...]) -> list[str]:
    """The trials named, a quoted glob ('walk*.c3d') expanded in order."""
    import glob

    out: list[str] = []
    for pattern in patterns:
        if any(c in pattern for c in "*?[") and not Path(pattern).exists():
            found = sorted(glob.glob(pattern))
            if not found:
                raise InputError(f"{pattern}: expected trial files matching the pattern, found "
                                 "none")
            out += found
        else:
            out.append(pattern)
    stems = [Path(p).stem for p in out]
    twice = sorted({s for s in stems if stems.count(s) > 1})
    if len(out) > 1 and twice:
        raise InputError(f"{', '.join(twice)}: expected trials with different file names (each "
                         "run is named after its trial's)")
    return out


@main.command()
@click.argument("model", required=False)
@click.argument("trials", nargs=-1, metavar="[TRIAL]...")
@click.option("--opensim-setup", type=click.Path(dir_okay=False), default=None,
              metavar="SETUP.xml",
              help="Run an OpenSim IK or ID setup as its tool would: its model, marker file "
                   "or coordinates file, task set, external loads, time range, accuracy (as "
                   "--tol) and low-pass cutoff (files relative to the setup's folder). What is "
                   "typed beside it wins; MODEL and TRIAL may then be left out.")
@click.option("--coordinates", type=click.Path(dir_okay=False), default=None, metavar="FILE",
              help="Inverse dynamics only, as OpenSim's ID tool: the model's coordinates from "
                   "FILE (.mot/.sto: OpenSim's IK output or `fccgrb export --format mot`; "
                   "degrees unless its header says inDegrees=no, metres for translations) in "
                   "place of a trial; with --loads for the ground reactions and "
                   "--filter-cutoff (Hz) to low-pass the coordinates as the tool does. An "
                   "imported OpenSim model only.")
@click.option("-o", "--output", default="results.h5", show_default=True,
              type=click.Path(dir_okay=False),
              help="HDF5 results file; an existing one gains this run (a run of the same "
                   "name is refused unless --replace).")
@click.option("--replace", is_flag=True, default=False,
              help="Replace a run of the same name in the results file (without it, a second "
                   "solve under one name is refused and nothing is written).")
@click.option("--write-model", type=click.Path(dir_okay=False), default=None, metavar="PATH",
              help="With --reduce-residuals: write the model with the adjusted segment masses "
                   "and centres of mass (YAML) to PATH.")
@click_options
@ACCEPT_TRUNCATED
@reports_input_errors
def solve(model: str | None, trials: tuple[str, ...], opensim_setup: str | None,
          coordinates: str | None, output: str, replace: bool, write_model: str | None,
          accept_truncated: bool, **options: Any) -> None:
    """Solve the kinematics of MODEL (YAML, or an OpenSim .osim) over TRIAL (C3D or TRC
    markers), then its inverse dynamics, and write HDF5.

    Prints a one-row summary: ms/frame (positions), iterations/frame, mean ‖Φ‖ over the active
    equations, max |topological Φ|, mean and max Euclidean distance (mm) between each tracked
    model point and its reference marker, the frames that did not converge (failed) and those
    the quality checks flagged (a jump, another assembly branch, a broken topology).

    Several trials of one subject (or a quoted glob, 'walk*.c3d'): one run each, named
    <trial file stem>-<run name>, and, for a lower-limb model, the subject's cycles over every
    trial's strides in /subject of the results file.

    With --coordinates FILE in place of a trial: the inverse dynamics of an OpenSim model
    along the coordinates FILE gives (OpenSim's ID tool), a run named id (id-f6Hz with
    --filter-cutoff 6).
    """
    from fccgrb_cli.core.atomic import check_target
    from fccgrb_cli.core.inputs import check_name
    from fccgrb_cli.results.storage import check_output, refuse_taken_names, write_runs
    from fccgrb_cli.trial.truth import truth_path

    chosen = from_cli(options)
    in_degrees = None
    if opensim_setup is not None:
        from fccgrb_cli.pipeline.opensim_setup import setup_inputs

        context = click.get_current_context()
        typed = frozenset(name for name in options if context.get_parameter_source(name)
                          not in (None, click.core.ParameterSource.DEFAULT))
        found = setup_inputs(opensim_setup, model, trials, coordinates, chosen, typed)
        model, trials, coordinates, chosen = (found.model, found.trials, found.coordinates,
                                              found.options)
        in_degrees = found.in_degrees
        for note in found.notes:
            click.echo(f"fccgrb: {note}", err=True)
    if model is None:
        raise InputError("solve: expected MODEL (a YAML or OpenSim .osim model) or "
                         "--opensim-setup SETUP.xml")
    if coordinates is not None:
        if trials:
            raise InputError(f"--coordinates {coordinates}: expected no trial beside it (the "
                             f"coordinates stand for the solve), got {', '.join(trials)}")
        if write_model is not None:
            raise InputError("--write-model: expected a trial to solve (it writes the model a "
                             "residual reduction adjusts), got --coordinates")
        _coordinates_only(model, coordinates, output, replace, chosen, in_degrees)
        return
    if not trials:
        raise InputError("solve: expected TRIAL (C3D or TRC markers) or --coordinates FILE")
    chosen = _first_run_engine(chosen)
    paths = _trial_paths(trials)
    from fccgrb_cli.pipeline.solve import check_window

    for path in paths:
        check_window(path, chosen)
    refuse_inputs(output, [model, *paths, *map(truth_path, paths), *_map_files(options)])
    check_target(output)
    if write_model is not None:
        named: list[str | Path] = [model, *paths, *map(truth_path, paths), output,
                                   *_map_files(options)]
        taken = {Path(p).resolve() for p in named}
        _check_model_output(write_model, taken, chosen, paths)
        check_target(write_model)
    check_output(output)
    if not replace and Path(output).exists():  # before any solve: the names are known
        from fccgrb_cli.pipeline.solve import expected_run_name

        name = expected_run_name(chosen)
        refuse_taken_names(Path(output), [name] if len(paths) == 1 else
                           [f"{Path(p).stem}-{name}" for p in paths])
    loaded = load_checked(model, chosen.form)
    runs = []
    for path in paths:
        run = _solve_one(loaded, path, chosen, accept_truncated, output)
        if np.isnan(run.result.theta).all():
            raise InputError(f"{path}: no frame could be solved (in every frame the markers "
                             "present cannot determine the model); nothing was written")
        if len(paths) > 1:
            name = check_name(f"{Path(path).stem}-{run.name}", f"{path}: run name")
            run = dataclasses.replace(run, name=name)
        if not replace and Path(output).exists():
            refuse_taken_names(Path(output), [run.name])  # before anything is written
        _report_kernels()
        runs.append(run)
        if write_model is not None:
            from fccgrb_cli.core.atomic import atomic_path

            assert run.reduction is not None  # --write-model asks for the reduction
            with atomic_path(write_model) as tmp:
                tmp.write_text(run.reduction.text, encoding="utf-8")
            click.echo(f"wrote {write_model}: the model with the adjusted segment inertia")
    with_gait = [r for r in runs if r.gait is not None]
    gaits = [r.gait for r in runs if r.gait is not None]  # with_gait's, in order
    subject = None
    if len(with_gait) > 1:
        from fccgrb_cli.gait.cycles import pooled

        subject = ([r.name for r in with_gait], pooled([g.cycles for g in gaits]))
    write_runs(output, runs, " ".join(["fccgrb", *sys.argv[1:]]), subject=subject,
               waiting=lambda line: click.echo(f"fccgrb: warning: {line}", err=True),
               replace=replace)
    for run in runs:
        _show(run, output)
    if subject is not None:
        from fccgrb_cli.presentation.gait_report import subject_report

        click.echo(subject_report(*subject))


def _first_run_engine(options: SolveOptions) -> SolveOptions:
    """``--engine auto`` before the kernels were ever compiled on this machine: this run in
    the numpy engine (the same answers to 1e-12) while a background process compiles them for
    the next runs, so that a first command does not wait a minute; said on stderr and recorded
    with the run (its options' engine). ``FCCGRB_BACKGROUND_COMPILE=0`` keeps the foreground
    compile (the tests set it: every run of a suite then uses one engine)."""
    import os

    from fccgrb_cli.pipeline.precompile import BACKGROUND, compile_in_background, compiling
    from fccgrb_cli.solvers.engine import numba_available

    if options.engine != "auto" or os.environ.get(BACKGROUND) == "0" or \
            not numba_available():
        return options
    import fccgrb_cli.solvers  # noqa: F401  (names the kernels' cache folder)
    from fccgrb_cli.core.kernel_cache import compiled_here

    folder = os.environ.get("NUMBA_CACHE_DIR")
    # a compile under way has written its first kernels: a run that took them would compile
    # the rest itself, in the foreground (~45 s)
    if not folder or (compiled_here() and not compiling(Path(folder))):
        return options
    started = compile_in_background(Path(folder))
    click.echo("fccgrb: the compiled kernels are not built on this machine yet: this run uses "
               "the numpy engine (the same answers to 1e-12, slower per frame)"
               + (" while they compile in the background for the next runs (about a minute)"
                  if started else "") + "; 'fccgrb compile' builds them now", err=True)
    return dataclasses.replace(options, engine="numpy")


def _coordinates_only(model: str, coordinates: str, output: str, replace: bool,
                      options: SolveOptions, in_degrees: bool | None = None) -> None:
    """``solve MODEL --coordinates FILE``: the inverse dynamics alone, one run written."""
    from fccgrb_cli.core.atomic import check_target
    from fccgrb_cli.opensim.storage import read_storage
    from fccgrb_cli.pipeline.coordinates import coordinates_run, coordinates_run_name
    from fccgrb_cli.results.storage import check_output, refuse_taken_names, write_runs

    refuse_inputs(output, [model, coordinates, *([options.loads] if options.loads else [])])
    check_target(output)
    check_output(output)
    if not replace and Path(output).exists():  # before the work
        refuse_taken_names(Path(output), [coordinates_run_name(options)])
    loaded = load_checked(model, options.form)
    storage = read_storage(coordinates)
    if storage.in_degrees is None and in_degrees is not None:  # the ID setup's word
        storage = dataclasses.replace(storage, in_degrees=in_degrees)
    run = coordinates_run(loaded, storage, options)
    write_runs(output, [run], " ".join(["fccgrb", *sys.argv[1:]]),
               waiting=lambda line: click.echo(f"fccgrb: warning: {line}", err=True),
               replace=replace)
    _show(run, output)


def _start_times(results: str) -> dict[str, float]:
    """Each run's first frame on its trial file's clock (s), by run name."""
    import h5py

    with h5py.File(results, "r") as h5:
        runs = h5.get("runs", {})
        return {name: float(runs[name].attrs.get("start_time_s", 0.0)) for name in runs}


def _map_files(options: dict[str, Any]) -> list[str]:
    """The label-map files a --map names (inputs too)."""
    return [item.strip() for item in options.get("mapping") or ()
            if item.strip().lower().endswith((".yaml", ".yml")) and "=" not in item]


def _check_model_output(path: str, taken: set[Path], options: SolveOptions,
                        trials: list[str]) -> None:
    """--write-model asks for a reduction of one trial, into a file that is no input."""
    if not options.reduce_residuals:
        raise InputError("--write-model: expected --reduce-residuals (the model it writes is "
                         "the one the reduction adjusts)")
    if len(trials) > 1:
        raise InputError(f"--write-model: expected one trial (each trial adjusts the model its "
                         f"own way), got {len(trials)}")
    if Path(path).resolve() in taken:
        raise InputError(f"--write-model {path}: expected a file other than the model, the "
                         "trials and the results (inputs are never modified)")


def _solve_one(model: Model, path: str, options: SolveOptions, accept_truncated: bool,
               output: str) -> Run:
    """One trial solved, its largest arrays held on disk beside ``output`` until written."""
    from fccgrb_cli.pipeline.solve import solve_trial
    from fccgrb_cli.trial.record import read_trial

    return solve_trial(model, read_trial(path, accept_truncated), options,
                       progress=Progress(f"solve {options.method} {Path(path).name}"),
                       spill=Path(output).resolve().parent)


def _report_kernels() -> None:
    """How long this process spent loading (or compiling) the compiled kernels, on stderr: a
    one-time cost per process that no ms/frame includes. Nothing in a command forked by the
    warm server (``cli.server``), which loaded them before the command, unless it compiled."""
    from fccgrb_cli.cli import server
    from fccgrb_cli.solvers.engine import KernelClock

    seconds, compiled = KernelClock.take()
    if (seconds and not server.warm) or compiled:
        what = "compiled" if compiled else "loaded"
        click.echo(f"fccgrb: compiled kernels {what} in {seconds:.2f} s (once per process; not "
                   "in ms/frame)", err=True)


@main.command("compile")
@reports_input_errors
def compile_command() -> None:
    """Compile the numba kernels now (once per install, about a minute; otherwise the first
    solve that runs in them does it), by solving a few frames of a built-in model with every
    compiled method."""
    from fccgrb_cli.pipeline.precompile import precompile

    total = precompile(lambda method, seconds: click.echo(f"{method}: {seconds:.1f} s"))
    click.echo(f"compiled kernels ready ({total:.1f} s)")


@main.command("server")
@click.option("--stop", is_flag=True, help="End every fccgrb server of yours (the commands "
              "they run finish first); the next command runs in its own process and leaves a "
              "fresh one.")
@reports_input_errors
def server_command(stop: bool) -> None:
    """The warm servers that run the commands you type at a terminal (one per install and
    environment; each ends after 10 minutes without a command; FCCGRB_SERVER=1 serves
    scripts' commands too, FCCGRB_SERVER=0 none): their process ids and sockets, or --stop
    them. See docs/performance.md."""
    from fccgrb_cli.cli import server

    if stop:
        stopped = server.stop()
        click.echo(f"stopped {len(stopped)} fccgrb server(s)"
                   + (f": {', '.join(map(str, stopped))}" if stopped else ""))
        return
    found = server.servers()
    if not server.enabled():
        click.echo("this command would not use a fccgrb server (FCCGRB_SERVER=0, not Linux, "
                   "or stderr not a terminal without FCCGRB_SERVER=1)")
    if not found:
        click.echo("no fccgrb server is up")
    for pid, path in found:
        click.echo(f"{pid}  {path}")


def _show(run: Run, output: str) -> None:
    from fccgrb_cli.anatomy.clinical import clinical_table
    from fccgrb_cli.pipeline.run import summary

    for message in (*run.result.messages, *run.warnings):
        click.echo(f"fccgrb: warning: {message}", err=True)
    for message in run.notes:
        click.echo(f"fccgrb: {message}", err=True)
    click.echo(format_summary(summary(run)))
    if run.clinical is not None:
        click.echo(clinical_table(run.clinical, run.trusted))
    if run.residuals is not None:
        from fccgrb_cli.presentation.residual_table import residual_table

        click.echo(residual_table(run.residuals, run.reduction))
    if run.gait is not None:
        from fccgrb_cli.presentation.gait_report import gait_report

        click.echo(gait_report(run.gait, run.start_time))
    click.echo(f"wrote run {run.name!r} ({run.result.n_frames} frames) to {output}")


def _frame_range(text: str | None) -> tuple[int, int] | None:
    if text is None:
        return None
    parts = text.split(":")
    if len(parts) != 2 or not all(p.strip().isdigit() for p in parts):
        raise InputError(f"--frames: expected A:B, frame indices from 0 with B excluded "
                         f"(e.g. 0:100), got {text!r}")
    return int(parts[0]), int(parts[1])


@main.command()
@click.argument("model")
@click.argument("trial")
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False),
              help="The personalized model to write (YAML).")
@click.option("--frames", default=None, metavar="A:B",
              help="Frame indices used (from 0, B excluded), e.g. a static trial's quiet "
                   "part or a stretch of a walking trial.  [default: every frame]")
@click.option("--mass", type=Bounded(float, 0, True, 500, "kg"), default=None,
              help="Body mass in kg: scales segment inertia (de Leva 1996) and gives moments "
                   "in N·m/kg. Without it the model has no inertia (kinematics only).")
@click.option("--knee-width", type=Widths(500, "mm"), default=None, metavar="MM[,MM]",
              help="The knee's width across the epicondyles, mm (Davis et al. 1991); Plug-in "
                   "Gait templates take left,right.  [Helen Hayes default: 100]")
@click.option("--ankle-width", type=Widths(500, "mm"), default=None, metavar="MM[,MM]",
              help="The ankle's width across the malleoli, mm; Plug-in Gait templates take "
                   "left,right.  [Helen Hayes default: 70]")
@click.option("--marker-diameter", type=Widths(500, "mm"), default=None, metavar="MM",
              help="The markers' diameter, mm.  [default: 14, Plug-in Gait's]")
@click.option("--subject", "subject_files", multiple=True, metavar="FILE",
              help="The subject's measurements from a Vicon .vsk or .mp, a C3D's PROCESSING "
                   "group or a YAML subject: section (repeatable; later files and the width "
                   "options win). The static TRIAL's own PROCESSING group and the template's "
                   "subject: section are read first.")
@click.option("--foot-flat/--no-foot-flat", default=None,
              help="Plug-in Gait templates: the static's heel-to-toe line taken level (raised "
                   "at the heel by the sole delta) for the foot offsets, as Plug-in Gait's "
                   "'foot flat' option does.  [default: the option whose offsets equal the "
                   "StaticPlantFlex and StaticRotOff the subject's files record, else foot "
                   "flat]")
@click.option("--map", "mapping", multiple=True, metavar="NAME=LABEL|FILE",
              help="The template's label → the trial's, where a lab spells them otherwise "
                   "(repeatable NAME=LABEL, comma-separated pairs, or a YAML file of NAME: "
                   "LABEL lines; the same map serves `fccgrb solve --map`).")
@click.option("--vertical", type=click.Choice(VERTICALS), default="auto", show_default=True,
              help="The lab's up: auto finds it from the trial (as `fccgrb solve --vertical`), "
                   "or an axis states it; the personal model's gravity points down it.")
@ACCEPT_TRUNCATED
@reports_input_errors
def calibrate(model: str, trial: str, output: str, frames: str | None,
              mass: float | None, knee_width: str | None, ankle_width: str | None,
              marker_diameter: str | None, subject_files: tuple[str, ...], foot_flat: bool | None,
              mapping: tuple[str, ...], vertical: str, accept_truncated: bool) -> None:
    """Personalize MODEL (a lower-limb template such as configs/models/lower_limb.yaml or
    helen_hayes.yaml) from TRIAL's markers: ISB segment frames from the landmarks named in its
    `calibration` section, hip centres by Harrington et al. (2007), knee and ankle centres
    between the epicondyles and the malleoli or, for the Helen Hayes/Davis set, by Davis et
    al.'s (1991) chord construction from the knee and ankle widths, each marker's local
    coordinates (mean over the frames), segment lengths and inertia. A Plug-in Gait template
    (configs/models/plugin_gait.yaml) is personalized as Plug-in Gait does (Davis hip centres,
    chord knee and ankle centres, thigh and shank rotation offsets, tibial torsion, the static's
    foot offsets) from the subject's measurements: the static C3D's PROCESSING group, the
    template's subject: section, --subject files and the width options, in that order; every
    other template reads its body mass (and a Helen Hayes one its widths and marker diameter)
    from the same sources in the same order. Writes a model ready for `fccgrb solve`."""
    from fccgrb_cli.core.atomic import atomic_path, check_target
    from fccgrb_cli.pipeline.calibration import Choices, Subject, calibrate_subject
    from fccgrb_cli.pipeline.options import from_cli
    from fccgrb_cli.trial.record import read_trial

    refuse_inputs(output, [model, trial, *_map_files({"mapping": mapping})])
    check_target(output)
    template = load_model(model)
    data = read_trial(trial, accept_truncated)
    done = calibrate_subject(
        template, data,
        Subject(mass, knee_width, ankle_width, marker_diameter, subject_files),
        Choices(_frame_range(frames), foot_flat, dict(from_cli({"mapping": mapping}).mapping),
                vertical), source=output)
    for message in done.warnings:
        click.echo(f"fccgrb: warning: {message}", err=True)
    for message in done.notes:
        click.echo(f"fccgrb: {message}", err=True)
    with atomic_path(output) as tmp:
        tmp.write_text(done.text, encoding="utf-8")
    start, stop = done.frames
    click.echo(f"wrote {output}: {done.model.name} from frame indices {start}:{stop} of "
               f"{trial}")
    for line in done.report:
        click.echo(line)


@main.command("perturb")
@click.argument("source")
@click.argument("target")
@click.option("--level", "level_mm", type=Bounded(float, 0, False, 1000, "mm"), required=True,
              help="Soft-tissue-artefact level in mm: the largest deviation per axis.")
@click.option("--markers", default=None, metavar="LABELS",
              help="Comma-separated file labels to perturb [default: every marker].")
@click.option("--seed", type=Bounded(int, 0, False, SEED_MAX), default=0, show_default=True,
              help="Seed of the perturbation (same seed, same artefact).")
@click.option("--units", type=click.Choice(["mm", "m"]), default="mm", show_default=True,
              help="Length unit written to TARGET.")
@ACCEPT_TRUNCATED
@reports_input_errors
def perturb_command(source: str, target: str, level_mm: float, markers: str | None, seed: int,
                    units: str, accept_truncated: bool) -> None:
    """Add a soft-tissue artefact to the markers of SOURCE and write TARGET (.c3d or .trc).

    Each perturbed marker and axis gets a seeded sum of sinusoids in the band of human movement
    (0.3–3 Hz) scaled to the level. A truth file beside SOURCE is copied beside TARGET, so
    results on TARGET still compare with the unperturbed reference.
    """
    import shutil

    from fccgrb_cli.core.atomic import atomic_path, check_target, transaction
    from fccgrb_cli.signals.artefact import perturb
    from fccgrb_cli.trial.record import TRIAL_ENDINGS, read_trial, write_trial
    from fccgrb_cli.trial.truth import truth_path

    sidecar = truth_path(source)
    copy_truth = sidecar.exists() and sidecar.resolve() != truth_path(target).resolve()
    outputs: tuple[str | Path, ...] = (target, *([truth_path(target)] if copy_truth else []))
    for path in outputs:
        refuse_inputs(path, [source, sidecar])
    if Path(target).suffix.lower() not in TRIAL_ENDINGS:
        raise InputError(f"{target}: expected an output ending in .c3d or .trc")
    for path in outputs:
        check_target(path)
    data = read_trial(source, accept_truncated)
    for message in data.warnings:
        click.echo(f"fccgrb: warning: {message}", err=True)
    only = _split(markers)
    unknown = sorted(set(only) - set(data.labels))
    if unknown:
        raise InputError(f"--markers: expected labels of {source}, got {', '.join(unknown)}")
    out = perturb(data.markers, data.labels, data.rate, level_mm * 1e-3, seed, only or None)
    with transaction():
        write_trial(target, list(data.labels), out, data.rate, units,
                    artefact_mm=level_mm + 1e3 * data.artefact_m)
        if copy_truth:
            with atomic_path(truth_path(target)) as tmp:
                shutil.copyfile(sidecar, tmp)
    click.echo(f"wrote {target}: {len(only) or len(data.labels)} of {len(data.labels)} markers "
               f"perturbed at {level_mm:g} mm (seed {seed})")


@main.command()
@click.argument("config")
@click.option("-o", "--output", default=None, type=click.Path(dir_okay=False),
              help="Sweep results (HDF5) [default: the config's name + .h5 in the current "
                   "folder]. Finished cells are kept in OUTPUT.cells/ so a rerun does only "
                   "the missing ones.")
@click.option("--workers", type=Bounded(int, 1, False, WORKERS_MAX), default=1,
              show_default=True,
              help="Processes running cells at once (cells in parallel mode run alone; at most "
                   "4 per CPU).")
@click.option("--scheduler", default=None, metavar="ADDRESS",
              help="Run the cells on an existing Dask cluster (e.g. tcp://host:8786) through "
                   "dask.distributed's executor; needs the 'cluster' extra.")
@click.option("--fresh", is_flag=True, help="Forget finished cells and run every cell again.")
@click.option("--format", "fmt", type=click.Choice(["text", "csv", "markdown"]), default="text",
              show_default=True, help="Format of the tables printed at the end.")
@ACCEPT_TRUNCATED
@reports_input_errors
def sweep(config: str, output: str | None, workers: int, scheduler: str | None, fresh: bool,
          fmt: str, accept_truncated: bool) -> None:
    """Run a grid of solves (models, trials, methods, tolerances, perturbation levels, seeds,
    tracked-point variants, sequential/parallel) from CONFIG (YAML; see configs/sweeps/), and
    print tables laid out like the paper's Tables 1 and 2 with the paper's figures beside ours."""
    import time

    from fccgrb_cli.batch.cells import cells_folder, remove_cells
    from fccgrb_cli.batch.sweep import check_sweep_output, load_sweep, run_sweep
    from fccgrb_cli.core.atomic import check_target
    from fccgrb_cli.presentation.tables import collect, render
    from fccgrb_cli.trial.record import read_trial

    spec = load_sweep(config)
    out = Path(output or f"{spec.name}.h5")
    refuse_inputs(out, [config, spec.model, spec.trial.get("file")])
    check_target(out)
    check_sweep_output(out, spec.name)
    if cells_folder(out).exists() and not cells_folder(out).is_dir():
        raise InputError(f"{cells_folder(out)}: expected the folder of finished cells, got a "
                         "file")
    if "file" in spec.trial:  # read once here: a bad trial stops before any cell runs
        for message in read_trial(spec.trial["file"], accept_truncated).warnings:
            click.echo(f"fccgrb: warning: {message}", err=True)
        spec = dataclasses.replace(spec, trial=spec.trial | {"accept_truncated": accept_truncated})
    if fresh:
        remove_cells(out)
    started = time.perf_counter()

    def progress(text: str) -> None:
        click.echo(f"sweep: {text}", err=True)

    with cluster_executor(scheduler) as executor:
        ran, kept = run_sweep(spec, out, workers=workers, executor=executor, progress=progress)
    click.echo(render(*collect(out), fmt=fmt))
    click.echo(f"wrote {out}: {ran} cells run, {kept} already done "
               f"({time.perf_counter() - started:.0f} s)")


@contextlib.contextmanager
def cluster_executor(scheduler: str | None) -> Iterator[Executor | None]:
    """The executor of the Dask cluster at ``scheduler`` (None: no cluster), closed after."""
    if scheduler is None:
        yield None
        return
    try:
        from dask.distributed import Client
    except ImportError:
        raise InputError("--scheduler: expected dask.distributed; install the 'cluster' "
                         "extra (pip install 'fccgrb-cli[cluster]')") from None
    try:
        client = Client(scheduler, timeout=10)
    except OSError as exc:
        raise InputError(f"--scheduler: cannot reach {scheduler} ({exc})") from None
    with client:
        yield client.get_executor()


@main.command()
@click.argument("study")
@click.option("-o", "--output", default=None, type=click.Path(dir_okay=False),
              help="Study results (HDF5) [default: the study's name + .h5 in the current "
                   "folder]. Finished calibrations and trials are kept in OUTPUT.cells/ so a "
                   "rerun does only the missing ones.")
@click.option("--workers", type=Bounded(int, 1, False, WORKERS_MAX), default=1,
              show_default=True, help="Local processes solving trials at once (at most 4 per "
                                      "CPU).")
@click.option("--scheduler", default=None, metavar="ADDRESS",
              help="Run the calibrations and trials on an existing Dask cluster (e.g. "
                   "tcp://host:8786) whose workers see the same files; needs the 'cluster' "
                   "extra.")
@click.option("--fresh", is_flag=True,
              help="Forget finished calibrations and trials and do every one again.")
@ACCEPT_TRUNCATED
@reports_input_errors
def batch(study: str, output: str | None, workers: int, scheduler: str | None, fresh: bool,
          accept_truncated: bool) -> None:
    """Run a study: calibrate each subject of STUDY (YAML; see the README) once from its static
    trial, solve every trial, pool the strides per subject and per group, and write one results
    file; print each subject's and group's spatiotemporal table and the failures.

    A trial or calibration that fails is listed at the end and does not stop the others. Exit
    status: 0 every trial solved; 1 some failed (the file holds the rest and the failures); 2
    bad input (the study file, a path or option in it, the output): nothing written."""
    import time

    from fccgrb_cli.batch.cells import remove_cells
    from fccgrb_cli.batch.study.batch import Executors, run_study
    from fccgrb_cli.batch.study.spec import load_study
    from fccgrb_cli.batch.study.store import check_study_output, read_study
    from fccgrb_cli.batch.study.tables import study_tables
    from fccgrb_cli.core.atomic import check_target

    spec = load_study(study)
    out = Path(output or f"{spec.name}.h5")
    refuse_inputs(out, list(spec.inputs))
    check_target(out)
    check_study_output(out)
    if fresh:
        remove_cells(out)
    started = time.perf_counter()
    progress = Progress("batch", delay=0.0, log_every=0.0, unit="trial", bar=20)
    with cluster_executor(scheduler) as executor:
        outcome = run_study(spec, out, Executors(workers, executor),
                            accept_truncated=accept_truncated, progress=progress)
    click.echo(study_tables(read_study(out, trial_gait=False)))
    failed = outcome.failed_trials
    calibrations = len(outcome.failures) - failed
    click.echo(f"wrote {out}: {outcome.solved} trials solved now, {outcome.kept} already done, "
               f"{failed} failed" + (f" ({calibrations} calibrations failed)" if calibrations
                                     else "") + f" ({time.perf_counter() - started:.0f} s)")
    if outcome.failures:
        sys.exit(1)


def _cycle_bands(results: str, names: tuple[str, ...]
                 ) -> dict[str, tuple[np.ndarray, dict[str, np.ndarray]]]:
    """Each run's frame times and its clinical curves' standard deviations (``--smooth
    auto``), for the cycles' bands."""
    from fccgrb_cli.gait.analysis import curve_sd
    from fccgrb_cli.results.runs import read_runs

    out = {}
    for name, run in read_runs(results).items():
        sd = run.clinical_sd if name in names else None
        if sd is not None:
            angles, moments = sd
            out[name] = (run.result.time, curve_sd(angles.names, angles.values,
                                                   None if moments is None else moments.values))
    return out


def _rate(results: str) -> float:
    """The frame rate of a results file's trial (Hz)."""
    import h5py

    with h5py.File(results, "r") as h5:
        return float(h5["reference/markers"].attrs["rate"])


@main.command()
@click.argument("results")
@click.option("--format", "fmt", type=click.Choice(["text", "csv", "markdown"]), default="text",
              show_default=True, help="text (aligned columns), csv (one value per line) or "
                                      "markdown (pipe tables).")
@click.option("--table", type=click.Choice(["table1", "table2"]), default=None,
              help="Compare with this table of the paper [default: the sweep's own, none for a "
                   "solve's results].")
@click.option("--html", "html_folder", default=None, type=click.Path(file_okay=False),
              metavar="FOLDER",
              help="For a study file (fccgrb batch): write the clinical report into FOLDER, "
                   "index.html for the study and subject-<name>.html per subject, "
                   "self-contained HTML pages (inline SVG plots; print or save as PDF from a "
                   "browser).")
@click.option("--normative", default=None, type=click.Path(dir_okay=False),
              help="With --html: a CSV of norms (columns variable, percent, mean, sd: curves by "
                   "clinical name without _l/_r, e.g. knee_flexion, knee_flexion_moment; rows "
                   "with an empty percent for spatiotemporal parameters, e.g. walking_speed), "
                   "drawn as grey mean ± sd bands and printed beside the parameters.")
@reports_input_errors
def report(results: str, fmt: str, table: str | None, html_folder: str | None,
           normative: str | None) -> None:
    """Print the tables of a results or sweep file: per method / variant / tracked points /
    tolerance, the ms/frame, iterations, mean ‖Φ‖, max topological Φ, ED (mm), jump (mm) and
    failed frames at P0, P7.5 and P30, the paper's figures in brackets where they match. For a
    study file (text), its trials, each subject's and group's spatiotemporal table and the
    failures; with --html, the clinical report."""
    from fccgrb_cli.batch.study.store import is_study
    from fccgrb_cli.presentation.tables import collect, render

    study = is_study(results)
    if normative is not None and html_folder is None:
        raise InputError("--normative: expected with --html (the cycle plots of "
                         "'fccgrb plot --kind cycles' take it too)")
    if html_folder is not None:
        if not study:
            raise InputError(f"{results}: --html: expected a study file (written by "
                             "'fccgrb batch')")
        from fccgrb_cli.presentation.clinical_report import write_report

        pages = write_report(results, html_folder, normative)
        click.echo(f"wrote {html_folder}: {len(pages)} pages ({pages[0].name} for the study, "
                   f"one per subject)")
        return
    if fmt == "text" and study:
        from fccgrb_cli.batch.study.store import read_study
        from fccgrb_cli.batch.study.tables import study_tables

        click.echo(study_tables(read_study(results, trial_gait=False)))
        return
    own, rows = collect(results)
    click.echo(render(table if table is not None else own, rows, fmt=fmt), nl=False)
    if fmt == "text":
        from fccgrb_cli.presentation.gait_report import gait_report
        from fccgrb_cli.results.gait import read_all_gait

        starts = _start_times(results)
        for name, gait in read_all_gait(results).items():
            click.echo(f"\nrun {name}: {gait_report(gait, starts.get(name, 0.0))}")
        from fccgrb_cli.presentation.residual_table import residual_table
        from fccgrb_cli.results.residuals import read_all_residuals

        for name, (residuals, reduction) in read_all_residuals(results).items():
            click.echo(f"\nrun {name}: {residual_table(residuals, reduction)}")


@main.command()
@click.argument("results")
@click.option("--kind", type=click.Choice(["point", "ed", "angle", "velocity", "clinical",
                                          "cycles", "residuals"]),
              default="point", show_default=True,
              help="point: x, y, z of a marker's model point against the reference (m); ed: its "
                   "Euclidean distance to the reference over time (mm); angle: a joint angle "
                   "against the truth (deg); velocity: a component of the point's velocity "
                   "(m/s, central differences); clinical: clinical angles (deg) and joint "
                   "moments (N·m/kg) of both legs, force-plate stances shaded; cycles: each "
                   "side's mean ± SD gait cycle (0–100 %) of the clinical angles and moments, "
                   "toe-off dashed; residuals: a floating base's residual force and moment "
                   "over the trial (the first model's beside the reduced one's), frames with "
                   "an unmeasured ground contact greyed.")
@click.option("--marker", default=None, help="Model marker name [default: the last tracked].")
@click.option("--angle", default=None,
              help="Angle name for --kind angle [default: the first]; for --kind clinical, "
                   "comma-separated parts of clinical angle names, e.g. 'hip,knee_flexion' "
                   "[default: 'flexion', the sagittal angles].")
@click.option("--normative", default=None, type=click.Path(dir_okay=False),
              help="For --kind cycles: a CSV of normative curves (columns variable, percent, "
                   "mean, sd; variable as the clinical name without _l/_r, e.g. knee_flexion), "
                   "drawn as a grey mean ± sd band.")
@click.option("--axis", type=click.Choice(["x", "y", "z"]), default="x", show_default=True,
              help="Velocity component for --kind velocity.")
@click.option("--runs", default=None, metavar="NAMES",
              help="Comma-separated run names (results file) or cell-key prefixes (sweep file) "
                   "[default: all].")
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False),
              help="Figure file, .png or .pdf.")
@reports_input_errors
def plot(results: str, kind: str, marker: str | None, angle: str | None,
         normative: str | None, axis: str, runs: str | None, output: str) -> None:
    """Draw one of the paper's figure kinds from a results or sweep file (needs the 'plots'
    extra: pip install 'fccgrb-cli[plots]')."""
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        raise InputError("plot: expected matplotlib; install the 'plots' extra "
                         "(pip install 'fccgrb-cli[plots]')") from None
    from fccgrb_cli.core.atomic import check_target
    from fccgrb_cli.presentation.plot import draw, load_series, save

    refuse_inputs(output, [results, normative])
    check_target(output)
    if kind == "cycles":
        from fccgrb_cli.gait.normative import read_norms
        from fccgrb_cli.presentation.gait_plot import draw_cycles
        from fccgrb_cli.results.gait import read_all_gait

        wanted = _split(runs)
        gaits = {k: g for k, g in read_all_gait(results).items()
                 if not wanted or k in wanted}
        save(draw_cycles(gaits, tuple(a for a in (angle or "").split(",") if a),
                         read_norms(normative).curves if normative else None,
                         _cycle_bands(results, tuple(gaits))), output)
        click.echo(f"wrote {output}: cycles for {len(gaits)} runs")
        return
    if kind == "residuals":
        from fccgrb_cli.presentation.residual_plot import draw_residuals
        from fccgrb_cli.results.residuals import read_all_residuals

        wanted = _split(runs)
        found = {k: r for k, r in read_all_residuals(results).items()
                 if not wanted or k in wanted}
        save(draw_residuals(found, _rate(results)), output)
        click.echo(f"wrote {output}: residuals for {len(found)} runs")
        return
    series = load_series(Path(results), _split(runs))
    save(draw(series, kind, marker, angle, axis), output)
    click.echo(f"wrote {output}: {kind} for {len(series)} runs")


@main.command()
@click.argument("results")
@click.option("--format", "fmt", type=click.Choice(["mot", "sto", "csv", "c3d"]), required=True,
              help="mot: the angles as an OpenSim motion file (deg, inDegrees=yes); sto: the "
                   "joint moments as an OpenSim storage file (N·m, as OpenSim's inverse "
                   "dynamics writes them); csv: one row per frame, time (s), trusted, every "
                   "angle (deg) and moment (N·m) with its unit in the header; c3d: the trial's "
                   "C3D with its markers, analogs and events, the angles and moments added as "
                   "points (POINT:ANGLES, POINT:MOMENTS). Clinical curves where the model "
                   "declares them, else every joint angle (a distance in m, its force in N).")
@click.option("--convention", default="fccgrb", show_default=True,
              type=click.Choice(["fccgrb", "plugin-gait", "opensim"]),
              help="plugin-gait (--format c3d, a run of the Plug-in Gait model): Plug-in "
                   "Gait's outputs as Nexus writes them, 3-component points LHipAngles (deg), "
                   "LKneeMoment (N·mm/kg), LAnklePower (W/kg, in Z), ..., replacing points of "
                   "the same names; opensim (--format mot, the same runs): OpenSim's coordinate "
                   "names and signs (pelvis_tilt, hip_flexion_r, knee_angle_r, ankle_angle_r, "
                   "...; Rajagopal 2015, knee flexion positive).")
@click.option("--run", "run_name", default=None, metavar="NAME",
              help="The run to export [default: the file's only run].")
@click.option("--trial", default=None, type=click.Path(dir_okay=False),
              help="For --format c3d: the C3D the run was solved from [default: the path "
                   "recorded in the results file].")
@click.option("-o", "--output", default=None, type=click.Path(dir_okay=False),
              help="The file to write [default: RESULTS with the format's suffix, "
                   "RESULTS.<run>.<format> when the file holds several runs].")
@reports_input_errors
def export(results: str, fmt: str, convention: str, run_name: str | None, trial: str | None,
           output: str | None) -> None:
    """Export a run of a results file for OpenSim, pandas, spreadsheets, Mokka, Nexus or
    Visual3D, times on the trial's own clock (its first frame's time). Frames the quality
    checks do not trust keep their values and are counted (the CSV's trusted column, the
    header's untrustedFrames, the C3D's FCCGRB:UNTRUSTED)."""
    from fccgrb_cli.core.atomic import check_target
    from fccgrb_cli.results.export import choose_run, default_output
    from fccgrb_cli.results.export import export as write
    from fccgrb_cli.results.runs import read_runs

    runs = read_runs(results)
    run = choose_run(runs, run_name, results)
    target = Path(output) if output is not None else default_output(results, run, fmt, list(runs))
    refuse_inputs(target, [results, trial or run.trial_path])
    check_target(target)
    replaced = write(run, fmt, target, trial, convention)
    if replaced:
        click.echo(f"fccgrb: {replaced} points of the trial with Plug-in Gait's names replaced "
                   "by the run's", err=True)
    untrusted = int((~run.trusted).sum())
    if untrusted:
        click.echo(f"fccgrb: warning: {untrusted} of {len(run.trusted)} frames of run "
                   f"{run.name!r} are not trusted (exported with their values, marked)",
                   err=True)
    click.echo(f"wrote {target}: run {run.name!r}, {len(run.trusted)} frames, {fmt}")


@main.command()
@click.argument("source")
@click.option("--run", "runs", multiple=True, metavar="NAME",
              help="A run to draw; give two to overlay them (e.g. nrm-wls against cno-sqp) "
                   "[default: the file's runs, when it holds one or two].")
@click.option("--frame", type=int, default=None,
              help="For an .svg output: the frame index of the still picture.")
@click.option("--camera", type=click.Choice(["sagittal", "frontal", "transverse", "orbit"]),
              default="orbit", show_default=True,
              help="The camera the page opens on and the still is seen from.")
@click.option("--curve", default=None, metavar="ANGLE",
              help="The angle drawn under the motion with its joint moment [default: the "
                   "first angle with a clinical sign, else the first].")
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False),
              help="The page (.html, one self-contained file) or a still picture (.svg).")
@reports_input_errors
def view(source: str, runs: tuple[str, ...], frame: int | None, camera: str,
         curve: str | None, output: str) -> None:
    """See a results file's runs move in 3D (the model, markers, plate forces, flags, a curve
    on a timeline), or a model file in its initial pose, labelled."""
    from fccgrb_cli.view.command import view as write_view

    click.echo(write_view(source, output, runs, frame, camera, curve))

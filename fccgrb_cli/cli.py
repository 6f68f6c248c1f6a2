"""The ``fccgrb`` command: thin wrappers over the library; bad input → one line, exit status 2."""

from __future__ import annotations

import functools
import sys
from collections.abc import Callable
from pathlib import Path

import click
import numpy as np

from fccgrb_cli import __version__
from fccgrb_cli.errors import InputError
from fccgrb_cli.model import Model, load_model
from fccgrb_cli.progress import Progress
from fccgrb_cli.system.structure import analyse

FORM = click.Choice(["model", "full", "reduced"])


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


def load_checked(path: str, form: str = "model") -> Model:
    """Load a model, apply a body-form override, and check that it determines its coordinates."""
    model = load_model(path)
    if form != "model":
        model = model.with_form(form)
    analyse(model)
    return model


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
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
    """Validate MODEL and report its coordinates, rank and redundant constraints."""
    loaded = load_model(model)
    if form != "model":
        loaded = loaded.with_form(form)
    report = analyse(loaded)
    click.echo(f"{model}: model {loaded.name!r} is valid")
    for line in report.lines():
        click.echo(f"  {line}")


@main.command()
@click.argument("model")
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False),
              help="Trial to write (C3D). The true angles go to OUTPUT's stem + '.truth.h5'.")
@click.option("--duration", type=click.FloatRange(min=0, min_open=True), default=3.0,
              show_default=True, help="Length of the trial in seconds.")
@click.option("--rate", type=click.FloatRange(min=0, min_open=True), default=100.0,
              show_default=True, help="Marker sampling rate in Hz.")
@click.option("--units", type=click.Choice(["mm", "m"]), default="mm", show_default=True,
              help="Length unit of the C3D points (POINT:UNITS).")
@click.option("--form", type=FORM, default="model", show_default=True,
              help="Body form used for the analysis (the points do not depend on it).")
@click.option("--tol", type=click.FloatRange(min=0, min_open=True), default=1e-10,
              show_default=True, help="Newton–Raphson tolerance on ‖Δq‖∞ (m and unitless).")
@reports_input_errors
def synth(model: str, output: str, duration: float, rate: float, units: str, form: str,
          tol: float) -> None:
    """Synthesize a trial: drive MODEL with its prescribed angles (kinematic analysis with
    angular drivers) and write its tracked points to a C3D file, with the exact angles, rates
    and points in a truth file beside it."""
    from fccgrb_cli.io.c3d import write_markers
    from fccgrb_cli.io.truth import Truth, truth_path, write_truth
    from fccgrb_cli.synth import synthesize

    loaded = load_checked(model, form)
    if not loaded.tracked_points:
        raise InputError(f"{model}: tracking.points: expected at least one tracked point to write")
    s = synthesize(loaded, duration, rate, tol, progress=Progress("synth"))
    r = s.result
    write_markers(output, list(s.labels), s.markers, rate, units,
                  description=f"fccgrb {__version__} synth {Path(model).name}")
    sidecar = truth_path(output)
    write_truth(sidecar, Truth(
        time=r.time, theta=r.theta, theta_d=r.theta_d, theta_dd=r.theta_dd,
        angle_names=r.angle_names, q=r.q, form=",".join(sorted(set(s.system.layout.forms))),
        markers=s.markers, labels=s.labels, rate=rate, model_text=loaded.text))
    click.echo(f"wrote {output}: {r.n_frames} frames at {rate:g} Hz, {len(s.labels)} markers "
               f"({units}); truth in {sidecar}")
    click.echo(f"AD analysis: {r.iterations.mean():.2f} iterations/frame, "
               f"{1e3 * r.time_s.mean():.3f} ms/frame, max ‖Φ‖ {r.phi_norm.max():.2e}, "
               f"angles {np.degrees(r.theta.min()):.1f}..{np.degrees(r.theta.max()):.1f} deg")

"""HDF5 results, written atomically (a temporary copy, then a rename); ``results.runs`` reads them
back.

Contract (SI units: m, rad, s):
  root attributes: ``model`` (YAML text), ``command`` (the command line), ``versions`` (JSON of
      package versions), ``trial`` (path)
  /reference/markers   frames × markers × 3, m; attributes ``labels`` (model marker names),
                       ``rate`` (Hz). The exact markers of a synthesized trial's truth file when
                       there is one, else the trial's markers as read (NaN in gaps).
  /truth/theta         frames × angles, rad (only for synthesized trials); attribute ``names``
  /runs/<name>/        attributes ``method``, ``tol``, ``perturb_level_m``, ``perturb_markers``,
                       ``perturb_seed``, ``tracking_weight`` (NaN for LS), ``warm_start``,
                       ``hessian``, ``form``, ``ad_drivers`` (AD runs), ``command``,
                       ``wall_s`` (the solve's wall-clock time in parallel mode, else NaN),
                       ``filter_cutoff_hz`` (the angles' low-pass, NaN when unfiltered: the
                       AD baseline's drivers, and the angles converted for the dynamics),
                       ``warnings`` (every warning the run printed: frames flagged or not
                       converged and why, a truncated trial accepted, …; empty when none),
                       the lab's axes (``fccgrb_cli.anatomy.lab_axes``): ``vertical`` (the axis up,
                       '+z'), ``gravity`` (m/s², what the dynamics used), ``vertical_chosen_by``
                       ('ground', 'model', 'option' or 'file'), ``vertical_why`` (the cues),
                       ``up`` and ``walking`` (unit vectors; NaN when not walking),
                       ``start_time_s`` (the first frame's time on the trial's clock; the
                       datasets' times count from it)
      q, qd, qdd                 frames × nq
      theta, theta_d, theta_dd   frames × angles; attributes ``names`` and ``units`` (per column:
                                 rad, or m for a distance coordinate; per s, per s²)
      model_points               frames × markers × 3, same marker order as /reference/markers
      markers_input              frames × markers × 3, the (perturbed) markers the solver saw
      iterations, time_s, phi_norm, phi_top_max   per frame
      converged                  per frame: True only where the solver converged AND no quality
                                 check flagged the frame (a frame on another assembly branch, a
                                 jump, a broken topology is never counted as converged)
      solver_converged           per frame, the solver's own verdict
      flags                      per frame, why it is not trusted: a bit mask (uint16; files of
                                 format 2 written before had uint8 and three bits) whose bits are
                                 the attributes (unconverged 1, topology 2, jump 4, no_data 8,
                                 singular 16, branch 32, angle_range 64, poor_fit 128,
                                 calibration 256; 0 = trusted), and attribute ``bits``: JSON, per
                                 bit its name, value, meaning, how many frames carry it, the
                                 first, and this run's explanation (README, "What fccgrb checks
                                 for you";
                                 see fccgrb_cli/solvers/quality.py)
      status                     per frame, the optimizer's own message (optimizers only)
      ed, ed_input               frames × markers: distance of each model point to the
                                 reference marker and to the input marker, m
    with inverse dynamics:
      moment_flags               frames × angles, why each joint moment is not trusted where
                                 its frame may be (bits as attributes and ``bits`` as for
                                 ``flags``: kinematics 1, no_dynamics 2, contact 4,
                                 noisy_rates 8; solvers/quality.py MOMENT_BITS); 0 = trusted
      joint_moments              frames × angles, N·m (N for a distance: attribute ``units``),
                                 conjugate to θ (τ_k = λ_k sin θ_k; −λ_k for a distance);
                                 attribute ``names``
      lambda                     frames × equations of the classical model; attribute ``labels``
      classical/q, qd, qdd, theta, theta_d, theta_dd   the classical model driven by θ(t)
      classical/flags            per frame, ``branch`` (32) where it was not solved from the
                                 mixed solution's configuration
      energy/kinetic, potential, external_power        J, J, W (a power-balance check)
      residual_force, residual_moment                  frames × floating bases × 3: what the
                                 base drivers apply (N; N·m about the base origin); attribute
                                 ``bases``
      loads/<name>/force, point, moment, body          external loads used (N, m, N·m)
    with angles declaring a clinical sign (see fccgrb_cli.anatomy.clinical):
      clinical/angles            frames × clinical angles, deg; attributes ``names``,
                                 ``contact`` (the contact body beyond each joint, or "")
      clinical/moments           frames × clinical angles, N·m, conjugate to them (with the
                                 dynamics); clinical/moments_per_kg, N·m/kg (attribute ``mass``)
      clinical/moments_trusted   frames × clinical angles: the moment trusted (its frame and
                                 its own checks, as ``moment_flags``)
      clinical/stance/<body>     per frame, True while a force plate loads that body
    with a model calibrated as Plug-in Gait, its outputs in Plug-in Gait's names and units
    (fccgrb_cli.results.plugin_gait): plugin_gait/angles, moments, powers;
    with one floating base and the dynamics: residuals/ (the residual over the frames where
    every ground contact is measured) and, with --reduce-residuals, the first model's residual
    and the reduction (layout in fccgrb_cli.results.residuals)
Arrays of 64 KiB or more are stored chunked and gzip-compressed (``fccgrb_cli.core.datasets``):
a long trial is written and read a chunk at a time; any HDF5 reader decodes them.

Writing: the runs of one command go into the file together, under the file's lock
(``core.lock``: two solves into one file never drop a run), into a copy renamed into place
(``core.atomic``: all of them or none, the old file intact on any error), through
``core.hdf5_writer`` (a full disk is an error, not HDF5's crash).
"""

from __future__ import annotations

import json
import shutil
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from fccgrb_cli.anatomy.clinical import ClinicalResults
from fccgrb_cli.anatomy.lab_axes import LabAxes
from fccgrb_cli.core.atomic import atomic_path, check_target
from fccgrb_cli.core.datasets import put as put_array
from fccgrb_cli.core.errors import InputError
from fccgrb_cli.core.hdf5_writer import writing
from fccgrb_cli.core.inputs import check_name, regular_file
from fccgrb_cli.core.lock import exclusive
from fccgrb_cli.core.spill import StoredArray
from fccgrb_cli.results.format import FORMAT_VERSION, check_run, reading, runs_group
from fccgrb_cli.results.gait import write_gait, write_subject
from fccgrb_cli.results.residuals import write_residuals
from fccgrb_cli.solvers.quality import BITS, FLAG_DTYPE, FRAME_BITS, MOMENT_BITS, bit_summary

if TYPE_CHECKING:
    from fccgrb_cli.dynamics.convert import Dynamics
    from fccgrb_cli.pipeline.run import Run
    from fccgrb_cli.pipeline.smoothing import Uncertainty

PACKAGES = {"fccgrb-cli": "fccgrb_cli", "numpy": "numpy", "scipy": "scipy", "h5py": "h5py",
            "ezc3d": "ezc3d", "click": "click", "pyyaml": "yaml"}


def versions() -> dict[str, str]:
    """The versions of the packages a results file was made with: a loaded module's own
    ``__version__``; for one this run did not import (scipy, whose LAPACK is loaded by file:
    fccgrb_cli.core.blas), the version in its installed dist-info folder's name. importlib.metadata
    gives the same, but importing it takes ~30 ms, a twentieth of the sample's whole solve."""
    import sys

    out = {}
    for name, module in PACKAGES.items():
        loaded = sys.modules.get(module)
        # click ≥ 8.2 deprecates click.__version__ (a warning on every solve): its dist-info
        version = getattr(loaded, "__version__", None) if module != "click" else None
        out[name] = version if isinstance(version, str) else _installed_version(name, module)
    return out


def _installed_version(name: str, module: str) -> str:
    from importlib.util import find_spec

    spec = find_spec(module)
    if spec is not None and spec.origin is not None:
        prefix = name.replace("-", "_")
        for info in Path(spec.origin).parent.parent.glob("*.dist-info"):
            stem = info.name[: -len(".dist-info")]
            dist, _, version = stem.rpartition("-")
            if dist.lower().replace("-", "_") == prefix.lower():
                return version
    from importlib.metadata import PackageNotFoundError
    from importlib.metadata import version as installed

    try:
        return installed(name)
    except PackageNotFoundError:
        return "unknown"


def check_output(path: str | Path) -> None:
    """An InputError unless ``path`` is absent or a results file of this format whose every run
    reads back (``fccgrb solve`` asks before solving, so that a long solve is not lost to an
    output it cannot write, and a damaged file is not extended into one ``report`` refuses)."""
    import h5py

    path = Path(path)
    if not path.exists() and not path.is_symlink():
        return
    regular_file(path, "results file")
    try:
        with h5py.File(path, "r") as h5:
            version = h5.attrs.get("format_version")
            if version is None and "runs" not in h5:
                raise InputError(f"{path}: exists and is not an fccgrb results file; choose "
                                 "another output")
            if version != FORMAT_VERSION:
                raise InputError(f"{path}: written in results format {version or 1}, this "
                                 f"fccgrb writes format {FORMAT_VERSION}; choose another output")
            for name, run in runs_group(h5, path).items():  # every run readable
                with reading(path, f"/runs/{name}"):
                    check_run(run, path, f"/runs/{name}")
    except OSError:
        raise InputError(f"{path}: exists and is not an HDF5 results file; "
                         "choose another output") from None


def write_run(path: str | Path, run: Run, command: str, cell: dict | None = None) -> None:
    """Add (or replace) one run in the results file, creating it when absent; ``cell`` (a sweep
    cell's parameters) is kept as the root attribute ``cell`` (JSON). Arrays the run holds in a
    Spill (``core.spill``) are copied from it as stored, and read from the results file after."""
    write_runs(path, [run], command, cell=cell)


def write_runs(path: str | Path, runs: list[Run], command: str, *, cell: dict | None = None,
               subject: tuple[list[str], dict] | None = None,
               waiting: Callable[[str], None] | None = None, replace: bool = True) -> None:
    """Add ``runs`` to the results file (replacing runs of the same names only with
    ``replace``: otherwise such a run is an InputError naming it and the command that made it,
    and nothing is written), and ``subject`` (the run names and their pooled cycles:
    ``/subject``), all in one write: every run lands or none does. Waits for another writer of
    the same file (``waiting`` is told); the names are checked under its lock."""
    path = check_target(path)
    for run in runs:
        check_name(run.name, "run name")
    with exclusive(path, waiting=waiting), atomic_path(path) as tmp:
        mode = "w"
        if path.exists():
            check_output(path)
            if not replace:
                refuse_taken_names(path, [run.name for run in runs])
            shutil.copyfile(path, tmp)
            mode = "r+"
        with writing(tmp, mode) as h5:
            for run in runs:
                _write_run(h5, run, command, cell)
            if subject is not None:
                write_subject(h5, *subject)
    for run in runs:
        for spill in {stored.spill for stored in _stored(run)}:
            spill.settled(path, f"/runs/{run.name}")


def refuse_taken_names(path: Path, names: list[str]) -> None:
    """An InputError when the results file at ``path`` already holds a run of one of
    ``names``, naming it and the command that made it (a second solve never replaces the
    first unless asked to)."""
    import h5py

    with h5py.File(path, "r") as h5:
        runs = h5.get("runs", {})
        taken = [name for name in names if name in runs]
        if taken:
            made = str(runs[taken[0]].attrs.get("command", "?"))
            raise InputError(f"{path}: already holds the run {taken[0]!r} (made by: {made}); "
                             "--name NAME for another run beside it, or --replace to replace it")


def _write_run(h5, run: Run, command: str, cell: dict | None) -> None:
    import h5py

    h5.attrs["format_version"] = FORMAT_VERSION
    h5.attrs["model"] = run.model_text
    h5.attrs["command"] = command
    h5.attrs["versions"] = json.dumps(versions())
    h5.attrs["trial"] = run.trial_path
    if cell is not None:
        h5.attrs["cell"] = json.dumps(cell, sort_keys=True, default=str)
    if "reference" in h5:
        del h5["reference"]
    ref = h5.create_group("reference")
    put(ref, "markers", run.reference)
    ref["markers"].attrs["labels"] = list(run.labels)
    ref["markers"].attrs["rate"] = run.rate
    if run.truth_theta is not None:
        if "truth" in h5:
            del h5["truth"]
        put(h5.create_group("truth"), "theta", run.truth_theta)
        h5["truth/theta"].attrs["names"] = list(run.result.angle_names)
    runs = h5.require_group("runs")
    if run.name in runs:
        del runs[run.name]
    g = runs.create_group(run.name)
    r = run.result
    g.attrs.update({
        "method": r.method, "tol": r.tol, "perturb_level_m": run.perturb_level_m,
        "perturb_markers": list(run.perturb_markers), "perturb_seed": run.perturb_seed,
        "tracking_weight": np.nan if run.tracking_weight is None else run.tracking_weight,
        "warm_start": run.warm_start, "hessian": run.hessian, "form": run.form,
        "ad_drivers": run.ad_drivers, "command": command, "wall_s": r.wall_s,
        "filter_cutoff_hz": np.nan if run.filter_cutoff is None else run.filter_cutoff,
    })
    text = h5py.string_dtype(encoding="utf-8")
    g.attrs.create("warnings", [*r.messages, *run.warnings], dtype=text)
    g.attrs.create("messages", list(r.messages), dtype=text)
    g.attrs.create("notes", list(run.notes), dtype=text)
    if run.axes is not None:
        _write_axes(g, run.axes)
    g.attrs.update({"options": run.options.to_json(), "model": run.model_text,
                    "trial": run.trial_path, "rate": run.rate,
                    "labels": list(run.labels), "start_time_s": run.start_time})
    put(g, "time", r.time)
    put(g, "reference", run.reference)
    if run.truth_theta is not None:
        put(g, "truth_theta", run.truth_theta)
    for key in ("q", "qd", "qdd", "iterations", "time_s", "phi_norm", "phi_top_max"):
        put(g, key, getattr(r, key))
    put(g, "converged", r.trusted)
    put(g, "solver_converged", r.converged)
    flags = r.flags if r.flags is not None else np.zeros(r.n_frames, FLAG_DTYPE)
    put(g, "flags", flags.astype(FLAG_DTYPE))
    g["flags"].attrs.update(BITS)
    g["flags"].attrs["bits"] = bit_summary(FRAME_BITS, flags)
    for key, per in (("theta", ""), ("theta_d", "/s"), ("theta_dd", "/s²")):
        put(g, key, getattr(r, key))
        g[key].attrs["names"] = list(r.angle_names)
        g[key].attrs.create("units", [u + per for u in run.angle_units], dtype=text)
    for key in ("model_points", "markers_input", "ed", "ed_input"):
        put(g, key, getattr(run, key))
    if r.status:
        g.create_dataset("status", data=list(r.status),
                         dtype=h5py.string_dtype(encoding="utf-8"))
    if run.dynamics is not None:
        _write_dynamics(g, run, run.dynamics)
    if run.clinical is not None:
        _write_clinical(g, run.clinical)
    if run.uncertainty is not None:
        _write_uncertainty(g, run, run.uncertainty)
    if run.gait is not None:
        write_gait(g, run.gait)
    if run.plugin_gait is not None:  # its module loads with a Plug-in Gait run only
        from fccgrb_cli.results.plugin_gait import write_plugin_gait

        write_plugin_gait(g, run.plugin_gait)
    if run.residuals is not None:
        write_residuals(g, run.residuals, run.reduction)


def _write_axes(g, axes: LabAxes) -> None:
    g.attrs.update({"vertical": axes.vertical, "gravity": np.asarray(axes.gravity),
                    "vertical_chosen_by": axes.chosen_by, "vertical_why": axes.why,
                    "up": axes.up,
                    "walking": np.full(3, np.nan) if axes.forward is None else axes.forward})


def put(group, key: str, values) -> None:
    """``core.datasets.put``, or for an array held in a Spill its stored dataset as it is."""
    if isinstance(values, StoredArray):
        values.copy_to(group, key)
    else:
        put_array(group, key, values)


def _stored(run: Run) -> list[StoredArray]:
    """The run's arrays held in a Spill."""
    holders = [run, run.result]
    if run.dynamics is not None:
        holders += [run.dynamics.kinematics, run.dynamics.inverse]
    return [value for holder in holders for value in vars(holder).values()
            if isinstance(value, StoredArray)]


def _write_clinical(g, c: ClinicalResults) -> None:
    out = g.create_group("clinical")
    put(out, "angles", c.angles)
    out["angles"].attrs.update({"names": list(c.names), "units": "deg",
                                "contact": [b or "" for b in c.contact]})
    if c.moments is not None:
        put(out, "moments", c.moments)
        out["moments"].attrs.update({"names": list(c.names), "units": "N·m"})
    if c.moments_trusted is not None:
        put(out, "moments_trusted", c.moments_trusted)
        out["moments_trusted"].attrs["names"] = list(c.names)
    if c.moments_per_kg is not None:
        put(out, "moments_per_kg", c.moments_per_kg)
        out["moments_per_kg"].attrs.update({"names": list(c.names), "units": "N·m/kg",
                                            "mass": c.mass})
    stance = out.create_group("stance")
    for body, frames in c.stance.items():
        put(stance, body, frames)


def _write_uncertainty(g, run: Run, u: Uncertainty) -> None:
    """/runs/<name>/uncertainty: the standard deviations of every angle, its rate and
    acceleration and its joint moment (frames × angles), and how the smoother was set."""
    import h5py

    text = h5py.string_dtype(encoding="utf-8")
    out = g.create_group("uncertainty")
    out.attrs.update({"noise_m": u.noise_m, "estimated": u.estimated,
                      "seconds": u.seconds, "cutoffs_hz": u.cutoffs_hz,
                      "extra_sd": u.extra_sd})
    out.attrs.create("coordinates", list(u.coordinates), dtype=text)
    units = run.angle_units
    forces = ["N" if unit == "m" else "N·m" for unit in units]
    for key, per in (("theta_sd", list(units)), ("theta_d_sd", [f"{u_}/s" for u_ in units]),
                     ("theta_dd_sd", [f"{u_}/s²" for u_ in units]), ("moments_sd", forces)):
        values = getattr(u, key)
        if values is None:
            continue
        put(out, key, values)
        out[key].attrs["names"] = list(run.result.angle_names)
        out[key].attrs.create("units", per, dtype=text)


def _write_dynamics(g, run: Run, d: Dynamics) -> None:
    import h5py

    inverse, kin = d.inverse, d.kinematics
    put(g, "joint_moments", inverse.joint_moments)
    g["joint_moments"].attrs["names"] = list(inverse.angle_names)
    if run.moment_flags is not None:
        put(g, "moment_flags", run.moment_flags.astype(FLAG_DTYPE))
        g["moment_flags"].attrs.update({bit.name: bit.value for bit in MOMENT_BITS})
        g["moment_flags"].attrs["bits"] = bit_summary(MOMENT_BITS, run.moment_flags)
        g["moment_flags"].attrs["names"] = list(inverse.angle_names)
    g["joint_moments"].attrs.create(
        "units", ["N" if u == "m" else "N·m" for u in run.angle_units],
        dtype=h5py.string_dtype(encoding="utf-8"))
    put(g, "lambda", inverse.lam)
    g["lambda"].attrs["labels"] = list(inverse.row_labels)
    put(g, "joint_residual", inverse.residual)
    classical = g.create_group("classical")
    classical.attrs.update({"method": kin.method, "tol": kin.tol,
                            "cutoff_hz": np.nan if d.cutoff is None else d.cutoff})
    for key in ("q", "qd", "qdd", "theta", "theta_d", "theta_dd", "iterations", "time_s",
                "phi_norm", "phi_top_max", "converged"):
        put(classical, key, getattr(kin, key))
    if kin.flags is not None:  # the frames solved away from the mixed solution (branch)
        put(classical, "flags", kin.flags)
    if inverse.base_names:
        for key in ("residual_force", "residual_moment"):
            put(g, key, getattr(inverse, key))
            g[key].attrs["bases"] = list(inverse.base_names)
        g["residual_force"].attrs["units"] = "N"
        g["residual_moment"].attrs["units"] = "N·m, about the base's origin"
    energy = g.create_group("energy")
    for key in ("kinetic", "potential", "external_power"):
        put(energy, key, getattr(inverse, key))
    loads = g.create_group("loads")
    for load in d.loads:
        item = loads.create_group(load.name)
        item.attrs["body"] = load.body
        for key in ("force", "point", "moment"):
            put(item, key, getattr(load, key))



"""HDF5 results, written atomically (a temporary copy, then a rename); ``io.runs`` reads them
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
                       converged and why, a truncated trial accepted, …; empty when none)
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
      flags                      per frame, why it is not trusted: a bit mask whose bits are the
                                 attributes (unconverged 1, topology 2, jump 4; 0 = trusted;
                                 see fccgrb_cli/solvers/quality.py)
      status                     per frame, the optimizer's own message (optimizers only)
      ed, ed_input               frames × markers: distance of each model point to the
                                 reference marker and to the input marker, m
    with inverse dynamics:
      joint_moments              frames × angles, N·m (N for a distance: attribute ``units``),
                                 conjugate to θ (τ_k = λ_k sin θ_k; −λ_k for a distance);
                                 attribute ``names``
      lambda                     frames × equations of the classical model; attribute ``labels``
      classical/q, qd, qdd, theta, theta_d, theta_dd   the classical model driven by θ(t)
      energy/kinetic, potential, external_power        J, J, W (a power-balance check)
      residual_force, residual_moment                  frames × floating bases × 3: what the
                                 base drivers apply (N; N·m about the base origin); attribute
                                 ``bases``
      loads/<name>/force, point, moment, body          external loads used (N, m, N·m)
    with angles declaring a clinical sign (see fccgrb_cli.clinical):
      clinical/angles            frames × clinical angles, deg; attributes ``names``,
                                 ``contact`` (the contact body beyond each joint, or "")
      clinical/moments           frames × clinical angles, N·m, conjugate to them (with the
                                 dynamics); clinical/moments_per_kg, N·m/kg (attribute ``mass``)
      clinical/stance/<body>     per frame, True while a force plate loads that body
    with one floating base and the dynamics: residuals/ (the residual over the frames where
    every ground contact is measured) and, with --reduce-residuals, the first model's residual
    and the reduction (layout in fccgrb_cli.io.residual_results)
Arrays of 64 KiB or more are stored chunked and gzip-compressed (``fccgrb_cli.io.datasets``):
a long trial is written and read a chunk at a time; any HDF5 reader decodes them.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from fccgrb_cli.clinical import ClinicalResults
from fccgrb_cli.errors import InputError
from fccgrb_cli.io.atomic import atomic_path
from fccgrb_cli.io.datasets import put as put_array
from fccgrb_cli.io.gait_results import write_gait
from fccgrb_cli.io.residual_results import write_residuals
from fccgrb_cli.io.spill import StoredArray
from fccgrb_cli.solvers.quality import BITS

if TYPE_CHECKING:
    from fccgrb_cli.run import Run  # the Run writes itself here (Run.to_hdf5)

FORMAT_VERSION = 2


PACKAGES = {"fccgrb-cli": "fccgrb_cli", "numpy": "numpy", "scipy": "scipy", "h5py": "h5py",
            "ezc3d": "ezc3d", "click": "click", "pyyaml": "yaml"}


def versions() -> dict[str, str]:
    """The versions of the packages a results file was made with: a loaded module's own
    ``__version__``; for one this run did not import (scipy, whose LAPACK is loaded by file:
    fccgrb_cli.blas), the version in its installed dist-info folder's name. importlib.metadata
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
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version(name)
    except PackageNotFoundError:
        return "unknown"


def check_output(path: str | Path) -> None:
    """An InputError unless ``path`` is absent or a results file of this format (``fccgrb solve``
    asks before solving, so that a long solve is not lost to an output it cannot write)."""
    import h5py

    path = Path(path)
    if not path.exists():
        return
    try:
        with h5py.File(path, "r") as h5:
            version = h5.attrs.get("format_version", FORMAT_VERSION)
    except OSError:
        raise InputError(f"{path}: exists and is not an HDF5 results file; "
                         "choose another output") from None
    if version != FORMAT_VERSION:
        raise InputError(f"{path}: written in results format {version}, this fccgrb writes "
                         f"format {FORMAT_VERSION}; choose another output")


def write_run(path: str | Path, run: Run, command: str, cell: dict | None = None) -> None:
    """Add (or replace) one run in the results file, creating it when absent; ``cell`` (a sweep
    cell's parameters) is kept as the root attribute ``cell`` (JSON). Arrays the run holds in a
    Spill (``io.spill``) are copied from it as stored, and read from the results file after."""
    import h5py

    path = Path(path)
    with atomic_path(path) as tmp:
        if path.exists():
            check_output(path)
            shutil.copyfile(path, tmp)
        with h5py.File(tmp, "a") as h5:
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
            g.attrs.update({"options": run.options.to_json(), "model": run.model_text,
                            "trial": run.trial_path, "rate": run.rate,
                            "labels": list(run.labels)})
            put(g, "time", r.time)
            put(g, "reference", run.reference)
            if run.truth_theta is not None:
                put(g, "truth_theta", run.truth_theta)
            for key in ("q", "qd", "qdd", "iterations", "time_s", "phi_norm", "phi_top_max"):
                put(g, key, getattr(r, key))
            put(g, "converged", r.trusted)
            put(g, "solver_converged", r.converged)
            put(g, "flags", r.flags if r.flags is not None else np.zeros(r.n_frames, np.uint8))
            g["flags"].attrs.update(BITS)
            for key, per in (("theta", ""), ("theta_d", "/s"), ("theta_dd", "/s²")):
                put(g, key, getattr(r, key))
                g[key].attrs["names"] = list(r.angle_names)
                g[key].attrs.create("units", [u + per for u in run._angle_units], dtype=text)
            for key in ("model_points", "markers_input", "ed", "ed_input"):
                put(g, key, getattr(run, key))
            if r.status:
                g.create_dataset("status", data=list(r.status),
                                 dtype=h5py.string_dtype(encoding="utf-8"))
            if run.dynamics is not None:
                _write_dynamics(g, run)
            if run.clinical is not None:
                _write_clinical(g, run.clinical)
            if run.gait is not None:
                write_gait(g, run.gait)
            if run.residuals is not None:
                write_residuals(g, run.residuals, run.reduction)
    for spill in {stored.spill for stored in _stored(run)}:
        spill.settled(path, f"/runs/{run.name}")


def put(group, key: str, values) -> None:
    """``io.datasets.put``, or for an array held in a Spill its stored dataset as it is."""
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
    if c.moments_per_kg is not None:
        put(out, "moments_per_kg", c.moments_per_kg)
        out["moments_per_kg"].attrs.update({"names": list(c.names), "units": "N·m/kg",
                                            "mass": c.mass})
    stance = out.create_group("stance")
    for body, frames in c.stance.items():
        put(stance, body, frames)


def _write_dynamics(g, run: Run) -> None:
    import h5py

    d = run.dynamics
    inverse, kin = d.inverse, d.kinematics
    put(g, "joint_moments", inverse.joint_moments)
    g["joint_moments"].attrs["names"] = list(inverse.angle_names)
    g["joint_moments"].attrs.create(
        "units", ["N" if u == "m" else "N·m" for u in run._angle_units],
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



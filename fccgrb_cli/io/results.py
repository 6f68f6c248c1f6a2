"""HDF5 results, written atomically (a temporary copy, then a rename).

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
      theta, theta_d, theta_dd   frames × angles; attribute ``names``
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
      joint_moments              frames × angles, N·m, conjugate to θ (τ_k = λ_k sin θ_k);
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
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np

from fccgrb_cli.clinical import ClinicalResults
from fccgrb_cli.errors import InputError
from fccgrb_cli.io.atomic import atomic_path
from fccgrb_cli.pipeline import Run
from fccgrb_cli.solvers.quality import BITS


def open_results(path: str | Path):
    """An existing results or sweep file, read-only (h5py.File); one-line errors otherwise."""
    import h5py

    path = Path(path)
    if not path.exists():
        raise InputError(f"{path}: results file not found")
    try:
        return h5py.File(path, "r")
    except OSError:
        raise InputError(f"{path}: not an HDF5 results file") from None


def _versions() -> dict[str, str]:
    from importlib.metadata import PackageNotFoundError, version

    out = {}
    for name in ("fccgrb-cli", "numpy", "scipy", "h5py", "ezc3d", "click", "pyyaml"):
        try:
            out[name] = version(name)
        except PackageNotFoundError:
            out[name] = "unknown"
    return out


def write_run(path: str | Path, run: Run, command: str, cell: dict | None = None) -> None:
    """Add (or replace) one run in the results file, creating it when absent; ``cell`` (a sweep
    cell's parameters) is kept as the root attribute ``cell`` (JSON)."""
    import h5py

    path = Path(path)
    with atomic_path(path) as tmp:
        if path.exists():
            try:
                with h5py.File(path, "r"):
                    pass
            except OSError:
                raise InputError(f"{path}: exists and is not an HDF5 results file; "
                                 "choose another output") from None
            shutil.copyfile(path, tmp)
        with h5py.File(tmp, "a") as h5:
            h5.attrs["model"] = run.model_text
            h5.attrs["command"] = command
            h5.attrs["versions"] = json.dumps(_versions())
            h5.attrs["trial"] = run.trial_path
            if cell is not None:
                h5.attrs["cell"] = json.dumps(cell, sort_keys=True, default=str)
            if "reference" in h5:
                del h5["reference"]
            ref = h5.create_group("reference")
            ref["markers"] = run.reference
            ref["markers"].attrs["labels"] = list(run.labels)
            ref["markers"].attrs["rate"] = run.rate
            if run.truth_theta is not None:
                if "truth" in h5:
                    del h5["truth"]
                h5.create_group("truth")["theta"] = run.truth_theta
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
            g.attrs.create("warnings", [*r.messages, *run.warnings],
                           dtype=h5py.string_dtype(encoding="utf-8"))
            for key in ("q", "qd", "qdd", "iterations", "time_s", "phi_norm", "phi_top_max"):
                g.create_dataset(key, data=getattr(r, key), compression="gzip")
            g["converged"] = r.trusted
            g["solver_converged"] = r.converged
            g["flags"] = r.flags if r.flags is not None else np.zeros(r.n_frames, np.uint8)
            g["flags"].attrs.update(BITS)
            for key in ("theta", "theta_d", "theta_dd"):
                g[key] = getattr(r, key)
                g[key].attrs["names"] = list(r.angle_names)
            for key in ("model_points", "markers_input", "ed", "ed_input"):
                g.create_dataset(key, data=getattr(run, key), compression="gzip")
            if r.status:
                g.create_dataset("status", data=list(r.status),
                                 dtype=h5py.string_dtype(encoding="utf-8"))
            if run.dynamics is not None:
                _write_dynamics(g, run)
            if run.clinical is not None:
                _write_clinical(g, run.clinical)


def _write_clinical(g, c: ClinicalResults) -> None:
    out = g.create_group("clinical")
    out["angles"] = c.angles
    out["angles"].attrs.update({"names": list(c.names), "units": "deg",
                                "contact": [b or "" for b in c.contact]})
    if c.moments is not None:
        out["moments"] = c.moments
        out["moments"].attrs.update({"names": list(c.names), "units": "N·m"})
    if c.moments_per_kg is not None:
        out["moments_per_kg"] = c.moments_per_kg
        out["moments_per_kg"].attrs.update({"names": list(c.names), "units": "N·m/kg",
                                            "mass": c.mass})
    stance = out.create_group("stance")
    for body, frames in c.stance.items():
        stance[body] = frames


def _write_dynamics(g, run: Run) -> None:
    d = run.dynamics
    inverse, kin = d.inverse, d.kinematics
    g.create_dataset("joint_moments", data=inverse.joint_moments)
    g["joint_moments"].attrs["names"] = list(inverse.angle_names)
    g["joint_moments"].attrs["units"] = "N·m"
    g.create_dataset("lambda", data=inverse.lam, compression="gzip")
    g["lambda"].attrs["labels"] = list(inverse.row_labels)
    classical = g.create_group("classical")
    for key in ("q", "qd", "qdd", "theta", "theta_d", "theta_dd"):
        classical.create_dataset(key, data=getattr(kin, key), compression="gzip")
    if inverse.base_names:
        for key in ("residual_force", "residual_moment"):
            g.create_dataset(key, data=getattr(inverse, key))
            g[key].attrs["bases"] = list(inverse.base_names)
        g["residual_force"].attrs["units"] = "N"
        g["residual_moment"].attrs["units"] = "N·m, about the base's origin"
    energy = g.create_group("energy")
    energy["kinetic"], energy["potential"] = inverse.kinetic, inverse.potential
    energy["external_power"] = inverse.external_power
    loads = g.create_group("loads")
    for load in d.loads:
        item = loads.create_group(load.name)
        item.attrs["body"] = load.body
        for key in ("force", "point", "moment"):
            item.create_dataset(key, data=getattr(load, key), compression="gzip")

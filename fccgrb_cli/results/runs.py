"""The runs of a results file (``results.storage`` writes them; the format is described there) read
back as the :class:`~fccgrb_cli.pipeline.run.Run` objects that wrote them."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from fccgrb_cli.anatomy.clinical import ClinicalResults
from fccgrb_cli.anatomy.lab_axes import LabAxes
from fccgrb_cli.core.datasets import open_results
from fccgrb_cli.core.errors import InputError
from fccgrb_cli.dynamics.convert import Dynamics
from fccgrb_cli.dynamics.inverse import InverseDynamics
from fccgrb_cli.dynamics.loads import ExternalLoad
from fccgrb_cli.pipeline.options import SolveOptions
from fccgrb_cli.pipeline.run import Run
from fccgrb_cli.pipeline.smoothing import Uncertainty
from fccgrb_cli.results.format import check_run, reading, runs_group
from fccgrb_cli.results.gait import read_gait
from fccgrb_cli.results.plugin_gait import read_plugin_gait
from fccgrb_cli.results.residuals import read_residuals
from fccgrb_cli.solvers.quality import FLAG_DTYPE
from fccgrb_cli.solvers.result import KinematicResult


def read_runs(path: str | Path) -> dict[str, Run]:
    """Every run of a results file as the Run that wrote it (see ``fccgrb_cli.read_results``);
    a file of another format version, or a sweep file, is a one-line error."""
    with open_results(path) as h5:
        if "runs" not in h5 and "cells" in h5:
            raise InputError(f"{path}: expected /runs in a results file (a sweep file's cells "
                             "are read by 'fccgrb report')")
        out = {}
        for name, g in runs_group(h5, path).items():
            with reading(path, f"/runs/{name}"):
                check_run(g, path, f"/runs/{name}")
                out[name] = _read_run(name, g)
        return out


def _strings(values) -> tuple[str, ...]:
    return tuple(v.decode() if isinstance(v, bytes) else str(v) for v in values)


def _read_result(g, angle_names: tuple[str, ...], time: np.ndarray, attrs: dict,
                 converged: np.ndarray, extra: dict) -> KinematicResult:
    return KinematicResult(
        method=str(attrs["method"]), tol=float(attrs["tol"]), time=time,
        **{key: g[key][()] for key in ("q", "qd", "qdd", "theta", "theta_d", "theta_dd",
                                       "iterations", "time_s", "phi_norm", "phi_top_max")},
        angle_names=angle_names, converged=converged, **extra)


def _read_run(name: str, g) -> Run:
    a = dict(g.attrs)
    names = _strings(g["theta"].attrs["names"])
    time = g["time"][()]
    messages = _strings(a["messages"])
    warnings = _strings(a["warnings"])[len(messages):]
    result = _read_result(g, names, time, a, g["solver_converged"][()], {
        "messages": messages, "wall_s": float(a["wall_s"]),
        "flags": g["flags"][()].astype(FLAG_DTYPE),  # uint8 in files written before 16 bits
        "status": _strings(g["status"][()]) if "status" in g else ()})
    residuals, reduction = read_residuals(g)
    return Run(
        name=name, options=SolveOptions.from_json(str(a["options"])), result=result,
        labels=_strings(a["labels"]), rate=float(a["rate"]), reference=g["reference"][()],
        markers_input=g["markers_input"][()], model_points=g["model_points"][()],
        ed=g["ed"][()], ed_input=g["ed_input"][()],
        truth_theta=g["truth_theta"][()] if "truth_theta" in g else None, form=str(a["form"]),
        model_text=str(a["model"]), trial_path=str(a["trial"]),
        dynamics=_read_dynamics(g, names, time) if "joint_moments" in g else None,
        warnings=warnings, notes=_strings(a["notes"]),
        clinical=_read_clinical(g["clinical"]) if "clinical" in g else None,
        gait=read_gait(g["gait"]) if "gait" in g else None,
        moment_flags=g["moment_flags"][()] if "moment_flags" in g else None,
        axes=_read_axes(a),
        uncertainty=_read_uncertainty(g["uncertainty"]) if "uncertainty" in g else None,
        plugin_gait=read_plugin_gait(g["plugin_gait"]) if "plugin_gait" in g else None,
        start_time=float(a.get("start_time_s", 0.0)), residuals=residuals,
        reduction=reduction)


def _read_axes(a: dict) -> LabAxes | None:
    """The run's lab axes (absent in files written before them)."""
    if "vertical" not in a:
        return None
    walking = np.asarray(a["walking"], dtype=float)
    gx, gy, gz = (float(x) for x in a["gravity"])
    return LabAxes(str(a["vertical"]), np.asarray(a["up"], dtype=float), (gx, gy, gz),
                   str(a["vertical_chosen_by"]),
                   str(a["vertical_why"]), None if np.isnan(walking).any() else walking)


def _read_uncertainty(u) -> Uncertainty:
    a = u.attrs
    return Uncertainty(
        theta_sd=u["theta_sd"][()], theta_d_sd=u["theta_d_sd"][()],
        theta_dd_sd=u["theta_dd_sd"][()],
        moments_sd=u["moments_sd"][()] if "moments_sd" in u else None,
        noise_m=float(a["noise_m"]), coordinates=_strings(a["coordinates"]),
        cutoffs_hz=np.asarray(a["cutoffs_hz"], dtype=float),
        extra_sd=np.asarray(a["extra_sd"], dtype=float), estimated=bool(a["estimated"]),
        seconds=float(a["seconds"]))


def _read_dynamics(g, names: tuple[str, ...], time: np.ndarray) -> Dynamics:
    c = g["classical"]
    cutoff = float(c.attrs["cutoff_hz"])
    kinematics = _read_result(c, names, time, dict(c.attrs), c["converged"][()],
                              {"flags": c["flags"][()]} if "flags" in c else {})
    bases = _strings(g["residual_force"].attrs["bases"]) if "residual_force" in g else ()
    inverse = InverseDynamics(
        angle_names=names, row_labels=_strings(g["lambda"].attrs["labels"]),
        lam=g["lambda"][()], joint_moments=g["joint_moments"][()],
        kinetic=g["energy/kinetic"][()], potential=g["energy/potential"][()],
        external_power=g["energy/external_power"][()], residual=g["joint_residual"][()],
        base_names=bases,
        residual_force=g["residual_force"][()] if bases else None,
        residual_moment=g["residual_moment"][()] if bases else None)
    loads = tuple(ExternalLoad(load_name, str(item.attrs["body"]), item["force"][()],
                               item["point"][()], item["moment"][()])
                  for load_name, item in g["loads"].items())
    return Dynamics(kinematics, inverse, loads, None if np.isnan(cutoff) else cutoff)


def _read_clinical(c) -> ClinicalResults:
    angles = c["angles"]
    mass = c["moments_per_kg"].attrs["mass"] if "moments_per_kg" in c else None
    return ClinicalResults(
        names=_strings(angles.attrs["names"]), angles=angles[()],
        moments=c["moments"][()] if "moments" in c else None,
        mass=None if mass is None else float(mass),
        stance={body: frames[()] for body, frames in c["stance"].items()},
        contact=tuple(b or None for b in _strings(angles.attrs["contact"])),
        moments_trusted=c["moments_trusted"][()] if "moments_trusted" in c else None)

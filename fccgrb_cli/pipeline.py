"""One solve: trial markers → (perturbation) → kinematic method → per-frame statistics."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fccgrb_cli.errors import InputError
from fccgrb_cli.io.trial import Trial
from fccgrb_cli.io.truth import Truth, read_truth, truth_path
from fccgrb_cli.model import Model
from fccgrb_cli.perturb import perturb
from fccgrb_cli.solvers import KinematicResult, solve_ad
from fccgrb_cli.solvers.nrm import solve_nrm
from fccgrb_cli.system import System, compile_system

METHODS = ("ad", "nrm-ls", "nrm-wls")


@dataclass(frozen=True)
class Run:
    """A solved trial with everything the results file and the summary need."""

    name: str
    result: KinematicResult
    labels: tuple[str, ...]
    rate: float
    reference: np.ndarray
    markers_input: np.ndarray
    model_points: np.ndarray
    ed: np.ndarray
    ed_input: np.ndarray
    truth_theta: np.ndarray | None
    perturb_level_m: float
    perturb_markers: tuple[str, ...]
    perturb_seed: int
    tracking_weight: float | None
    warm_start: str
    hessian: str
    form: str
    model_text: str
    trial_path: str


def match_labels(model: Model, trial: Trial, mapping: dict[str, str]) -> list[str]:
    """The file label each tracked marker follows: the CLI mapping, else the YAML's marker name;
    a file label 'Subject:NAME' matches NAME when NAME itself is absent."""
    have = set(trial.labels)
    stripped = {label.split(":")[-1]: label for label in trial.labels}
    unknown = sorted(set(mapping) - set(model.marker_labels))
    if unknown:
        raise InputError(f"--map: expected marker names of the model "
                         f"({', '.join(model.marker_labels)}), got {', '.join(unknown)}")
    out, missing = [], []
    for name in model.marker_labels:
        wanted = mapping.get(name, name)
        label = wanted if wanted in have else stripped.get(wanted)
        if label is None:
            missing.append(wanted)
        out.append(label)
    if missing:
        shown = ", ".join(trial.labels[:12]) + (" …" if len(trial.labels) > 12 else "")
        raise InputError(f"{trial.path}: expected the labels {', '.join(missing)} tracked by "
                         f"{model.source}, the file has: {shown} (map names with --map)")
    return out


def _vector_targets(model: Model, trial: Trial, markers: dict[str, np.ndarray]) -> np.ndarray:
    out = []
    for tv in model.tracked_vectors:
        ends = []
        for label in (tv.from_marker, tv.to_marker):
            if label not in markers:
                if label not in trial.labels:
                    raise InputError(f"{trial.path}: expected the label {label} used by a "
                                     f"tracked vector of {model.source}")
                markers[label] = trial.select([label])[:, 0]
            ends.append(markers[label])
        d = ends[1] - ends[0]
        out.append(d / np.linalg.norm(d, axis=1, keepdims=True))
    return np.stack(out, axis=1) if out else np.zeros((trial.n_frames, 0, 3))


def solve_trial(model: Model, trial: Trial, *, method: str = "nrm-wls", tol: float = 1e-10,
                mapping: dict[str, str] | None = None, perturb_level_m: float = 0.0,
                perturb_markers: tuple[str, ...] = (), seed: int = 0,
                tracking_weight: float = 1e-3, warm_start: str = "extrapolate",
                hessian: str = "auto", skip_unsolvable: bool = False, name: str | None = None,
                progress: Callable[[int, int], None] | None = None) -> Run:
    """Solve a trial with one method and gather the per-frame statistics."""
    if method not in METHODS:
        raise InputError(f"--method: expected one of {', '.join(METHODS)}, got {method!r}")
    labels = match_labels(model, trial, mapping or {})
    unknown = sorted(set(perturb_markers) - set(model.marker_labels))
    if unknown:
        raise InputError(f"--perturb-markers: expected marker names of the model "
                         f"({', '.join(model.marker_labels)}), got {', '.join(unknown)}")
    measured = trial.select(labels)
    truth = _truth_for(trial, model)
    reference = truth.markers if truth is not None and truth.markers.shape == measured.shape \
        else measured
    inputs = perturb(measured, model.marker_labels, trial.rate, perturb_level_m, seed,
                     only=perturb_markers or None)
    time = trial.time
    if method == "ad":
        system = compile_system(model, angles="driver")
        result = _solve_with_true_angles(system, trial, truth, tol, progress)
    else:
        system = compile_system(model, angles="coordinate", track=True)
        by_label = dict(zip(model.marker_labels, np.moveaxis(inputs, 1, 0), strict=True))
        vectors = _vector_targets(model, trial, by_label)
        targets = np.concatenate([inputs, vectors], axis=1)
        result = solve_nrm(system, time, targets,
                           tracking_weight=None if method == "nrm-ls" else tracking_weight,
                           tol=tol, warm_start=warm_start, hessian=hessian,
                           skip_unsolvable=skip_unsolvable,
                           target_labels=model.marker_labels + tuple(
                               tv.marker for tv in model.tracked_vectors),
                           method=method, source=trial.path, progress=progress)
    which = [(tp.body, tp.point) for tp in model.tracked_points]
    points = np.array([system.point_positions(q, which) for q in result.q])
    level = f"-P{perturb_level_m * 1e3:g}" if perturb_level_m > 0 else ""
    return Run(
        name=name or f"{method}{level}", result=result, labels=model.marker_labels,
        rate=trial.rate, reference=reference, markers_input=inputs, model_points=points,
        ed=np.linalg.norm(points - reference, axis=2),
        ed_input=np.linalg.norm(points - inputs, axis=2),
        truth_theta=truth.theta if truth is not None else None, perturb_level_m=perturb_level_m,
        perturb_markers=perturb_markers or (model.marker_labels if perturb_level_m > 0 else ()),
        perturb_seed=seed, tracking_weight=None if method == "nrm-ls" else tracking_weight,
        warm_start=warm_start, hessian=hessian if method != "ad" else "",
        form=",".join(sorted({b.form for b in model.bodies})),
        model_text=model.text, trial_path=trial.path)


def _truth_for(trial: Trial, model: Model) -> Truth | None:
    sidecar = truth_path(trial.path)
    if not Path(sidecar).exists():
        return None
    truth = read_truth(sidecar)
    if truth.angle_names != tuple(a.name for a in model.angles) or \
            len(truth.time) != trial.n_frames:
        return None
    return truth


def _solve_with_true_angles(system: System, trial: Trial, truth: Truth | None, tol: float,
                            progress: Callable[[int, int], None] | None) -> KinematicResult:
    model = system.model
    if truth is None:
        raise InputError(f"{trial.path}: --method ad drives the model with the true angles of a "
                         f"synthesized trial, and {truth_path(trial.path)} (written by "
                         "'fccgrb synth') was not found or does not match the model")
    return solve_ad(system, truth.time, truth.theta, truth.theta_d, truth.theta_dd,
                    system.layout.pose_q(model), tol=tol, progress=progress)


def summary(run: Run) -> dict[str, float | str | int]:
    """The one-row summary: method, ms/frame, iterations/frame, ‖Φ‖, topology, ED (mm)."""
    r = run.result
    ok = np.isfinite(run.ed).all(axis=1) & r.converged
    row: dict[str, float | str | int] = {
        "run": run.name, "method": r.method, "ms/frame": 1e3 * float(np.mean(r.time_s)),
        "iter/frame": float(np.mean(r.iterations)),
        "mean |Phi|": float(np.nanmean(r.phi_norm)),
        "max |Phi_top|": float(np.nanmax(r.phi_top_max)),
        "mean ED mm": 1e3 * float(np.nanmean(run.ed[ok])) if ok.any() else float("nan"),
        "max ED mm": 1e3 * float(np.nanmax(run.ed[ok])) if ok.any() else float("nan"),
        "failed": int((~r.converged).sum()),
    }
    if run.truth_theta is not None:
        err = np.abs(r.theta - run.truth_theta)[ok]
        row["max |dθ| deg"] = float(np.degrees(err.max())) if err.size else float("nan")
    return row

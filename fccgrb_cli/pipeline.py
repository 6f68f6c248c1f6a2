"""One solve: trial markers → (perturbation) → kinematic method → per-frame statistics."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fccgrb_cli.clinical import ClinicalResults, clinical_results
from fccgrb_cli.dynamics.contact import MAX_DISTANCE, assign
from fccgrb_cli.dynamics.convert import Dynamics, classical_dynamics
from fccgrb_cli.dynamics.loads import ExternalLoad
from fccgrb_cli.errors import InputError
from fccgrb_cli.io.trial import Trial
from fccgrb_cli.io.truth import Truth, read_truth, truth_path
from fccgrb_cli.model import Model
from fccgrb_cli.perturb import perturb
from fccgrb_cli.solvers import KinematicResult, solve_ad
from fccgrb_cli.solvers.baseline import solve_baseline
from fccgrb_cli.solvers.nrm import solve_nrm
from fccgrb_cli.solvers.optimize import Settings, solve_optimization
from fccgrb_cli.solvers.quality import JUMP, assessed
from fccgrb_cli.system import System, compile_system

METHODS = ("ad", "nrm-ls", "nrm-wls", "cno-sqp", "cno-ip", "mo-tc", "mo-ed")


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
    ad_drivers: str = ""
    filter_cutoff: float | None = None
    dynamics: Dynamics | None = None
    warnings: tuple[str, ...] = ()
    notes: tuple[str, ...] = ()
    clinical: ClinicalResults | None = None


def match_labels(model: Model, trial: Trial, mapping: dict[str, str]) -> list[str]:
    """The file label each tracked marker follows: the CLI mapping, else the YAML's marker name;
    a file label 'Subject:NAME' matches NAME when NAME itself is absent."""
    unknown = sorted(set(mapping) - set(model.marker_labels))
    if unknown:
        raise InputError(f"--map: expected marker names of the model "
                         f"({', '.join(model.marker_labels)}), got {', '.join(unknown)}")
    out, missing = [], []
    for name in model.marker_labels:
        wanted = mapping.get(name, name)
        label = trial.find(wanted)
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
                ad_drivers: str = "markers", filter_cutoff: float | None = None,
                filter_order: int = 2, dynamics: bool | None = None, objective: str = "tc",
                max_iter: int | None = None, parallel: bool = False, workers: int | None = None,
                parallel_init: str = "nrm", truth: Truth | None = None,
                progress: Callable[[int, int], None] | None = None) -> Run:
    """Solve a trial with one method, then (when the model has inertia, or ``dynamics``) its
    inverse dynamics on the classical model driven by the solved angles."""
    if method not in METHODS:
        raise InputError(f"--method: expected one of {', '.join(METHODS)}, got {method!r}")
    labels = match_labels(model, trial, mapping or {})
    unknown = sorted(set(perturb_markers) - set(model.marker_labels))
    if unknown:
        raise InputError(f"--perturb-markers: expected marker names of the model "
                         f"({', '.join(model.marker_labels)}), got {', '.join(unknown)}")
    measured = trial.select(labels)
    truth = _truth_for(trial, model) if truth is None else truth
    reference = measured
    if truth is not None:
        index = {label: k for k, label in enumerate(truth.labels)}
        if all(label in index for label in labels) and len(truth.time) == trial.n_frames:
            reference = truth.markers[:, [index[label] for label in labels]]
    inputs = perturb(measured, model.marker_labels, trial.rate, perturb_level_m, seed,
                     only=perturb_markers or None)
    time = trial.time
    if method == "ad":
        system = compile_system(model, angles="driver")
        if ad_drivers == "truth":
            result = _solve_with_true_angles(system, trial, truth, tol, progress)
        else:
            result = solve_baseline(model, time, inputs, cutoff=filter_cutoff,
                                    order=filter_order, tol=tol, progress=progress)
    else:
        system = compile_system(model, angles="coordinate", track=True)
        by_label = dict(zip(model.marker_labels, np.moveaxis(inputs, 1, 0), strict=True))
        targets = np.concatenate([inputs, _vector_targets(model, trial, by_label)], axis=1)
        if method.startswith("nrm"):
            result = solve_nrm(
                system, time, targets,
                tracking_weight=None if method == "nrm-ls" else tracking_weight, tol=tol,
                max_iter=max_iter or 50, warm_start=warm_start, hessian=hessian,
                skip_unsolvable=skip_unsolvable,
                target_labels=model.marker_labels + tuple(
                    tv.marker for tv in model.tracked_vectors),
                method=method, source=trial.path, progress=progress)
        else:
            settings = Settings(method, objective, tol, max_iter or 500)
            result = solve_optimization(system, time, targets, settings, parallel=parallel,
                                        workers=workers, init=parallel_init,
                                        warm_start=warm_start, nrm_weight=tracking_weight,
                                        progress=progress)
    which = [(tp.body, tp.point) for tp in model.tracked_points]
    points = np.array([system.point_positions(q, which) for q in result.q])
    result = assessed(result, points, inputs)
    warnings: list[str] = [*trial.warnings, *_quality_advice(result)]
    notes: list[str] = []
    stance: dict[str, np.ndarray] = {}
    solved_dynamics = None
    failed = len(result.failed_frames)
    if dynamics is None and not model.has_inertia:
        warnings.append(f"{model.source}: no mass and inertia on every body; inverse dynamics "
                        "skipped")
    elif dynamics is None and failed:
        warnings.append(f"{trial.path}: {failed} frames not solved (first: frame index "
                        f"{int(result.failed_frames[0])}); inverse dynamics skipped")
    elif dynamics is not False:
        if failed:
            raise InputError(f"{trial.path}: {failed} frames were not solved (first: frame "
                             f"index {int(result.failed_frames[0])}); inverse dynamics needs "
                             "every frame")
        baseline = method == "ad" and ad_drivers == "markers"
        contact_points = {body: _body_points(system, result.q, body)
                          for body in model.contact_bodies}
        loads = plate_loads(model, trial, warnings, contact_points, notes)
        for load in loads:
            on = np.abs(load.force).any(axis=1)
            stance[load.body] = stance.get(load.body, np.zeros_like(on)) | on
        if filter_cutoff is not None:
            loads = [load.lowpassed(trial.rate, filter_cutoff, filter_order) for load in loads]
        solved_dynamics = classical_dynamics(
            model, result, cutoff=None if baseline else filter_cutoff, order=filter_order,
            loads=loads, tol=tol)
    return Run(
        name=name or run_name(result.method, ad_drivers, filter_cutoff, perturb_level_m,
                              perturb_markers),
        result=result, labels=model.marker_labels,
        rate=trial.rate, reference=reference, markers_input=inputs, model_points=points,
        ed=np.linalg.norm(points - reference, axis=2),
        ed_input=np.linalg.norm(points - inputs, axis=2),
        truth_theta=truth.theta if truth is not None else None, perturb_level_m=perturb_level_m,
        perturb_markers=perturb_markers or (model.marker_labels if perturb_level_m > 0 else ()),
        perturb_seed=seed, tracking_weight=None if method == "nrm-ls" else tracking_weight,
        warm_start=warm_start, hessian=hessian if method != "ad" else "",
        form=",".join(sorted({b.form for b in model.bodies})),
        model_text=model.text, trial_path=trial.path,
        ad_drivers=ad_drivers if method == "ad" else "", filter_cutoff=filter_cutoff,
        dynamics=solved_dynamics, warnings=tuple(warnings), notes=tuple(notes),
        clinical=clinical_results(
            model, result.theta,
            None if solved_dynamics is None else solved_dynamics.inverse.joint_moments, stance))


def _quality_advice(result: KinematicResult) -> list[str]:
    """What to do about flagged frames, where the method is known to cause them."""
    jumps = int((result.converged & (result.flags & JUMP > 0)).sum())
    if not jumps or not result.method.startswith("mo-"):
        return []
    return [f"{result.method}: {jumps} of {result.n_frames} frames jump: goal attainment "
            "minimizes the largest residual only, so on noisy markers its per-frame optimum is "
            "not unique and successive frames land anywhere on it; its accelerations and joint "
            "moments are meaningless there. For joint moments use cno-sqp or nrm-wls"]


def run_name(method: str, ad_drivers: str, cutoff: float | None, level_m: float,
             subset: tuple[str, ...] = ()) -> str:
    """The default run name: the method as the solver labels it (e.g. cno-sqp-ed-parallel), AD
    drivers, filter, perturbation and the perturbed subset, e.g. ad-f6Hz-P30-P4+P9."""
    parts = [method]
    if method == "ad" and ad_drivers == "truth":
        parts.append("truth")
    if cutoff is not None:
        parts.append(f"f{cutoff:g}Hz")
    if level_m > 0:
        parts.append(f"P{level_m * 1e3:g}")
        if subset:
            parts.append("+".join(subset))
    return "-".join(parts)


def _body_points(system: System, q: np.ndarray, body: str) -> np.ndarray:
    """Positions (frames × points × 3) of every named point of a body along a solution."""
    which = [(body, name) for name in system.model.body(body).points]
    return np.array([system.point_positions(qf, which) for qf in q])


def plate_loads(model: Model, trial: Trial, warnings: list[str],
                contact_points: dict[str, np.ndarray] | None = None,
                notes: list[str] | None = None) -> list[ExternalLoad]:
    """The trial's force platforms as external loads: those ``loads.force_plates`` assigns to a
    body, and every other plate's contacts to the nearest of ``loads.contact``'s bodies (whose
    point positions, frames × points × 3, are ``contact_points``)."""
    if not model.force_plates and not model.contact_bodies:
        return []
    if not trial.path.lower().endswith(".c3d"):
        if not model.force_plates:
            return []
        raise InputError(f"{model.source}: loads.force_plates: expected a C3D trial with force "
                         f"platforms, got {trial.path}")
    from fccgrb_cli.io.forceplates import read_force_plates

    plates = {p.number: p for p in read_force_plates(trial.path, trial.n_frames,
                                                     model.plate_threshold)}
    loads = []
    for k, assignment in enumerate(model.force_plates):
        plate = plates.get(assignment.plate)
        key = f"loads.force_plates[{k}].plate"
        if plate is None:
            raise InputError(f"{model.source}: {key}: expected a plate of {trial.path} "
                             f"(it has {len(plates)}), got {assignment.plate}")
        if plate.problem is not None:
            raise InputError(f"{trial.path}: FORCE_PLATFORM plate {plate.number}: expected "
                             f"{plate.problem} (assigned by {model.source} {key})")
        if not np.abs(plate.force).any():
            warnings.append(f"{trial.path}: force plate {plate.number} carries no load above "
                            f"{model.plate_threshold:g} N in any frame")
        loads.append(ExternalLoad(f"plate{plate.number}", assignment.body, plate.force,
                                  plate.cop, plate.free_moment))
    assigned = {a.plate for a in model.force_plates}
    for number, plate in plates.items():
        if number in assigned or not model.contact_bodies:
            continue
        if plate.problem is not None:
            warnings.append(f"{trial.path}: FORCE_PLATFORM plate {number} ignored: expected "
                            f"{plate.problem}")
            continue
        loads.extend(_contact_loads(plate, contact_points or {}, trial.path, warnings,
                                    notes if notes is not None else []))
    return loads


def _contact_loads(plate, contact_points: dict[str, np.ndarray], path: str,
                   warnings: list[str], notes: list[str]) -> list[ExternalLoad]:
    """One plate's loads, each contact given to the nearest contact body."""
    loaded = np.abs(plate.force).any(axis=1)
    mask: dict[str, np.ndarray] = {}
    for c in assign(loaded, plate.cop, contact_points):
        if c.body is None:
            warnings.append(f"{path}: force plate {plate.number}, frame indices {c.start}:"
                            f"{c.stop}: no contact body within {1e3 * MAX_DISTANCE:.0f} mm of "
                            f"the centre of pressure (nearest {1e3 * c.distance:.0f} mm); load "
                            "ignored")
            continue
        notes.append(f"force plate {plate.number}, frame indices {c.start}:{c.stop} → {c.body} "
                     f"(centre of pressure {1e3 * c.distance:.0f} mm from its nearest point)")
        mask.setdefault(c.body, np.zeros(len(loaded), dtype=bool))[c.start:c.stop] = True
    out = []
    for body, frames in mask.items():
        keep = frames[:, None]
        name = f"plate{plate.number}" if len(mask) == 1 else f"plate{plate.number}_{body}"
        out.append(ExternalLoad(name, body, np.where(keep, plate.force, 0.0), plate.cop,
                                np.where(keep, plate.free_moment, 0.0)))
    return out


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


def mean_jump(points: np.ndarray) -> float:
    """Mean frame-to-frame displacement of the model points (m): noise in a trajectory shows
    as a larger jump than the motion itself needs (compare runs of the same trial)."""
    if len(points) < 2:
        return 0.0
    return float(np.nanmean(np.linalg.norm(np.diff(points, axis=0), axis=2)))


def summary(run: Run) -> dict[str, float | str | int]:
    """The one-row summary: method, ms/frame, iterations/frame, ‖Φ‖, topology, ED (mm)."""
    r = run.result
    ok = np.isfinite(run.ed).all(axis=1) & r.converged
    per_frame = r.wall_s / r.n_frames if np.isfinite(r.wall_s) else float(np.mean(r.time_s))
    row: dict[str, float | str | int] = {
        "run": run.name, "method": r.method, "ms/frame": 1e3 * per_frame,
        "iter/frame": float(np.mean(r.iterations)),
        "mean |Phi|": float(np.nanmean(r.phi_norm)),
        "max |Phi_top|": float(np.nanmax(r.phi_top_max)),
        "mean ED mm": 1e3 * float(np.nanmean(run.ed[ok])) if ok.any() else float("nan"),
        "max ED mm": 1e3 * float(np.nanmax(run.ed[ok])) if ok.any() else float("nan"),
        "jump mm": 1e3 * mean_jump(run.model_points),
        "failed": int((~r.converged).sum()),
        "flagged": int((r.converged & ~r.trusted).sum()),
    }
    if run.truth_theta is not None:
        err = np.abs(r.theta - run.truth_theta)[ok]
        row["max |dθ| deg"] = float(np.degrees(err.max())) if err.size else float("nan")
    if run.dynamics is not None:
        row["max |τ| N·m"] = float(np.abs(run.dynamics.inverse.joint_moments).max())
    return row

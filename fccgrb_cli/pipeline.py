"""One solve, as the design's steps: load (labels, truth) → perturb → kinematic solve → quality
assessment → angular drivers (filtered) → inverse dynamics → a Run, whatever asked for it (the
CLI, a sweep cell or the Python API), every option coming in one ``SolveOptions``.

What the stages use lives in their layers: the trial's labels each marker follows
(``io.labels``), the force plates as loads (``io.plate_loads``), the result (``run.Run``)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np

from fccgrb_cli.clinical import clinical_results
from fccgrb_cli.dynamics.convert import Dynamics, classical_dynamics
from fccgrb_cli.errors import InputError
from fccgrb_cli.gait.analysis import analyse_gait, landmark_labels
from fccgrb_cli.io.labels import match_labels, vector_targets
from fccgrb_cli.io.plate_loads import plate_loads
from fccgrb_cli.io.trial import Trial
from fccgrb_cli.io.truth import Truth, read_truth, truth_path
from fccgrb_cli.model import Model
from fccgrb_cli.options import SolveOptions, prepared
from fccgrb_cli.perturb import perturb
from fccgrb_cli.residual_stage import residual_stage
from fccgrb_cli.run import Run
from fccgrb_cli.solvers import KinematicResult, solve_ad
from fccgrb_cli.solvers.ad.baseline import solve_baseline
from fccgrb_cli.solvers.ad.solve import stacked_drives
from fccgrb_cli.solvers.nrm.solve import NrmSettings, solve_nrm
from fccgrb_cli.solvers.quality import JUMP, assessed
from fccgrb_cli.system import System, compile_system

__all__ = ["solve_trial"]

Progress = Callable[[int, int], None] | None


def solve_trial(model: Model, trial: Trial, options: SolveOptions | None = None, *,
                truth: Truth | None = None, progress: Progress = None,
                spill: str | Path | None = None) -> Run:
    """Solve a trial with one method, then (when the model has inertia, or ``dynamics``) its
    inverse dynamics on the classical model driven by the solved angles; ``truth``: the exact
    motion of a synthesized trial (read from its sidecar when None). ``spill``: a folder (the
    results' own, as ``fccgrb solve`` gives it) where the largest per-frame arrays wait on disk
    from the moment the later stages no longer need them (``io.spill``: the Run holds a
    StoredArray in their place, which ``write_run`` copies into the results as stored), so that
    a long trial's memory stays at the markers, q and the dynamics stage's working arrays."""
    options = options or SolveOptions()
    model = prepared(model, options)
    labels = match_labels(model, trial, dict(options.mapping))
    unknown = sorted(set(options.perturb_markers) - set(model.marker_labels))
    if unknown:
        raise InputError(f"--perturb-markers: expected marker names of the model "
                         f"({', '.join(model.marker_labels)}), got {', '.join(unknown)}")
    measured = trial.select(labels)
    truth = _truth_for(trial, model) if truth is None else truth
    reference = _reference(measured, labels, trial, truth)
    inputs = perturb(measured, model.marker_labels, trial.rate, options.perturb_level_m,
                     options.seed, only=options.perturb_markers or None)
    del measured  # the reference itself, or no longer needed
    with _Store(spill) as store:  # a failing stage leaves no scratch file
        trial = store.trial(trial, model)
        system, result = _kinematics(model, trial, inputs, options, truth, progress)
        result = store.rates(result)
        which = [(tp.body, tp.point) for tp in model.tracked_points]
        points = points_along(system, result.q, which)
        result = assessed(result, points, inputs)
        ed, ed_input = (store.keep(key, distances(points, markers)) for key, markers in
                        (("ed", reference), ("ed_input", inputs)))
        reference, inputs, points = (store.keep(key, values) for key, values in
                                     (("reference", reference), ("markers_input", inputs),
                                      ("model_points", points)))
        warnings: list[str] = [*trial.warnings, *_quality_advice(result)]
        notes: list[str] = []
        stance: dict[str, np.ndarray] = {}
        solved_dynamics = _dynamics(model, trial, system, result, options, warnings, notes, stance)
        residuals = residual_stage(model, trial, result, solved_dynamics, stance, inputs, options,
                                   warnings)
        solved_dynamics = residuals.dynamics
        result = store.coordinates(result)
        solved_dynamics = store.dynamics(solved_dynamics)
        clinical = clinical_results(
            model, result.theta,
            None if solved_dynamics is None else solved_dynamics.inverse.joint_moments, stance)
        gait = None if options.events == "none" else \
            analyse_gait(model, trial, clinical, result.trusted, options.events)
        return Run(
            name=options.name or run_name(result.method, options.ad_drivers,
                                          options.filter_cutoff, options.perturb_level_m,
                                          options.perturb_markers),
            options=options, result=result, labels=model.marker_labels, rate=trial.rate,
            reference=reference, markers_input=inputs, model_points=points, ed=ed,
            ed_input=ed_input, truth_theta=truth.theta if truth is not None else None,
            form=",".join(sorted({b.form for b in model.bodies})),
            model_text=model.text, trial_path=trial.path,
            dynamics=solved_dynamics, warnings=tuple(warnings), notes=tuple(notes),
            clinical=clinical, gait=gait, residuals=residuals.report,
            reduction=residuals.reduction)


class _Store:
    """Where ``solve_trial`` puts each large per-frame array once the later stages are done
    with it: in memory as it is (no spill folder), or in a Spill in that folder (``io.spill``),
    keyed by its dataset's path in the run's group of the results file."""

    def __init__(self, folder: str | Path | None) -> None:
        from fccgrb_cli.io.spill import Spill

        self.spill = None if folder is None else Spill(folder)

    def __enter__(self) -> _Store:
        return self

    def __exit__(self, kind, error, trace) -> None:
        if kind is not None and self.spill is not None:
            self.spill.discard()

    def keep(self, key: str, values: np.ndarray):
        """The array, or its StoredArray in the spill."""
        return values if self.spill is None else self.spill.keep(key, values)

    def trial(self, trial: Trial, model: Model) -> Trial:
        """What the stages after the markers' selection read of the trial: its path, rate and
        frame count, the markers of tracked vectors and the gait's landmarks; the trial's every
        marker of every frame can then go (when the caller, as ``fccgrb solve``, keeps no
        reference to it)."""
        if self.spill is None:
            return trial
        vectors = {label for tv in model.tracked_vectors
                   for label in (tv.from_marker, tv.to_marker) if label in trial.labels}
        labels = tuple(dict.fromkeys([*landmark_labels(model, trial).values(), *vectors]))
        return Trial(trial.path, labels, trial.select(list(labels)), trial.rate, trial.warnings)

    def rates(self, result: KinematicResult) -> KinematicResult:
        """q̇, q̈, θ̇, θ̈ stored (the dynamics stage takes q and θ only)."""
        if self.spill is None:
            return result
        return replace(result, **{key: self.keep(key, getattr(result, key))
                                  for key in ("qd", "qdd", "theta_d", "theta_dd")})

    def coordinates(self, result: KinematicResult) -> KinematicResult:
        """q stored (θ, the later stages' input, copied out of it when it is q's columns)."""
        if self.spill is None:
            return result
        theta = result.theta if result.theta.base is None else result.theta.copy()
        return replace(result, q=self.keep("q", result.q), theta=theta)

    def dynamics(self, solved: Dynamics | None) -> Dynamics | None:
        """The classical model's q, q̇, q̈ and the multipliers stored."""
        if solved is None or self.spill is None:
            return solved
        kinematics = replace(solved.kinematics, **{
            key: self.keep(f"classical/{key}", getattr(solved.kinematics, key))
            for key in ("q", "qd", "qdd")})
        inverse = replace(solved.inverse, lam=self.keep("lambda", solved.inverse.lam))
        return replace(solved, kinematics=kinematics, inverse=inverse)


def distances(points: np.ndarray, markers: np.ndarray, block: int = 8192) -> np.ndarray:
    """‖point − marker‖ per frame and marker (frames × markers), ``block`` frames at a time
    (the differences of a long trial's every frame would be one more frames × markers × 3)."""
    out = np.empty(points.shape[:2])
    for start in range(0, len(points), block):
        part = slice(start, start + block)
        out[part] = np.linalg.norm(points[part] - markers[part], axis=2)
    return out


def _reference(measured: np.ndarray, labels: list[str], trial: Trial,
               truth: Truth | None) -> np.ndarray:
    """The markers errors are measured against: a synthesized trial's exact ones, else the
    trial's own."""
    if truth is not None:
        index = {label: k for k, label in enumerate(truth.labels)}
        if all(label in index for label in labels) and len(truth.time) == trial.n_frames:
            return truth.markers[:, [index[label] for label in labels]]
    return measured


def _kinematics(model: Model, trial: Trial, inputs: np.ndarray, options: SolveOptions,
                truth: Truth | None, progress: Progress) -> tuple[System, KinematicResult]:
    """The kinematic solve by the chosen method (FORMULATION §3)."""
    o, time = options, trial.time
    if o.method == "ad":
        system = compile_system(model, angles="driver")
        if o.ad_drivers == "truth":
            return system, _solve_with_true_angles(system, trial, truth, o.tol, progress)
        return system, solve_baseline(model, time, inputs, cutoff=o.filter_cutoff,
                                      order=o.filter_order, tol=o.tol, progress=progress)
    system = compile_system(model, angles="coordinate", track=True)
    by_label = dict(zip(model.marker_labels, np.moveaxis(inputs, 1, 0), strict=True))
    vectors = vector_targets(model, trial, by_label)
    targets = np.concatenate([inputs, vectors], axis=1) if vectors.shape[1] else inputs
    if o.method.startswith("nrm"):
        labels = model.marker_labels + tuple(tv.marker for tv in model.tracked_vectors)
        return system, solve_nrm(system, time, targets, NrmSettings.from_options(o),
                                 labels=labels, source=trial.path, progress=progress)
    from fccgrb_cli.solvers.optimize.solve import (  # scipy.optimize: 0.1 s
        Settings,
        solve_optimization,
    )

    return system, solve_optimization(system, time, targets, Settings.from_options(o),
                                      progress)


def _dynamics(model: Model, trial: Trial, system: System, result: KinematicResult,
              options: SolveOptions, warnings: list[str], notes: list[str],
              stance: dict[str, np.ndarray]) -> Dynamics | None:
    """The inverse dynamics of the classical model driven by the run's angles (FORMULATION §4),
    with the trial's force plates; None, with a warning, when it cannot or need not run."""
    failed = len(result.failed_frames)
    if options.dynamics is None and not model.has_inertia:
        warnings.append(f"{model.source}: no mass and inertia on every body; inverse dynamics "
                        "skipped")
        return None
    if options.dynamics is None and failed:
        warnings.append(f"{trial.path}: {failed} frames not solved (first: frame index "
                        f"{int(result.failed_frames[0])}); inverse dynamics skipped")
        return None
    if options.dynamics is False:
        return None
    if failed:
        raise InputError(f"{trial.path}: {failed} frames were not solved (first: frame "
                         f"index {int(result.failed_frames[0])}); inverse dynamics needs "
                         "every frame")
    baseline = options.method == "ad" and options.ad_drivers == "markers"
    contact_points = {body: _body_points(system, result.q, body)
                      for body in model.contact_bodies}
    loads = plate_loads(model, trial, warnings, contact_points, notes)
    del contact_points  # frames × points × 3 each: not for the drive
    for load in loads:
        on = np.abs(load.force).any(axis=1)
        stance[load.body] = stance.get(load.body, np.zeros_like(on)) | on
    cutoff = options.filter_cutoff
    if cutoff is not None:
        loads = [load.lowpassed(trial.rate, cutoff, options.filter_order) for load in loads]
    return classical_dynamics(model, result, cutoff=None if baseline else cutoff,
                              order=options.filter_order, loads=loads, tol=options.tol,
                              engine=options.engine)


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
    return points_along(system, q, [(body, name) for name in system.model.body(body).points])


def points_along(system: System, q: np.ndarray, which: list[tuple[str, str]],
                 block: int = 8192) -> np.ndarray:
    """System.point_positions of every frame at once (frames × points × 3): r + l₁u + l₂v + l₃w
    of each (body, point) on the frames' x = S V q (Eq. 2, 5), ``block`` frames at a time (a long
    trial's x of every frame would be one more frames × nx array)."""
    lay = system.layout
    places = [(lay.x_offset(body) + np.arange(12), system.model.body(body).points[point].local)
              for body, point in which]
    out = np.empty((len(q), len(which), 3))
    for start in range(0, len(q), block):
        part = q[start:start + block]
        x = np.empty((len(part), lay.nx))
        x[:, lay.copy_x] = part[:, lay.copy_q]
        if len(lay.reduced_w):
            x[:, lay.reduced_w] = np.cross(part[:, lay.reduced_u], part[:, lay.reduced_v])
        for k, (columns, local) in enumerate(places):
            r, u, v, w = x[:, columns].reshape(-1, 4, 3).transpose(1, 0, 2)
            out[start:start + len(part), k] = r + local[0] * u + local[1] * v + local[2] * w
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
    drives = stacked_drives(system, truth.theta, truth.theta_d, truth.theta_dd, None)
    return solve_ad(system, truth.time, drives, system.layout.pose_q(model), tol=tol,
                    progress=progress)



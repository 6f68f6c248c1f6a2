"""One solve, as the design's steps: load (labels, truth) → perturb → kinematic solve → quality
assessment → angular drivers (filtered) → inverse dynamics → a Run, whatever asked for it (the
CLI, a sweep cell or the Python API), every option coming in one ``SolveOptions``.

What the stages use lives in their layers: the trial's labels each marker follows
(``trial.labels``), the force plates as loads (``dynamics.plate_loads``), the result
(``pipeline.run.Run``)."""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass, fields, replace
from pathlib import Path

import numpy as np

from fccgrb_cli.anatomy.clinical import clinical_results
from fccgrb_cli.anatomy.lab_axes import lab_axes
from fccgrb_cli.core.errors import InputError
from fccgrb_cli.core.stretches import clocked, merged, runs, shifted, shortest, spans, take
from fccgrb_cli.dynamics.convert import Dynamics, classical_dynamics, smoothed_dynamics
from fccgrb_cli.dynamics.loads import ExternalLoad, lowpassed
from fccgrb_cli.dynamics.plate_loads import plate_loads
from fccgrb_cli.gait.analysis import analyse_gait, find_events, landmark_labels
from fccgrb_cli.model import Model
from fccgrb_cli.pipeline.assessment import (
    contact_events,
    curve_trust,
    describe_moments,
    dynamic_findings,
    kinematic_findings,
    moment_flags,
)
from fccgrb_cli.pipeline.options import SolveOptions, prepared
from fccgrb_cli.pipeline.residuals import residual_stage
from fccgrb_cli.pipeline.run import Run
from fccgrb_cli.pipeline.smoothing import Smoothing, smoothed_or_warned
from fccgrb_cli.signals.artefact import perturb
from fccgrb_cli.signals.butterworth import frames_needed
from fccgrb_cli.solvers import KinematicResult, solve_ad
from fccgrb_cli.solvers.ad.solve import stacked_drives
from fccgrb_cli.solvers.determined import determined
from fccgrb_cli.solvers.engine import use_kernels
from fccgrb_cli.solvers.methods import Method, mixed_runs_compiled, solve_stretch
from fccgrb_cli.solvers.mixed import recounted
from fccgrb_cli.solvers.nrm.problem import unsolvable_text
from fccgrb_cli.solvers.optimize.frame import method_label
from fccgrb_cli.solvers.quality import JUMP, NO_DATA, Finding, assessed, with_findings
from fccgrb_cli.system import System, compile_system
from fccgrb_cli.system.sparse import supported
from fccgrb_cli.trial.labels import match_labels, vector_targets
from fccgrb_cli.trial.record import Trial
from fccgrb_cli.trial.truth import Truth, read_truth, truth_path
from fccgrb_cli.trial.virtual import resolved

__all__ = ["StageNotes", "check_window", "dynamics_stage", "expected_run_name", "solve_trial"]

Progress = Callable[[int, int], None] | None


def solve_trial(model: Model, trial: Trial, options: SolveOptions | None = None, *,
                truth: Truth | None = None, progress: Progress = None,
                spill: str | Path | None = None) -> Run:
    """Solve a trial with one method, then (when the model has inertia, or ``dynamics``) its
    inverse dynamics on the classical model driven by the solved angles; ``truth``: the exact
    motion of a synthesized trial (read from its sidecar when None). ``spill``: a folder (the
    results' own, as ``fccgrb solve`` gives it) where the largest per-frame arrays wait on disk
    from the moment the later stages no longer need them (``core.spill``: the Run holds a
    StoredArray in their place, which ``write_run`` copies into the results as stored), so that
    a long trial's memory stays at the markers, q and the dynamics stage's working arrays. A
    trial whose arrays are small (below ``SPILL_MB``) stays in memory: writing and reading
    them back would cost a short trial a tenth of its solve for no memory worth saving."""
    options = options or SolveOptions()
    trial = _window(trial, options)
    _check_length(trial, options)
    model = prepared(model, options)
    if not model.tracked_points:
        raise InputError(f"{model.source}: tracking.points: expected at least one tracked point "
                         "(a marker on a body) to solve a trial from; the section is empty or "
                         "absent")
    given = None
    if options.loads is not None:  # --loads: an OpenSim load set
        from fccgrb_cli.opensim.loads import trial_loads

        given = trial_loads(options.loads, model, trial)
    if model.moving_joints and Method(options.method).drives_angles:
        raise InputError(f"--method ad: {model.source}: the angular-driver baseline computes "
                         f"angles from segment frames, which an imported OpenSim model's "
                         f"coordinates are not; use a mixed-coordinate method (nrm-wls, cno-sqp …)")
    if model.moving_joints:  # an OpenSim model tracks the markers the trial has, as its IK does
        from fccgrb_cli.model.osim.convert import for_trial

        model = for_trial(model, trial, dict(options.mapping))
    trial, mapping = resolved(model, trial, dict(options.mapping), set(model.marker_labels))
    artefact_m = trial.artefact_m  # `fccgrb perturb`'s level, judged as --perturb's
    labels = match_labels(model, trial, mapping)
    unknown = sorted(set(options.perturb_markers) - set(model.marker_labels))
    if unknown:
        raise InputError(f"--perturb-markers: expected marker names of the model "
                         f"({', '.join(model.marker_labels)}), got {', '.join(unknown)}")
    measured = trial.select(labels)
    axes = lab_axes(model, trial, measured, options.vertical)
    model = model.with_gravity(axes.gravity)
    truth = _truth_for(trial, model) if truth is None else truth
    reference = _reference(measured, labels, trial, truth)
    inputs = perturb(measured, model.marker_labels, trial.rate, options.perturb_level_m,
                     options.seed, only=options.perturb_markers or None)
    del measured  # the reference itself, or no longer needed
    with _Store(spill if _worth_spilling(model, trial) else None) as store:  # a failing
        # stage leaves no scratch file
        trial = store.trial(trial, model)
        system, result, no_data = _kinematics(model, trial, inputs, options, truth, progress)
        result = store.rates(result)
        which = [(tp.body, tp.point) for tp in model.tracked_points]
        points = points_along(system, result.q, which)
        fit = distances(points, inputs)
        found = kinematic_findings(model, result, fit, options, truth is not None,
                                   artefact_m)
        found[NO_DATA] = no_data
        unassessed = result
        result = assessed(unassessed, points, inputs, found)
        warnings: list[str] = [*trial.warnings, *axes.warnings, *_quality_advice(result)]
        notes: list[str] = [axes.note()] if axes.chosen_by != "ground" else []
        if model.moving_joints:  # recorded with the run: which engine solved it
            notes.append(_moving_engine(options, system))
        if artefact_m:
            notes.append(f"{trial.path}: markers perturbed by fccgrb perturb at "
                         f"{1e3 * artefact_m:g} mm (recorded in the file): the fit check allows "
                         "for it as for --perturb")
        smoothing = smoothed_or_warned(model, result, inputs, options, warnings)
        bridged = result
        if smoothing is not None:  # checked again where the smoother put the model
            bridged = smoothing.result
            # before the first and after the last frame the smoother used it had no data
            outside = _outside_the_data(no_data.frames | ~smoothing.motion.used)
            smoothed = replace(_blank(bridged, outside), messages=unassessed.messages)
            points = points_along(system, smoothed.q, which)
            fit = distances(points, inputs)
            found = kinematic_findings(model, smoothed, fit, options, truth is not None)
            found[NO_DATA] = no_data
            result = assessed(smoothed, points, inputs, found)
        ed, ed_input = (store.keep(key, values) for key, values in
                        (("ed", distances(points, reference)), ("ed_input", fit)))
        reference, inputs, points = (store.keep(key, values) for key, values in
                                     (("reference", reference), ("markers_input", inputs),
                                      ("model_points", points)))
        stance: dict[str, np.ndarray] = {}
        solved_dynamics = dynamics_stage(model, trial, system, bridged, options,
                                         StageNotes(warnings, notes, stance, given), smoothing)
        uncertainty = None
        if smoothing is not None:
            uncertainty = _blank(smoothing.uncertainty(
                None if solved_dynamics is None else solved_dynamics.kinematics.q,
                () if solved_dynamics is None else solved_dynamics.loads), outside)
            notes.append(uncertainty.describe())
            solved_dynamics = _blank_frames(solved_dynamics, outside, result.time)
        residuals = residual_stage(model, trial, result, solved_dynamics, stance, inputs, options,
                                   warnings)
        solved_dynamics = residuals.dynamics
        if solved_dynamics is not None and not model.moving_joints:  # the classical model's
            result = with_findings(result, dynamic_findings(model, solved_dynamics))
        pig = None
        if model.calibration_method == "plugin-gait":
            from fccgrb_cli.plugin_gait.outputs import plugin_gait_results, upper_body_missing

            pig = plugin_gait_results(model, result.q, result.trusted, solved_dynamics, {
                label: trial.markers[:, k] for k, label in enumerate(trial.labels)})
            missing = upper_body_missing(model, trial.labels)
            warnings += [missing] if missing else []
        result = store.coordinates(result)
        solved_dynamics = store.dynamics(solved_dynamics)
        clinical = clinical_results(
            model, result.theta,
            None if solved_dynamics is None else solved_dynamics.inverse.joint_moments, stance)
        events = None if options.events == "none" else \
            find_events(model, trial, clinical, options.events, result.converged, axes)
        moments = None
        if solved_dynamics is not None:
            moments, details = moment_flags(model, result, solved_dynamics, stance,
                                            contact_events(events), trial.rate)
            warnings += describe_moments(moments, details, result.time, result.trusted)
            if clinical is not None:
                clinical = replace(clinical, moments_trusted=moments[:, [
                    k for k, a in enumerate(model.angles) if a.clinical_sign is not None]] == 0)
        gait = None if events is None else analyse_gait(
            model, trial, clinical, result.trusted, options.events, events=events,
            trusted_curves=curve_trust(model, result.trusted, moments))
        # every time a message gives on the trial file's clock, as its events and exports
        result = replace(result, messages=tuple(clocked(m, trial.start)
                                                for m in result.messages))
        warnings = [clocked(w, trial.start) for w in warnings]
        return Run(
            name=expected_run_name(options),
            options=options, result=result, labels=model.marker_labels, rate=trial.rate,
            reference=reference, markers_input=inputs, model_points=points, ed=ed,
            ed_input=ed_input, truth_theta=truth.theta if truth is not None else None,
            form=",".join(sorted({b.form for b in model.bodies})),
            model_text=model.text, trial_path=trial.path,
            dynamics=solved_dynamics, warnings=tuple(warnings), notes=tuple(notes),
            clinical=clinical, gait=gait, moment_flags=moments, axes=axes,
            uncertainty=uncertainty, plugin_gait=pig, start_time=trial.start,
            residuals=residuals.report, reduction=residuals.reduction)


# A run's per-frame arrays are spilled when they would hold more than this many MiB (estimated
# as 12 arrays of the frames × the model's coordinates, float64): a 10-minute trial's ~1 GB,
# not a walk's few MB. The environment's FCCGRB_SPILL_MB sets another (0: always, as the test
# suite runs, so that its short trials take the path a long one takes).
SPILL_MB = 64.0
SPILL_SETTING = "FCCGRB_SPILL_MB"


def _worth_spilling(model: Model, trial: Trial) -> bool:
    """Whether the trial's arrays are large enough to be kept on disk (``SPILL_MB``)."""
    try:
        limit = float(os.environ.get(SPILL_SETTING, SPILL_MB))
    except ValueError:
        raise InputError(f"{SPILL_SETTING}: expected a size in MiB, got "
                         f"{os.environ[SPILL_SETTING]!r}") from None
    coordinates = 12 * len(model.bodies) + len(model.angles)
    return 12 * 8 * coordinates * trial.n_frames > limit * 2**20


class _Store:
    """Where ``solve_trial`` puts each large per-frame array once the later stages are done
    with it: in memory as it is (no spill folder), or in a Spill in that folder (``core.spill``),
    keyed by its dataset's path in the run's group of the results file."""

    def __init__(self, folder: str | Path | None) -> None:
        from fccgrb_cli.core.spill import Spill

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
        frame count, the markers of tracked vectors and the gait's landmarks (and a Plug-in Gait
        model's upper-body markers, which its outputs read); the trial's every
        marker of every frame can then go (when the caller, as ``fccgrb solve``, keeps no
        reference to it)."""
        if self.spill is None:
            return trial
        vectors = {label for tv in model.tracked_vectors
                   for label in (tv.from_marker, tv.to_marker) if label in trial.labels}
        upper: tuple[str, ...] = ()
        if model.calibration_method == "plugin-gait":  # the upper body's angles read them
            from fccgrb_cli.plugin_gait.upper import MARKERS

            upper = tuple(label for label in MARKERS if label in trial.labels)
        labels = tuple(dict.fromkeys([*landmark_labels(model, trial).values(), *vectors,
                                      *upper]))
        return Trial(trial.path, labels, trial.select(list(labels)), trial.rate, trial.warnings,
                     trial.start)

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


def _moving_engine(options: SolveOptions, system: System) -> str:
    """The note that says which engine solved a model with moving joints."""
    if mixed_runs_compiled(options.method, system, options):
        return "engine: compiled kernels (moving joints' functions as polynomial pieces)"
    if options.engine == "numpy":
        why = "--engine numpy"
    elif not supported(system):
        why = "the compiled kernels do not take this model's functions"
    else:
        why = f"the compiled kernels do not run {options.method} with these options"
    return f"engine: numpy reference ({why})"


def _kinematics(model: Model, trial: Trial, inputs: np.ndarray, options: SolveOptions,
                truth: Truth | None, progress: Progress
                ) -> tuple[System, KinematicResult, Finding]:
    """The kinematic solve by the chosen method (docs/formulation.md §3), on every stretch of frames
    the markers determine (``solvers.determined``); the others are left unsolved (no data, no
    answer), or are an error naming the first without ``--skip-unsolvable``. Also the frames
    the markers do not determine, named (the ``no_data`` finding)."""
    o, time = options, trial.time
    driven = Method(o.method).drives_angles
    if driven and o.ad_drivers == "truth":
        system = compile_system(model, angles="driver")
        return (system, _solve_with_true_angles(system, trial, truth, o.tol, progress),
                Finding(np.zeros(len(time), dtype=bool)))
    mixed = compile_system(model, angles="coordinate", track=True)
    by_label = dict(zip(model.marker_labels, np.moveaxis(inputs, 1, 0), strict=True))
    vectors = vector_targets(model, trial, by_label)
    targets = np.concatenate([inputs, vectors], axis=1) if vectors.shape[1] else inputs
    known = determined(mixed, targets, every_marker=driven)
    labels = model.marker_labels + tuple(tv.marker for tv in model.tracked_vectors)
    if not known.all() and not o.skip_unsolvable:
        f = int(np.flatnonzero(~known)[0])
        text = unsolvable_text(f, trial.start + time, ~np.isfinite(targets[f]).all(axis=1),
                               labels, trial.path)
        why = "; the angular-driver pre-analysis needs every marker" if driven else ""
        raise InputError(f"{text}{why} (--skip-unsolvable leaves such frames unsolved)")
    system = compile_system(model, angles="driver") if driven else mixed
    parts = runs(known)
    if len(parts) == 1 and parts[0] == (0, len(time)):
        return system, solve_stretch(o.method, system, time, targets, o,
                                    source=trial.path, progress=progress), Finding(~known)
    done = 0

    def step(k: int, _: int) -> None:
        if progress is not None:
            progress(done + k, len(time))

    solved = []
    for a, b in parts:
        part = solve_stretch(o.method, system, time[a:b], targets[a:b], o, source=trial.path,
                             progress=step)
        solved.append((slice(a, b), part))
        done += b - a
    unknown = np.flatnonzero(~known)
    messages = [shifted(m, a) for (a, _), (_, part) in zip(parts, solved, strict=True)
                for m in part.messages]
    gone = (~np.isfinite(targets[unknown]).all(axis=2)).any(axis=0)
    result = recounted(system, replace(merged(solved, len(time), time),
                                       messages=tuple(messages))) if solved else \
        _unsolved(system, time, o)
    return system, result, Finding(
        ~known, f"{trial.path}: frame indices {spans(unknown)} (missing: "
                f"{', '.join(np.array(labels)[gone])})")


def _unsolved(system: System, time: np.ndarray, options: SolveOptions) -> KinematicResult:
    """A run none of whose frames the markers determine."""
    n, nq = len(time), system.nq
    nan = np.full((n, nq), np.nan)
    angles = np.full((n, len(system.model.angles)), np.nan)
    return KinematicResult(
        method=options.method, tol=options.tol, time=time, q=nan, qd=nan, qdd=nan,
        theta=angles, theta_d=angles, theta_dd=angles,
        angle_names=tuple(a.name for a in system.model.angles),
        iterations=np.zeros(n, dtype=int), time_s=np.zeros(n), phi_norm=np.full(n, np.nan),
        phi_top_max=np.full(n, np.nan), converged=np.zeros(n, dtype=bool))


def _outside_the_data(no_data: np.ndarray) -> np.ndarray:
    """The frames before the first and after the last that the markers determine: there the
    smoother's prior extrapolates from nothing (a gap between determined frames it bridges with
    the model, and its standard deviation says so; either way the frames stay untrusted)."""
    known = np.flatnonzero(~no_data)
    frame = np.arange(len(no_data))
    if not len(known):
        return np.ones(len(no_data), dtype=bool)
    return (frame < known[0]) | (frame > known[-1])


def _blank(value, frames: np.ndarray):
    """A smoothed result or its uncertainty with the float per-frame arrays NaN on ``frames``
    (outside the data: the smoother's prior there is no answer); flags, counts and the
    convergence mask as they were."""
    if not frames.any():
        return value
    n = len(frames)
    return replace(value, **{
        f.name: np.where(frames.reshape(-1, *[1] * (v.ndim - 1)), np.nan, v)
        for f in fields(value) if f.init
        for v in [getattr(value, f.name)]
        if isinstance(v, np.ndarray) and v.ndim and len(v) == n and v.dtype.kind == "f"})


def _blank_frames(dynamics: Dynamics | None, frames: np.ndarray, time: np.ndarray
                  ) -> Dynamics | None:
    """The inverse dynamics without the frames the markers did not determine (NaN, False)."""
    if dynamics is None or not frames.any():
        return dynamics
    n = len(frames)
    keep = runs(~frames)
    if not keep:
        return None
    return merged([(slice(a, b), take(dynamics, slice(a, b), n)) for a, b in keep], n, time)


@dataclass(frozen=True)
class StageNotes:
    """Where the dynamics stage reports: warnings, notes, and each foot's stance frames; and
    the ``--loads`` set it applies in place of the trial's force plates (its loads and the
    notes that say which force went where; None: the plates), read before the solve so that a
    bad file stops the run before the work."""

    warnings: list[str]
    notes: list[str]
    stance: dict[str, np.ndarray]
    given: tuple[list[ExternalLoad], list[str]] | None = None


def dynamics_stage(model: Model, trial: Trial, system: System, result: KinematicResult,
                   options: SolveOptions, report: StageNotes,
                   smoothing: Smoothing | None = None, *,
                   batched: bool | None = None) -> Dynamics | None:
    """The inverse dynamics of the classical model driven by the run's angles
    (docs/formulation.md §4), with the trial's force plates (or the ``--loads`` set,
    ``report.given``), on every stretch of solved frames long enough for its rates
    (``stretches.shortest``): θ̇, θ̈ and the filter within each stretch, never across a gap;
    None, with a warning, when it cannot or need not run, or no stretch is long enough. With
    ``smoothing`` the model is driven by the smoothed rates over the whole trial (the smoother
    bridged its gaps with the model; their frames stay untrusted and so do their moments) and the
    plates are smoothed alike (smoothing.py). ``batched``: the classical model's frames all at
    once, or one by one (None: as ``dynamics.convert.classical_dynamics`` chooses); the
    benchmarks time each."""
    warnings, notes, stance, given = report.warnings, report.notes, report.stance, report.given
    if options.dynamics is None and not model.has_inertia:
        warnings.append(f"{model.source}: no mass and inertia on every body; inverse dynamics "
                        "skipped")
        return None
    if options.dynamics is False:
        return None
    n = result.n_frames
    least = shortest(options.filter_order if options.filter_cutoff is not None else None)
    if n < least:
        tiny = (f"{trial.path}: {n} frame{'s' * (n != 1)}; the inverse dynamics needs at least "
                f"{least} (a stretch of solved frames long enough for its rates)")
        if options.dynamics:
            raise InputError(tiny)
        warnings.append(f"{tiny}; skipped")
        return None
    solved = np.isfinite(result.q).all(axis=1)
    if smoothing is None:
        solved &= result.converged
    parts = runs(solved, least)
    covered = np.zeros(n, dtype=bool)
    for a, b in parts:
        covered[a:b] = True
    if not covered.all():
        left = np.flatnonzero(~covered)
        short = np.flatnonzero(~covered & solved)
        warnings.append(
            f"{trial.path}: inverse dynamics on {int(covered.sum())} of {n} frames; left out "
            f"{len(left)} frames (frame indices {spans(left)}): not solved"
            + (f", or in stretches of solved frames shorter than {least} "
               f"(frame indices {spans(short)})" if len(short) else ""))
    if not parts:
        return None
    baseline = Method(options.method).drives_angles and options.ad_drivers == "markers"
    contact_points = {body: _body_points(system, result.q, body)
                      for body in model.contact_bodies}
    if given is None:
        loads = plate_loads(model, trial, warnings, contact_points, notes)
    else:  # --loads: an OpenSim load set names each force's body in place of the plates
        loads, said = given
        notes.extend(said)
    del contact_points  # frames × points × 3 each: not for the drive
    for load in loads:
        on = np.abs(load.force).any(axis=1)
        stance[load.body] = stance.get(load.body, np.zeros_like(on)) | on
    cutoff = options.filter_cutoff
    if model.moving_joints:  # the coordinates' own forces, as OpenSim's ID tool gives them
        if not loads:
            warnings.append(f"{model.source}: no external loads (--loads, or a C3D's plates "
                            "with --plate): the generalized forces hold no ground reaction; "
                            "while the model touches the ground its weight shows on the base's "
                            "residual forces and the joint moments are not the subject's")
        # the solve's system, when its kernels take it (mixed, with tracking), runs them
        compiled = supported(system) and use_kernels(options.engine, True)
        return _coordinate_dynamics(model, result, parts, loads, options,
                                    smoothed=smoothing is not None,
                                    kernels=system if compiled else None)
    if smoothing is not None and parts == [(0, n)]:
        loads = smoothing.smoothed_loads(loads, trial.rate)
        return smoothed_dynamics(model, result, smoothing.drives, loads=loads, tol=options.tol,
                                 engine=options.engine)
    pieces = []
    for a, b in parts:
        part = slice(a, b)
        some = [take(load, part, n) for load in loads]
        if cutoff is not None:
            some = lowpassed(some, trial.rate, cutoff, options.filter_order)
        pieces.append((part, classical_dynamics(
            model, take(result, part, n), cutoff=None if baseline else cutoff,
            order=options.filter_order, loads=some, tol=options.tol, engine=options.engine,
            batched=batched)))
    if len(pieces) == 1 and parts[0] == (0, n):
        return pieces[0][1]
    return merged(pieces, n, result.time)


def _coordinate_dynamics(model: Model, result: KinematicResult,
                         parts: list[tuple[int, int]], loads: list[ExternalLoad],
                         options: SolveOptions, smoothed: bool,
                         kernels: System | None = None) -> Dynamics:
    """The inverse dynamics of an imported model along its solved coordinates, on each stretch
    of ``parts``: θ low-passed at ``--filter-cutoff`` as OpenSim's ID tool does and
    differentiated through its quintic spline (``dynamics.moving.coordinate_rates``), or the
    smoother's θ, θ̇, θ̈ as they are (``smoothed``); the loads applied as given, as the tool
    applies them (docs/opensim.md). Frames outside ``parts`` are NaN. ``kernels``: the
    solve's system, whose compiled kernels then run the rates and multipliers
    (``dynamics.moving.coordinate_inverse``)."""
    from fccgrb_cli.dynamics.moving import coordinate_inverse, coordinate_rates

    system = compile_system(model, angles="coordinate")  # the topology alone: no tracking rows
    n = result.n_frames
    pieces = []
    for a, b in parts:
        part = slice(a, b)
        if smoothed:
            rates = result.theta[part], result.theta_d[part], result.theta_dd[part]
        else:
            rates = coordinate_rates(result.time[part], result.theta[part],
                                     options.filter_cutoff)
        some = [take(load, part, n) for load in loads]
        (q, qd, qdd), inverse = coordinate_inverse(system, *rates, some, kernels=kernels)
        kinematics = replace(take(result, part, n), q=q, qd=qd, qdd=qdd, theta=rates[0],
                             theta_d=rates[1], theta_dd=rates[2])
        pieces.append((part, Dynamics(kinematics, inverse, tuple(some),
                                      options.filter_cutoff)))
    if len(pieces) == 1 and parts[0] == (0, n):
        return pieces[0][1]
    return merged(pieces, n, result.time)


def check_window(path: str, options: SolveOptions) -> None:
    """A ``--from``/``--to`` window into a C3D is refused rather than misaligned: its plates,
    events and lab axes are read again from the file frame by frame from its first."""
    windowed = options.time_from is not None or options.time_to is not None
    if windowed and str(path).lower().endswith(".c3d"):
        raise InputError(f"{path}: --from/--to: expected a TRC trial or --coordinates (a "
                         "C3D's plates and events are aligned from its first frame; cut the "
                         "trial to the range first)")


def _window(trial: Trial, options: SolveOptions) -> Trial:
    """The trial's frames within ``--from``/``--to`` (its own clock; :func:`check_window`)."""
    check_window(trial.path, options)
    return trial.between(options.time_from, options.time_to)


def _check_length(trial: Trial, options: SolveOptions) -> None:
    """A trial too short for the filter asked for is an error naming the frames it needs."""
    if options.filter_cutoff is None:
        return
    need = frames_needed(options.filter_order)
    if trial.n_frames < need:
        raise InputError(f"{trial.path}: {trial.n_frames} frame{'s' * (trial.n_frames != 1)}; "
                         f"--filter-cutoff needs at least {need} (a Butterworth of order "
                         f"{options.filter_order} run forward and backward), or solve without it")


def _quality_advice(result: KinematicResult) -> list[str]:
    """What to do about flagged frames, where the method is known to cause them."""
    assert result.flags is not None  # advice follows the assessment that sets them
    jumps = int((result.converged & (result.flags & JUMP > 0)).sum())
    if not jumps or not result.method.startswith("mo-"):
        return []
    return [f"{result.method}: {jumps} of {result.n_frames} frames jump: goal attainment "
            "minimizes the largest residual only, so on noisy markers its per-frame optimum is "
            "not unique and successive frames land anywhere on it; its accelerations and joint "
            "moments are meaningless there. For joint moments use cno-sqp or nrm-wls"]


def _smoothing(options: SolveOptions) -> str:
    """How the run was smoothed, as its name says it: '' (not), 'smooth' (the strength
    estimated), 'smooth6Hz' (a cutoff given), 'smooth-n0.5mm' (a noise given)."""
    if options.smooth == "none":
        return ""
    if options.smooth_cutoff is not None:
        return f"smooth{options.smooth_cutoff:g}Hz"
    if options.smooth_noise is not None:
        return f"smooth-n{options.smooth_noise:g}mm"
    return "smooth"


def expected_run_name(options: SolveOptions) -> str:
    """The name a solve with ``options`` writes its run under, known before it solves (so that
    a second run into a results file is refused before the work): ``--name``, else
    :func:`run_name` of the method's label (``solvers.optimize.frame.method_label``)."""
    if options.name:
        return options.name
    label = method_label(options.method, options.objective, options.parallel,
                         options.parallel_init)
    return run_name(label, options.ad_drivers, options.filter_cutoff, options.perturb_level_m,
                    options.perturb_markers, _smoothing(options))


def run_name(method: str, ad_drivers: str, cutoff: float | None, level_m: float,
             subset: tuple[str, ...] = (), smoothing: str = "") -> str:
    """The default run name: the method as the solver labels it (e.g. cno-sqp-ed-parallel), AD
    drivers, filter, smoothing (:func:`_smoothing`), perturbation and the perturbed subset, e.g.
    ad-f6Hz-P30-P4+P9 or nrm-wls-smooth."""
    parts = [method]
    if method == Method.AD and ad_drivers == "truth":  # the solver's label: "ad" alone
        parts.append("truth")
    if cutoff is not None:
        parts.append(f"f{cutoff:g}Hz")
    if smoothing:
        parts.append(smoothing)
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



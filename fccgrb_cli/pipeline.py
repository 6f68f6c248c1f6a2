"""One solve, as the design's steps: load (labels, truth) → perturb → kinematic solve → quality
assessment → angular drivers (filtered) → inverse dynamics → a Run, whatever asked for it (the
CLI, a sweep cell or the Python API), every option coming in one ``SolveOptions``."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from functools import cached_property
from pathlib import Path

import numpy as np

from fccgrb_cli.clinical import ClinicalResults, clinical_results
from fccgrb_cli.dynamics.contact import MAX_DISTANCE, assign
from fccgrb_cli.dynamics.convert import Dynamics, classical_dynamics
from fccgrb_cli.dynamics.loads import ExternalLoad
from fccgrb_cli.errors import InputError
from fccgrb_cli.gait.analysis import GaitResults, analyse_gait, landmark_labels
from fccgrb_cli.io.trial import Trial
from fccgrb_cli.io.truth import Truth, read_truth, truth_path
from fccgrb_cli.model import Model
from fccgrb_cli.named import NamedArray
from fccgrb_cli.options import METHODS, SolveOptions
from fccgrb_cli.perturb import perturb
from fccgrb_cli.solvers import KinematicResult, solve_ad
from fccgrb_cli.solvers.baseline import solve_baseline
from fccgrb_cli.solvers.nrm import NrmSettings, solve_nrm
from fccgrb_cli.solvers.quality import JUMP, assessed
from fccgrb_cli.system import System, compile_system

__all__ = ["METHODS", "Run", "solve_trial", "summary"]

Progress = Callable[[int, int], None] | None


@dataclass(frozen=True, repr=False)
class Run:
    """A solved trial: the options it was solved with, the kinematic result (with each frame's
    quality flags), the markers it saw, the model points it reached, and the inverse dynamics."""

    name: str
    options: SolveOptions
    result: KinematicResult
    labels: tuple[str, ...]
    rate: float
    reference: np.ndarray
    markers_input: np.ndarray
    model_points: np.ndarray
    ed: np.ndarray
    ed_input: np.ndarray
    truth_theta: np.ndarray | None
    form: str
    model_text: str
    trial_path: str
    dynamics: Dynamics | None = None
    warnings: tuple[str, ...] = ()
    notes: tuple[str, ...] = ()
    clinical: ClinicalResults | None = None
    gait: GaitResults | None = None

    def __repr__(self) -> str:
        r = self.result
        return (f"Run({self.name!r}: {self.options.method}, {len(r.time)} frames, "
                f"{int((~r.converged).sum())} failed, {int((~r.trusted).sum())} not trusted, "
                f"dynamics {'on' if self.dynamics is not None else 'off'})")

    # --- what the results file records of the options, as they applied to this run -------
    @property
    def perturb_level_m(self) -> float:
        return self.options.perturb_level_m

    @property
    def perturb_markers(self) -> tuple[str, ...]:
        """The perturbed markers: those named, else every tracked one when perturbed."""
        return self.options.perturb_markers or (self.labels if self.perturb_level_m > 0 else ())

    @property
    def perturb_seed(self) -> int:
        return self.options.seed

    @property
    def tracking_weight(self) -> float | None:
        return None if self.options.method == "nrm-ls" else self.options.tracking_weight

    @property
    def warm_start(self) -> str:
        return self.options.warm_start

    @property
    def hessian(self) -> str:
        return "" if self.options.method == "ad" else self.options.hessian

    @property
    def ad_drivers(self) -> str:
        return self.options.ad_drivers if self.options.method == "ad" else ""

    @property
    def filter_cutoff(self) -> float | None:
        return self.options.filter_cutoff

    # --- the Python API's view: named arrays with units ------------------------------------
    @cached_property
    def model(self) -> Model:
        """The model as solved (the run's YAML with the options' form and tracked markers)."""
        from fccgrb_cli.model import parse_model

        return prepared(parse_model(self.model_text, self.trial_path), self.options)

    def _named(self, values: np.ndarray, names: tuple[str, ...], units: tuple[str, ...]
               ) -> NamedArray:
        return NamedArray(values, names, units, self.result.time)

    @property
    def _angle_units(self) -> tuple[str, ...]:
        return tuple("m" if getattr(a, "kind", "angle") == "distance" else "rad"
                     for a in self.model.angles)

    @property
    def angles(self) -> NamedArray:
        """Every joint angle (rad; a distance coordinate in m) per frame."""
        return self._named(self.result.theta, self.result.angle_names, self._angle_units)

    @property
    def angular_velocities(self) -> NamedArray:
        """θ̇ (rad/s; m/s for distances), by central differences of the solved θ."""
        return self._named(self.result.theta_d, self.result.angle_names,
                           tuple(f"{u}/s" for u in self._angle_units))

    @property
    def angular_accelerations(self) -> NamedArray:
        """θ̈ (rad/s²; m/s² for distances)."""
        return self._named(self.result.theta_dd, self.result.angle_names,
                           tuple(f"{u}/s²" for u in self._angle_units))

    def _coordinates(self, values: np.ndarray, per: str) -> NamedArray:
        names, units = [], []
        for body in self.model.bodies:
            for vector in ("r", "u", "v", "w")[: 4 if body.form == "full" else 3]:
                names += [f"{body.name}.{vector}.{axis}" for axis in "xyz"]
                units += [("m" if vector == "r" else "1") + per] * 3
        if values.shape[1] > len(names):  # mixed coordinates: the angles follow
            names += list(self.result.angle_names)
            units += [u + per for u in self._angle_units]
        return self._named(values, tuple(names), tuple(units))

    @property
    def q(self) -> NamedArray:
        """The system coordinates per frame (Eq. 9): each body's r (m) and unit vectors, then
        the mixed coordinates (rad, m)."""
        return self._coordinates(self.result.q, "")

    @property
    def qd(self) -> NamedArray:
        """q̇, consistent with the topological equations (per s)."""
        return self._coordinates(self.result.qd, "/s")

    @property
    def qdd(self) -> NamedArray:
        """q̈, consistent with the topological equations (per s²)."""
        return self._coordinates(self.result.qdd, "/s²")

    @property
    def moments(self) -> NamedArray | None:
        """Joint moments conjugate to the angles (N·m; N for distances), None without the
        dynamics."""
        if self.dynamics is None:
            return None
        return self._named(self.dynamics.inverse.joint_moments, self.result.angle_names,
                           tuple("N" if u == "m" else "N·m" for u in self._angle_units))

    @property
    def clinical_angles(self) -> NamedArray | None:
        """Clinical angles (deg) of the angles that declare a clinical sign."""
        c = self.clinical
        return None if c is None else self._named(c.angles, c.names, ("deg",) * len(c.names))

    @property
    def clinical_moments(self) -> NamedArray | None:
        """Their conjugate moments, N·m/kg when the subject's mass is known, else N·m."""
        c = self.clinical
        if c is None or c.moments is None:
            return None
        per_kg = c.moments_per_kg
        values, unit = (per_kg, "N·m/kg") if per_kg is not None else (c.moments, "N·m")
        return self._named(values, c.names, (unit,) * len(c.names))

    @property
    def trusted(self) -> np.ndarray:
        """Per frame: converged and not flagged by the quality checks."""
        return self.result.trusted

    def summary(self) -> dict[str, float | str | int]:
        """The one-row summary the command line prints."""
        return summary(self)

    def to_hdf5(self, path: str | Path, command: str = "fccgrb_cli.solve (Python API)") -> None:
        """Add this run to a results file (created when absent), atomically."""
        from fccgrb_cli.io.results import write_run

        write_run(path, self, command)

    def to_dataframe(self):
        """One row per frame: time, trusted, the angles, their moments and the clinical curves
        (columns 'name [unit]'); needs pandas."""
        import pandas as pd

        parts = [self.angles.to_dataframe()]
        parts += [a.to_dataframe().add_prefix(prefix) for prefix, a in (
            ("moment ", self.moments), ("clinical ", self.clinical_angles),
            ("clinical moment ", self.clinical_moments)) if a is not None]
        frame = pd.concat(parts, axis=1)
        frame.insert(0, "trusted", self.trusted)
        return frame


def match_labels(model: Model, trial: Trial, mapping: dict[str, str]) -> list[str]:
    """The file label each tracked marker follows: the CLI mapping, else the YAML's marker name;
    a file label 'Subject:NAME' matches NAME when NAME itself is absent. A label not found is an
    error naming, for each, the file's closest labels."""
    unknown = sorted(set(mapping) - set(model.marker_labels))
    if unknown:
        raise InputError(f"--map: expected marker names of the model "
                         f"({', '.join(model.marker_labels)}), got "
                         f"{_with_closest(unknown, model.marker_labels)}")
    out, missing = [], []
    for name in model.marker_labels:
        wanted = mapping.get(name, name)
        label = trial.find(wanted)
        if label is None:
            missing.append(wanted)
        out.append(label)
    if missing:
        free = [label for label in trial.labels if label not in out]
        shown = ", ".join(free[:12]) + (" …" if len(free) > 12 else "")
        raise InputError(f"{trial.path}: expected the labels tracked by {model.source}; not "
                         f"found: {_with_closest(missing, free)}; the file's labels no marker "
                         f"follows: {shown or 'none'} (map names with --map NAME=LABEL or "
                         "--map FILE.yaml)")
    return out


def _with_closest(names: list[str], known: tuple[str, ...] | list[str]) -> str:
    """'A (closest: B, C), D (closest: none)': each name with the nearest of ``known``."""
    from difflib import get_close_matches

    bare = {k.split(":")[-1].lower(): k for k in known}
    parts = []
    for name in names:
        near = get_close_matches(name.split(":")[-1].lower(), list(bare), n=3, cutoff=0.4)
        parts.append(f"{name} (closest: {', '.join(bare[n] for n in near) or 'none'})")
    return ", ".join(parts)


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


def prepared(model: Model, options: SolveOptions) -> Model:
    """The model as the options ask: every body in one form, only some markers tracked."""
    if options.form != "model":
        model = model.with_form(options.form)
    if options.track:
        unknown = sorted(set(options.track) - set(model.marker_labels))
        if unknown:
            raise InputError(f"--track: expected marker names of {model.source} "
                             f"({', '.join(model.marker_labels)}), got {', '.join(unknown)}")
        model = model.with_tracked(options.track)
    return model


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
            clinical=clinical, gait=gait)


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
    vectors = _vector_targets(model, trial, by_label)
    targets = np.concatenate([inputs, vectors], axis=1) if vectors.shape[1] else inputs
    if o.method.startswith("nrm"):
        labels = model.marker_labels + tuple(tv.marker for tv in model.tracked_vectors)
        return system, solve_nrm(system, time, targets, NrmSettings.from_options(o),
                                 labels=labels, source=trial.path, progress=progress)
    from fccgrb_cli.solvers.optimize import Settings, solve_optimization  # scipy.optimize: 0.1 s

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
    from fccgrb_cli.io.c3d_header import read_parameters
    from fccgrb_cli.io.forceplates import read_force_plates

    used = read_parameters(trial.path).get("FORCE_PLATFORM:USED")
    none = used is not None and used.values.size and not used.values[0]
    # FORCE_PLATFORM:USED 0: ezc3d would find no plate after loading every frame's points
    plates = {} if none else {p.number: p for p in read_force_plates(
        trial.path, trial.n_frames, model.plate_threshold)}
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
        distance = np.array(run._angle_units) == "m"
        angle_err = err[:, ~distance]
        row["max |dθ| deg"] = float(np.degrees(angle_err.max())) if angle_err.size else float("nan")
        if distance.any():
            row["max |dd| mm"] = 1e3 * float(err[:, distance].max()) if err.size else float("nan")
    if run.dynamics is not None:
        loads = np.abs(run.dynamics.inverse.joint_moments)
        distance = np.array(run._angle_units) == "m"
        row["max |τ| N·m"] = float(loads[:, ~distance].max()) if (~distance).any() else \
            float("nan")
        if distance.any():  # a slide's joint force (N) is not a moment
            row["max |F| N"] = float(loads[:, distance].max())
    return row

"""Residual reduction (dynamic consistency): segment masses and centres of mass, then the
kinematics, adjusted so that a floating base's residual falls, for the least added marker misfit.

1. The residual over the measured frames (``residuals``) of the first model.
2. Masses and CoMs within their bounds (``inertia_fit``); the adjusted model's inverse dynamics
   on the same motion.
3. The motion the dynamics used (the solved angles and the base's trajectory, low-passed as
   the run asks) corrected by a small rigid motion of the whole body per frame
   (``kinematic_correction``), CORRECTION_STEPS Gauss–Newton steps, each followed by the
   adjusted model's inverse dynamics on the corrected motion. The correction is added after
   the low-pass (the drive is then given the filtered angles and base and no cutoff), so that
   the filter does not take back what the correction puts in.

The contact states (which frames are measured) are those of the first motion throughout, so
that before and after are over the same frames. Joint angles are not changed: the correction
moves every body alike, so closed chains stay closed and every joint equation holds.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
import yaml

from fccgrb_cli.core.errors import InputError
from fccgrb_cli.dynamics.convert import Dynamics, classical_dynamics
from fccgrb_cli.dynamics.inertia_fit import InertiaFit, fit_inertia
from fccgrb_cli.dynamics.kinematic_correction import (
    CorrectionData,
    RigidCorrection,
    correction_step,
)
from fccgrb_cli.dynamics.loads import ExternalLoad
from fccgrb_cli.dynamics.mass import mass_blocks
from fccgrb_cli.dynamics.residuals import (
    BodyMotion,
    ResidualReport,
    contact_states,
    residual_report,
)
from fccgrb_cli.model import Inertia, Model
from fccgrb_cli.signals.butterworth import lowpass, settling_frames
from fccgrb_cli.solvers.result import KinematicResult
from fccgrb_cli.system import compile_system

CORRECTION_STEPS = 2


@dataclass(frozen=True)
class Stage:
    """How the dynamics stage ran: frame rate (Hz), the low-pass cutoff (Hz, None: none) and
    order, the drive's tolerance and engine (SolveOptions' names)."""

    rate: float
    cutoff: float | None
    order: int
    tol: float
    engine: str


@dataclass(frozen=True)
class Reduction:
    """What a reduction did (all of it stored with the run): the adjusted model's YAML text,
    the inertia fit, the whole-body correction applied (summed over the steps), the first
    model's residuals, and the marker misfit RMS (m) of the motion the dynamics used, before
    and after, over the measured frames and over all frames."""

    text: str
    fit: InertiaFit
    correction: RigidCorrection
    before: ResidualReport
    markers_before: tuple[float, float]
    markers_after: tuple[float, float]


@dataclass(frozen=True)
class Reduced:
    """A reduction's outcome: what it did, the adjusted model, its inverse dynamics on the
    corrected motion, and its residuals over the first model's frames."""

    reduction: Reduction
    model: Model
    dynamics: Dynamics
    after: ResidualReport


def states_of(model: Model, dynamics: Dynamics, stance: dict[str, np.ndarray],
              stage: Stage) -> tuple[BodyMotion, dict[str, np.ndarray]]:
    """The motion the dynamics used and every contact body's state per frame, the low-pass
    filter's reach counted (``residuals.contact_states``)."""
    k = dynamics.kinematics
    motion = BodyMotion.of(compile_system(model, angles="driver"), k.q, k.qd, k.qdd)
    reach = 0 if stage.cutoff is None else settling_frames(stage.rate, stage.cutoff,
                                                           stage.order)
    return motion, contact_states(model, motion, stance, stage.rate, reach)


def report_of(model: Model, dynamics: Dynamics, stance: dict[str, np.ndarray],
              stage: Stage, trusted: np.ndarray | None = None) -> ResidualReport | None:
    """A run's residual report over the ``trusted`` frames (None without exactly one floating
    base)."""
    motion, states = states_of(model, dynamics, stance, stage)
    return residual_report(model, motion, mass_blocks(model), dynamics.loads, states,
                           trusted=trusted)


def adjusted_model(model: Model, fit: InertiaFit) -> Model:
    """The model with the fitted masses and CoMs (inertia tensors scaled by the mass)."""
    bodies = []
    for body in model.bodies:
        k = fit.names.index(body.name)
        assert body.inertia is not None  # the fit's mass matrices required it
        tensor = fit.tensor(k, np.array(body.inertia.tensor))
        bodies.append(replace(body, inertia=Inertia(
            float(fit.mass[k]), _floats(fit.com[k]),
            (_floats(tensor[0]), _floats(tensor[1]), _floats(tensor[2])))))
    return replace(model, bodies=tuple(bodies))


def _floats(v: np.ndarray) -> tuple[float, float, float]:
    """A 3-vector as a tuple of Python floats."""
    return (float(v[0]), float(v[1]), float(v[2]))


def adjusted_text(model: Model, fit: InertiaFit, trial: str) -> str:
    """The model's YAML with the fitted inertia, and a header saying where it came from."""
    doc = yaml.safe_load(model.text)
    for k, name in enumerate(fit.names):
        spec = doc["bodies"][name]
        inertia = model.body(name).inertia
        assert inertia is not None  # the fit's mass matrices required it
        tensor = fit.tensor(k, np.array(inertia.tensor))
        spec.update(mass=float(f"{fit.mass[k]:.6g}"),
                    com=np.round(fit.com[k], 6).tolist(),
                    inertia=np.round(tensor, 8).tolist())
    header = (f"# {doc.get('name', 'model')} with segment masses and centres of mass adjusted by "
              f"`fccgrb solve --reduce-residuals` on {trial}\n# (within ±25 % of each mass and "
              "±10 % of each segment's size; inertia tensors scaled by the mass) from "
              f"{model.source}.\n")
    return header + yaml.safe_dump(doc, sort_keys=False, default_flow_style=None, width=100)


def _marker_rms(model: Model, motion: BodyMotion, markers: np.ndarray,
                frames: np.ndarray) -> tuple[float, float, np.ndarray]:
    """RMS marker misfit (m) over ``frames`` and over all, and the tracked points."""
    points = np.stack([motion.points(tp.body, np.array([model.body(tp.body).points[tp.point]
                                                        .local]))[0][:, 0]
                       for tp in model.tracked_points], axis=1)
    d2 = np.sum((points - markers) ** 2, axis=2)
    return (float(np.sqrt(np.nanmean(d2[frames]))), float(np.sqrt(np.nanmean(d2))), points)


def prefiltered(model: Model, result: KinematicResult, stage: Stage) -> KinematicResult:
    """The run's angles and floating bases' coordinates low-passed as the drive would do it:
    driven with no cutoff, the same motion as the run's drive with it."""
    if stage.cutoff is None:
        return result
    system = compile_system(model, angles="driver")
    q = result.q.copy()
    blocks = [system.layout.q_slice(base) for base in model.floating_bases]
    # one pass of the filter over the angles and the bases (each column alone)
    together = lowpass(np.concatenate([result.theta, *(q[:, b] for b in blocks)], axis=1),
                       stage.rate, stage.cutoff, stage.order)
    start = result.theta.shape[1]
    for block in blocks:
        width = q[:, block].shape[1]
        q[:, block] = together[:, start:start + width]
        start += width
    return replace(result, q=q, theta=np.ascontiguousarray(together[:, :result.theta.shape[1]]))


@dataclass(frozen=True)
class RunData:
    """What the reduction takes of a solved run: the model (with inertia), its kinematic
    result, its first dynamics, each contact body's plate stance (unfiltered), the markers the
    kinematics followed (frames × tracked markers × 3) and the trial's path."""

    model: Model
    result: KinematicResult
    dynamics: Dynamics
    stance: dict[str, np.ndarray]
    markers: np.ndarray
    trial: str


def reduce_residuals(run: RunData, stage: Stage) -> Reduced:
    """The module's three steps on a solved run."""
    model, loads = run.model, run.dynamics.loads
    if len(model.floating_bases) != 1:
        raise InputError(f"--reduce-residuals: expected a model with one floating base (its "
                         f"drivers give the residual); {model.source} has "
                         f"{len(model.floating_bases)}")
    motion, states = states_of(model, run.dynamics, run.stance, stage)
    before = residual_report(model, motion, mass_blocks(model), loads, states,
                             trusted=run.result.trusted)
    assert before is not None  # one floating base, checked above
    if not before.measured.any():
        raise InputError(f"{run.trial}: --reduce-residuals: expected frames where every "
                         "contact with the ground is measured by a force plate; there are none")
    markers_before = _marker_rms(model, motion, run.markers, before.measured)[:2]
    fit = fit_inertia(model, motion, loads, before.measured, before.over_measured.weight)
    adjusted = adjusted_model(model, fit)
    result = prefiltered(adjusted, run.result, stage)
    dynamics = _drive(adjusted, result, loads, stage)
    system = compile_system(adjusted, angles="driver")
    body = system.layout.n_body_q
    total = np.zeros((len(result.q), 6))
    for _ in range(CORRECTION_STEPS):
        k = dynamics.kinematics
        motion = BodyMotion.of(system, k.q, k.qd, k.qdd)
        points = _marker_rms(adjusted, motion, run.markers, before.measured)[2]
        step = correction_step(adjusted, CorrectionData(
            motion, mass_blocks(adjusted), loads, before.measured, points, run.markers,
            before.over_measured.weight, stage.rate))
        q = result.q.copy()
        q[:, :body] = step.apply(system, q[:, :body])
        result = replace(result, q=q)
        total += np.concatenate([step.translation, step.rotation], axis=1)
        dynamics = _drive(adjusted, result, loads, stage)
    k = dynamics.kinematics
    motion = BodyMotion.of(system, k.q, k.qd, k.qdd)
    after = residual_report(adjusted, motion, mass_blocks(adjusted), loads, states,
                            before.over_measured.weight, run.result.trusted)
    assert after is not None  # the adjusted model keeps its one floating base
    markers_after = _marker_rms(adjusted, motion, run.markers, before.measured)[:2]
    reduction = Reduction(adjusted_text(model, fit, run.trial), fit,
                          RigidCorrection(total[:, :3], total[:, 3:], step.centre), before,
                          markers_before, markers_after)
    return Reduced(reduction, adjusted, replace(dynamics, cutoff=stage.cutoff), after)


def _drive(model: Model, result: KinematicResult, loads: Sequence[ExternalLoad],
           stage: Stage) -> Dynamics:
    """The classical model's inverse dynamics on a motion already low-passed."""
    return classical_dynamics(model, result, cutoff=None, order=stage.order, loads=loads,
                              tol=stage.tol, engine=stage.engine)

"""The residual stage of a solve: after the inverse dynamics, the floating base's residual over
the frames where every ground contact is measured (``dynamics.residuals``), and with
``SolveOptions.reduce_residuals`` the residual reduction (``dynamics.reduction``), whose
adjusted model's dynamics then stand for the run's."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from fccgrb_cli.core.errors import InputError
from fccgrb_cli.dynamics.convert import Dynamics
from fccgrb_cli.dynamics.residuals import ResidualReport
from fccgrb_cli.model import Model
from fccgrb_cli.pipeline.options import SolveOptions
from fccgrb_cli.solvers.result import KinematicResult
from fccgrb_cli.trial.record import Trial

if TYPE_CHECKING:  # loaded where a model has a floating base to report on
    from fccgrb_cli.dynamics.reduction import Reduction


@dataclass(frozen=True)
class ResidualStage:
    """The run's residual report (None without dynamics or a single floating base), the
    reduction (None unless asked), and the dynamics that stand for the run's (the adjusted
    model's after a reduction)."""

    report: ResidualReport | None
    reduction: Reduction | None
    dynamics: Dynamics | None


def residual_stage(model: Model, trial: Trial, result: KinematicResult,
                   dynamics: Dynamics | None, stance: dict[str, np.ndarray],
                   markers: np.ndarray, options: SolveOptions,
                   warnings: list[str]) -> ResidualStage:
    """Report the residual of ``dynamics`` (and reduce it when the options ask), the run's
    ``markers`` being those its tracked points followed (frames × points × 3)."""
    if options.reduce_residuals and dynamics is None:
        raise InputError(f"{model.source}: --reduce-residuals: expected the inverse dynamics "
                         "(every body with mass and inertia, every frame solved, no "
                         "--no-dynamics)")
    if dynamics is None or len(model.floating_bases) != 1:
        if options.reduce_residuals:
            raise InputError(f"--reduce-residuals: expected a model with one floating base "
                             f"(its drivers give the residual); {model.source} has "
                             f"{len(model.floating_bases)}")
        return ResidualStage(None, None, dynamics)
    from fccgrb_cli.dynamics.reduction import RunData, Stage, reduce_residuals, report_of

    stage = Stage(trial.rate, options.filter_cutoff, options.filter_order, options.tol,
                  options.engine)
    if not options.reduce_residuals:
        report = report_of(model, dynamics, stance, stage, result.trusted)
        _check_weight(report, warnings, model.subject_mass)
        return ResidualStage(report, None, dynamics)
    reduced = reduce_residuals(RunData(model, result, dynamics, stance, np.asarray(markers),
                                       trial.path), stage)
    _check_weight(reduced.reduction.before, warnings, model.subject_mass)
    if not reduced.reduction.fit.success:
        warnings.append(f"--reduce-residuals: the inertia fit stopped without converging "
                        f"({reduced.reduction.fit.message})")
    return ResidualStage(reduced.after, reduced.reduction, reduced.dynamics)


def _check_weight(report: ResidualReport | None, warnings: list[str],
                  subject_mass: float | None) -> None:
    """The plates' body weight against the subject's mass (the model's where it records none),
    a warning where they disagree."""
    message = None if report is None else report.weight_mismatch(subject_mass=subject_mass)
    if message is not None:
        warnings.append(message)

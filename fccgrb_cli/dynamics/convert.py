"""MC solution → classical model (FORMULATION §4, paper §5): the solved θ(t) become AR drivers
θ*(t) (optionally low-passed; θ̇*, θ̈* by central differences), the tracking constraints go, and
the square system gives consistent q, q̇, q̈ for the inverse dynamics."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from fccgrb_cli.dynamics.inverse import InverseDynamics, inverse_dynamics
from fccgrb_cli.dynamics.loads import ExternalLoad
from fccgrb_cli.model import Model
from fccgrb_cli.solvers.baseline import driven_by
from fccgrb_cli.solvers.result import KinematicResult
from fccgrb_cli.system import compile_system


@dataclass(frozen=True)
class Dynamics:
    """The converted model's kinematics and its inverse dynamics."""

    kinematics: KinematicResult
    inverse: InverseDynamics
    loads: tuple[ExternalLoad, ...]
    cutoff: float | None


def classical_dynamics(model: Model, result: KinematicResult, *, cutoff: float | None = None,
                       order: int = 2, loads: Sequence[ExternalLoad] = (),
                       tol: float = 1e-10) -> Dynamics:
    """Drive the classical model with the run's angles and solve its inverse dynamics."""
    system = compile_system(model, angles="driver")
    n_body = system.layout.n_body_q
    base = np.array([system.base_reference(q[:n_body]) for q in result.q])
    kinematics = driven_by(system, result.time, result.theta, result.q[0, :n_body].copy(),
                           cutoff=cutoff, order=order, tol=tol, method=result.method, base=base)
    inverse = inverse_dynamics(system, kinematics.q, kinematics.qd, kinematics.qdd,
                               kinematics.theta, loads)
    return Dynamics(kinematics, inverse, tuple(loads), cutoff)

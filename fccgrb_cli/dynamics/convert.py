"""MC solution → classical model (docs/formulation.md §4, paper §5): the solved θ(t) become AR
drivers θ*(t) (optionally low-passed; θ̇*, θ̈* by central differences), the tracking constraints go,
and the square system gives consistent q, q̇, q̈ for the inverse dynamics."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

from fccgrb_cli.dynamics.inverse import InverseDynamics, KernelInverse, inverse_dynamics
from fccgrb_cli.dynamics.loads import ExternalLoad
from fccgrb_cli.model import Model
from fccgrb_cli.solvers.ad.baseline import drivers_from
from fccgrb_cli.solvers.ad.solve import solve_ad, solve_ad_batched
from fccgrb_cli.solvers.batched import Drives, Stacked
from fccgrb_cli.solvers.result import KinematicResult
from fccgrb_cli.system import System, compile_system


@dataclass(frozen=True)
class Dynamics:
    """The converted model's kinematics and its inverse dynamics."""

    kinematics: KinematicResult
    inverse: InverseDynamics
    loads: tuple[ExternalLoad, ...]
    cutoff: float | None


def classical_dynamics(model: Model, result: KinematicResult, *, cutoff: float | None = None,
                       order: int = 2, loads: Sequence[ExternalLoad] = (),
                       tol: float = 1e-10, batched: bool | None = None,
                       engine: str = "numpy") -> Dynamics:
    """Drive the classical model with the run's angles and solve its inverse dynamics.

    ``batched`` True: every frame at once, each starting from the run's own body coordinates
    (they satisfy the same topology, and the drivers exactly when unfiltered), the multipliers
    by stacked solves; False: frame by frame, each from the run's body coordinates too (the
    reference the batched path equals to rounding). Starting from the run's configuration
    keeps the classical model on the mixed solution's assembly branch where the angles alone
    leave two (a parallelogram's change point); a frame that does not converge from there is
    flagged (solvers/quality.py, ``BRANCH``). None (the default): batched where Φ_q is
    square. A taller Φ_q (a signed angle's sine row, a floating base's drivers beside its
    rigid-body rows) takes least squares: stacked QR costs as much per frame as LAPACK's
    frame-by-frame one and the batch's guesses need more Gauss–Newton iterations there (the
    lower-limb gait trial: 4 per frame against 2.8), so it stays frame by frame. ``engine``
    ('numpy', 'compiled' or 'auto', as SolveOptions.engine): the compiled kernels solve the
    batch frame by frame in machine code (any Φ_q of full column rank) where they take the
    model."""
    system = compile_system(model, angles="driver")
    base = Stacked(system).base_reference(result.q[:, :system.layout.n_body_q])
    drives = drivers_from(system, result.time, result.theta, base, cutoff, order)
    return _driven(system, result, drives, loads, tol, batched, engine, cutoff)


def smoothed_dynamics(model: Model, result: KinematicResult, drives: Drives, *,
                      loads: Sequence[ExternalLoad] = (), tol: float = 1e-10,
                      engine: str = "numpy") -> Dynamics:
    """:func:`classical_dynamics` with the classical model's θ*, θ̇*, θ̈* and base features
    with their rates as given (the whole-trial smoother's, ``smoothing.py``) instead of the
    run's θ differenced."""
    system = compile_system(model, angles="driver")
    return _driven(system, result, drives, loads, tol, None, engine, None)


def _driven(system: System, result: KinematicResult, drives: Drives,
            loads: Sequence[ExternalLoad], tol: float, batched: bool | None, engine: str,
            cutoff: float | None) -> Dynamics:
    """The classical ``system`` driven by ``drives`` from the run's body coordinates, and its
    inverse dynamics (:func:`classical_dynamics`)."""
    compiled = kernels_for(system, engine)
    if batched is None:
        batched = compiled or system.n_rows == system.nq
    body_q = result.q[:, :system.layout.n_body_q]
    compiled = compiled and batched
    # the kernels solve the multipliers on the factor the drive leaves at each frame
    solved = KernelInverse.prepare(system, loads, len(body_q)) if compiled else None
    if batched:
        kinematics = solve_ad_batched(system, result.time, drives, body_q, tol=tol,
                                      compiled=compiled,
                                      inverse=None if solved is None else solved.arrays)
    else:
        # each frame from the mixed solution's configuration too: the classical model stays
        # on its assembly branch (a frame that cannot is flagged: solve_ad)
        kinematics = solve_ad(system, result.time, drives, body_q, tol=tol)
    kinematics = replace(kinematics, method=result.method)
    inverse = inverse_dynamics(system, kinematics, loads, batched=batched, compiled=compiled,
                               solved=solved)
    return Dynamics(kinematics, inverse, tuple(loads), cutoff)


def kernels_for(system: System, engine: str) -> bool:
    """Whether the classical model's batch runs in the compiled kernels (engine.use_kernels);
    where they cannot take the model, or numba is missing, it stays in numpy even with
    'compiled' (the kinematic stage has already said so when it ran in them)."""
    from fccgrb_cli.solvers.engine import numba_available, use_kernels
    from fccgrb_cli.system.sparse import compilable

    return compilable(system) and numba_available() and use_kernels(engine, True)

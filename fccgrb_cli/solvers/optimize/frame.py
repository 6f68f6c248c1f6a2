"""One frame through an optimization method (docs/formulation.md §3, CNO and MO): the settings, the
structured optimizer or scipy's (the paper's reference), the verdict, and the retry from the
frame's NRM-WLS solution; what the sequential loop, the parallel pool and the compiled loop
(optimize/compiled.py) all call for a frame."""

from __future__ import annotations

import time as clock
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from fccgrb_cli.solvers.cno.reference import solve_cno_frame
from fccgrb_cli.solvers.cno.sqp import FAR, sqp_weights, stabilized_sqp
from fccgrb_cli.solvers.cno.sqp import MAX_ITER as MAX_SQP
from fccgrb_cli.solvers.goal.reference import FrameOutcome, solve_goal_frame
from fccgrb_cli.solvers.goal.sqp import FAR as FAR_GOAL
from fccgrb_cli.solvers.goal.sqp import MAX_ITER as MAX_GOAL
from fccgrb_cli.solvers.goal.sqp import active_set_sqp
from fccgrb_cli.solvers.newton import Iterate, gauss_newton
from fccgrb_cli.solvers.nrm.problem import row_weights, without_gaps
from fccgrb_cli.solvers.optimize.problem import FrameProblem
from fccgrb_cli.system import System

if TYPE_CHECKING:
    from fccgrb_cli.pipeline.options import SolveOptions

STRUCTURED = {method: (name, f"{name}: converged successfully") for method, name in
              (("cno-sqp", "stabilized SQP"), ("cno-ip", "interior point"),
               ("mo-tc", "active-set SQP"), ("mo-ed", "active-set SQP"))}
CONVERGED = STRUCTURED["cno-sqp"][1]


@dataclass(frozen=True)
class Settings:
    """An optimization method: ``method`` (one of METHODS), CNO ``objective`` ('tc' or 'ed'),
    tolerance and iteration cap per frame, the warm start of each frame; ``parallel``: frames
    over ``workers`` processes, each from its ``init`` guess (PARALLEL_INITS; 'nrm' solves
    NRM-WLS first with tracking weight ``nrm_weight``)."""

    method: str
    objective: str = "tc"
    tol: float = 1e-10
    max_iter: int = 500
    warm_start: str = "extrapolate"
    parallel: bool = False
    workers: int | None = None
    init: str = "nrm"
    nrm_weight: float = 1e-3
    optimizer: str = "auto"
    engine: str = "auto"

    @classmethod
    def from_options(cls, o: SolveOptions) -> Settings:
        return cls(o.method, o.objective, o.tol, o.max_iter or 500, o.warm_start, o.parallel,
                   o.workers, o.parallel_init, o.tracking_weight, o.optimizer, o.engine)

    @property
    def structured(self) -> bool:
        """Whether the engine's own optimizer runs: CNO with the TC objective by the stabilized
        SQP or its interior point (solvers/cno/sqp.py), goal attainment by the active-set SQP
        (solvers/goal/sqp.py). 'auto' takes it for CNO only: goal attainment's optimum on noisy
        markers is a face, the structured method's point on it drifts smoothly from frame to
        frame where SLSQP's jumps, and the jump flag (solvers/quality.py) that marks MO's
        frames as untrustworthy then misses some (4 frames of the five-bar at 30 mm, whose
        joint moments are 3–3.5× NRM-WLS's worst); 'structured' takes it for MO too. CNO-ED,
        and ``optimizer='scipy'``, run through scipy (the paper's reference)."""
        if self.optimizer == "scipy" or (self.method.startswith("cno")
                                         and self.objective != "tc"):
            return False
        return self.optimizer == "structured" or self.method.startswith("cno")

    @property
    def reference(self) -> str:
        """The scipy method a structured frame falls back to."""
        return "trust-constr" if self.method == "cno-ip" else "SLSQP"


@dataclass(frozen=True)
class FrameRecord:
    q: np.ndarray
    iterations: int
    converged: bool
    message: str
    seconds: float
    phi_norm: float
    phi_top: float


def _optimize(problem: FrameProblem, settings: Settings, q0: np.ndarray,
              attempt: Iterate | None = None) -> FrameOutcome:
    """One frame from q0; ``attempt``: the structured optimizer's result from q0 where the
    compiled kernels already ran it."""
    if settings.structured:
        out = verdict(problem, settings, attempt or structured_frame(problem, settings, q0))
        if out.converged:
            return out
        scipy = _optimize(problem, replace(settings, optimizer="scipy"), q0)
        return FrameOutcome(scipy.q, out.iterations + scipy.iterations, scipy.converged,
                            f"{out.message}; {settings.reference}: {scipy.message}")
    if problem.system.redundant_topology:  # SLSQP and trust-constr need independent equalities
        problem.keep_independent(q0)
    if settings.method.startswith("cno"):
        return solve_cno_frame(problem, q0, algorithm=settings.method[4:],
                               objective=settings.objective, tol=settings.tol,
                               max_iter=settings.max_iter)
    return solve_goal_frame(problem, q0, objective=settings.method[3:], tol=settings.tol,
                            max_iter=settings.max_iter)


def structured_frame(problem: FrameProblem, settings: Settings, q0: np.ndarray) -> Iterate:
    """One frame by the engine's structured optimizer (the stabilized SQP, its interior point
    inside the problem's bounds, or goal attainment's active-set SQP). A guess far off the
    constraints (a rigid fit: the first frame, or after a failure) first goes through NRM-WLS,
    whose line search these iterations lack; from the previous frames' extrapolation they start
    at once."""
    system, tol, max_iter = problem.system, settings.tol, settings.max_iter
    before = 0
    goal = settings.method.startswith("mo")
    if np.abs(problem.constraints(q0)).max(initial=0.0) > (FAR_GOAL if goal else FAR):
        weights = without_gaps(row_weights(system, 1e-3), system, problem.missing)
        start = gauss_newton(system, q0, problem.drive, weights, tol, min(max_iter, 50), "auto")
        q0, before = start.q, start.iterations
    interior = settings.method == "cno-ip"
    if goal:
        it, _ = active_set_sqp(problem, q0, settings.method[3:], tol, min(max_iter, MAX_GOAL))
    else:
        it = stabilized_sqp(system, q0, problem.drive,
                            sqp_weights(system, problem.point_weights), tol,
                            min(max_iter, MAX_SQP), problem.bound_arrays() if interior else None)
    return Iterate(it.q, before + it.iterations, it.converged)


def verdict(problem: FrameProblem, settings: Settings, it: Iterate) -> FrameOutcome:
    """A structured optimizer's iterate judged: converged, and inside the problem's bounds."""
    name, done = STRUCTURED[settings.method]
    if not it.converged:
        return FrameOutcome(it.q, it.iterations, False,
                            f"{name}: no convergence in {it.iterations} iterations")
    if not within_bounds(problem, it.q):
        return FrameOutcome(it.q, it.iterations, False,
                            f"{name}: the optimum lies outside the bounds")
    return FrameOutcome(it.q, it.iterations, True, done)


def within_bounds(problem: FrameProblem, q: np.ndarray) -> bool:
    lower, upper = problem.bound_arrays()
    return bool(np.all((q >= lower) & (q <= upper)))


def solve_frame(system: System, settings: Settings, q0: np.ndarray, y: np.ndarray,
                attempt: Iterate | None = None) -> FrameRecord:
    """One frame with the chosen optimizer, timed, with its statistics (``attempt``: see
    :func:`_optimize`). A frame the optimizer fails from q0 is retried once from that frame's
    NRM-WLS solution (goal attainment's optimum is flat where markers are noisy, and SLSQP can
    wander off it); both tries are counted."""
    started = clock.perf_counter()
    problem = FrameProblem(system, y)
    out = _optimize(problem, settings, q0, attempt)
    if not out.converged:
        weights = without_gaps(row_weights(system, 1e-3), system, problem.missing)
        start = gauss_newton(system, q0, problem.drive, weights, settings.tol, 50, "auto")
        retry = _optimize(problem, settings, start.q)
        out = FrameOutcome(retry.q, out.iterations + start.iterations + retry.iterations,
                           retry.converged,
                           f"{out.message}; retried from the NRM-WLS solution: {retry.message}")
    seconds = clock.perf_counter() - started
    phi_norm, phi_top = problem.statistics(out.q)
    return FrameRecord(out.q, out.iterations, out.converged, out.message, seconds, phi_norm,
                       phi_top)



def method_label(method: str, objective: str = "tc", parallel: bool = False,
                 init: str = "nrm") -> str:
    """What a solve records as its method (``KinematicResult.method``) and the default run
    name starts with: the method, ``-ed`` for CNO on the distances' objective, and
    ``-parallel`` (``-parallel-<init>`` unless each frame starts from the same guess) for
    frames solved apart by the optimization methods (CNO, goal attainment); any other
    method's name as it is."""
    label = str(method)
    if not label.startswith(("cno", "mo")):
        return label
    if label.startswith("cno") and objective == "ed":
        label += "-ed"
    if parallel:
        label += "-parallel" + ("" if init == "same" else f"-{init}")
    return label

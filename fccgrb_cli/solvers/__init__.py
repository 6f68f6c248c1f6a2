"""Kinematic solution methods, one subpackage per method family, each with its numpy reference
beside its compiled engine, and one result type:

    ad/        the kinematic analysis with angular drivers, and the classical baseline
    nrm/       mixed coordinates by Newton–Raphson on (weighted) least squares
    cno/       constrained nonlinear optimization per frame: scipy's, the stabilized SQP / IP
    goal/      goal attainment per frame: scipy's SLSQP, the active-set SQP and its kernels
    optimize/  one frame's problem and the loop over frames that CNO and goal attainment share

Shared numerics beside them: ``newton`` (Newton–Raphson, Gauss–Newton), ``rates`` (q̇, q̈),
``mixed`` (a mixed-coordinate result from q), ``batched`` (stacks of frames), ``initial`` (the
first guess), ``quality`` (frames not to be trusted), ``result`` (KinematicResult), ``engine``
(numpy or compiled) and ``kernels`` (the compiled kernels' shared parts)."""

from fccgrb_cli.core.kernel_cache import configure

configure()  # before any kernel is defined: numba's cache named by the kernels' sources

from fccgrb_cli.solvers.ad.solve import assemble, solve_ad  # noqa: E402
from fccgrb_cli.solvers.result import KinematicResult  # noqa: E402

__all__ = ["KinematicResult", "assemble", "solve_ad"]

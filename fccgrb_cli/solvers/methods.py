"""The kinematic methods, by name, and the one entry point that solves a stretch of frames with
any of them (``solve_stretch``), as scipy.optimize's ``minimize`` takes its ``method``.

A method's name is a string at the edges only (the command line, a sweep's keys, a results
file's attribute); inside, :class:`Method` says what a method is: its family (its subpackage),
whether it drives the classical model by angles computed from the markers (``ad``), whether it
weighs the tracking equations."""

from __future__ import annotations

from collections.abc import Callable
from enum import Enum
from typing import Any

import numpy as np

from fccgrb_cli.solvers.result import KinematicResult
from fccgrb_cli.system import System

__all__ = ["METHODS", "Method", "mixed_runs_compiled", "solve_stretch"]


class Method(str, Enum):
    """A kinematic method (docs/formulation.md §3); equal to its name as a string."""

    AD = "ad"            # kinematic analysis with angular drivers from the markers
    NRM_LS = "nrm-ls"    # mixed coordinates, Newton–Raphson on least squares
    NRM_WLS = "nrm-wls"  # ... on weighted least squares
    CNO_SQP = "cno-sqp"  # constrained optimization per frame: SQP
    CNO_IP = "cno-ip"    # ... interior point
    MO_TC = "mo-tc"      # goal attainment on each tracking component
    MO_ED = "mo-ed"      # ... on each point's distance

    @property
    def family(self) -> str:
        """The subpackage that solves it: 'ad', 'nrm' or 'optimize' (CNO and goal
        attainment share one frame's problem and its loop)."""
        return {"ad": "ad", "nrm": "nrm"}.get(self.value.split("-")[0], "optimize")

    @property
    def drives_angles(self) -> bool:
        """Whether it is the classical route: angles from the markers, then angular drivers."""
        return self is Method.AD

    @property
    def weighted(self) -> bool:
        """Whether the tracking equations carry the tracking weight (NRM-WLS)."""
        return self is Method.NRM_WLS

    def __str__(self) -> str:
        return self.value


METHODS = tuple(m.value for m in Method)

Progress = Callable[[int, int], None] | None


def solve_stretch(method: Method | str, system: System, time: np.ndarray,
                  targets: np.ndarray, options: Any, *, source: str = "",
                  progress: Progress = None) -> KinematicResult:
    """Solve a stretch of frames, each determined by its markers, with ``method``.

    Parameters
    ----------
    method
        A :class:`Method` or its name.
    system
        The compiled system: with angular drivers for ``ad``, else with the angles as
        coordinates and the tracking rows.
    time
        (frames,) s.
    targets
        (frames, tracked points + tracked vectors, 3): the markers (m) then the tracked
        vectors (unit), as the system's tracking rows take them.
    options
        The solve's options (``pipeline.options.SolveOptions`` or any object with the fields
        each family's settings read: ``tol``, ``tracking_weight``, ``filter_cutoff``, ...).
    source
        The trial's file, for messages.
    progress
        Called with (frames done, frames) as the solve goes.

    Returns
    -------
    KinematicResult
        The frames' coordinates, rates, iterations and statuses.
    """
    method = Method(method)
    if method.family == "ad":
        from fccgrb_cli.solvers.ad.baseline import solve_baseline

        markers = targets[:, :len(system.model.tracked_points)]
        return solve_baseline(system.model, time, markers, cutoff=options.filter_cutoff,
                              order=options.filter_order, tol=options.tol, progress=progress)
    if method.family == "nrm":
        from fccgrb_cli.solvers.nrm.solve import NrmSettings, solve_nrm

        model = system.model
        labels = model.marker_labels + tuple(tv.marker for tv in model.tracked_vectors)
        return solve_nrm(system, time, targets, NrmSettings.from_options(options),
                         labels=labels, source=source, progress=progress)
    from fccgrb_cli.solvers.optimize.solve import (  # scipy.optimize: 0.1 s
        Settings,
        solve_optimization,
    )

    return solve_optimization(system, time, targets, Settings.from_options(options), progress)


def mixed_runs_compiled(method: Method | str, system: System, options: Any) -> bool:
    """Whether :func:`solve_stretch` solves with a mixed-coordinate ``method`` (not 'ad') in
    the compiled kernels: the decision its solver makes from the same options."""
    method = Method(method)
    if method.drives_angles:
        raise ValueError("mixed_runs_compiled: 'ad' is not a mixed-coordinate method")
    if method.family == "nrm":
        from fccgrb_cli.solvers.nrm.solve import NrmSettings

        return NrmSettings.from_options(options).compiled(system)
    from fccgrb_cli.solvers.optimize.solve import Settings, compiled_structured

    settings = Settings.from_options(options)
    return not settings.parallel and compiled_structured(system, settings)

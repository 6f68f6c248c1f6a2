"""The classical baseline (docs/formulation.md §6): angular drivers computed from the markers in a
pre-analysis step, optionally low-passed, then the kinematic analysis with angular drivers.

Each frame's segment frames are fitted to the markers (the rigid fits of ``initial_guess``), and
each angle is the angle between the same two vectors the model's angular coordinate names (a
distance coordinate: the fitted points' offset along its axis).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from fccgrb_cli.core.errors import InputError
from fccgrb_cli.signals.butterworth import lowpass
from fccgrb_cli.solvers.ad.solve import solve_ad, stacked_drives
from fccgrb_cli.solvers.batched import Drives
from fccgrb_cli.solvers.initial import initial_guess
from fccgrb_cli.solvers.rates import central_derivatives
from fccgrb_cli.solvers.result import KinematicResult
from fccgrb_cli.solvers.turns import counted
from fccgrb_cli.system import System, compile_system


def marker_fits(system: System, targets: np.ndarray) -> list[np.ndarray]:
    """Each frame's q from segment frames fitted to its markers (targets: frames × n_targets
    × 3); the angles follow as ``system.angles_at(q)``."""
    fits = []
    for f, y in enumerate(targets):
        if not np.all(np.isfinite(y)):
            missing = [system.model.marker_labels[k]
                       for k in np.flatnonzero(~np.all(np.isfinite(y), axis=1))
                       if k < len(system.model.marker_labels)]
            raise InputError(f"frame {f}: the angular-driver pre-analysis needs every marker; "
                             f"missing {', '.join(missing)}")
        fits.append(initial_guess(system, y))
    return fits


def drivers_from(system: System, time: np.ndarray, theta: np.ndarray, base: np.ndarray | None,
                 cutoff: float | None, order: int) -> Drives:
    """The drives of an AD analysis from angles θ(t) (frames × coordinates), optionally
    low-passed (zero-lag Butterworth of ``order`` at ``cutoff`` Hz), θ̇ and θ̈ by central
    differences; a floating base follows ``base`` (frames × slots × 3), filtered and
    differentiated alike."""
    rate = 1.0 / float(time[1] - time[0]) if len(time) > 1 else 1.0
    flat = None
    if system.n_base_slots:
        assert base is not None  # a system with a floating base is driven along it
        flat = base.reshape(len(time), -1)
    if cutoff is not None:  # the angles and the base in one pass of the filter (each column alone)
        width = theta.shape[1]
        together = lowpass(theta if flat is None else np.concatenate([theta, flat], axis=1),
                           rate, cutoff, order)
        theta = np.ascontiguousarray(together[:, :width])
        flat = None if flat is None else np.ascontiguousarray(together[:, width:])
    theta_d, theta_dd = central_derivatives(theta, 1.0 / rate)
    base_rates = None
    if flat is not None:
        assert base is not None
        d1, d2 = central_derivatives(flat, 1.0 / rate)
        r, r_d, r_dd = (a.reshape(base.shape) for a in (flat, d1, d2))
        base_rates = (r, r_d, r_dd)
    return stacked_drives(system, theta, theta_d, theta_dd, base_rates)


def solve_baseline(model, time: np.ndarray, targets: np.ndarray, *, cutoff: float | None,
                   order: int = 2, tol: float = 1e-10,
                   progress: Callable[[int, int], None] | None = None) -> KinematicResult:
    """The baseline AD run on marker targets (frames × n_targets × 3)."""
    fit_system = compile_system(model, angles="coordinate", track=True)
    fits = marker_fits(fit_system, targets)
    theta = np.array([fit_system.angles_at(q) for q in fits])
    full = fit_system.full_angles
    theta[:, full] = counted(theta[:, full], np.ones(len(theta), bool))[0]  # keep counting
    ad = compile_system(model, angles="driver")
    n_body = ad.layout.n_body_q
    base = np.array([ad.base_reference(q[:n_body]) for q in fits])
    return solve_ad(ad, time, drivers_from(ad, time, theta, base, cutoff, order),
                    fits[0][:n_body], tol=tol, progress=progress)

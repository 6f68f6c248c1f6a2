"""A solved trial (:class:`Run`): what ``pipeline.solve_trial`` returns, the results file
stores (``results.storage`` writes it, ``results.runs`` reads it back) and the Python API hands
out, with
the one-row summary the command line prints."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import TYPE_CHECKING

import numpy as np

from fccgrb_cli.anatomy.clinical import ClinicalResults
from fccgrb_cli.anatomy.lab_axes import LabAxes
from fccgrb_cli.core.named import NamedArray
from fccgrb_cli.dynamics.convert import Dynamics
from fccgrb_cli.gait.analysis import GaitResults
from fccgrb_cli.model import Model
from fccgrb_cli.model.elements import in_metres
from fccgrb_cli.pipeline.options import SolveOptions
from fccgrb_cli.solvers.methods import Method
from fccgrb_cli.solvers.result import KinematicResult

if TYPE_CHECKING:  # what only some solves hold (their modules load where a solve makes them)
    from fccgrb_cli.dynamics.reduction import Reduction
    from fccgrb_cli.dynamics.residuals import ResidualReport
    from fccgrb_cli.pipeline.smoothing import Uncertainty
    from fccgrb_cli.plugin_gait.outputs import PluginGaitResults

__all__ = ["Run", "mean_jump", "summary"]


@dataclass(frozen=True, repr=False)
class Run:
    """A solved trial: the options it was solved with, the kinematic result (with each frame's
    quality flags), the markers it saw, the model points it reached, and the inverse dynamics.

    The properties give the arrays by name and unit (:class:`NamedArray`): ``angles``,
    ``angular_velocities``, ``angular_accelerations`` (rad, rad/s, rad/s²; m for distances),
    ``q``, ``qd``, ``qdd``, ``moments`` (N·m; N for distances), ``clinical_angles`` (deg),
    ``clinical_moments`` (N·m/kg), ``angle_sd`` and ``moment_sd`` (with the smoother), and the
    per-frame ``trusted`` (n_frames) and per-joint ``moments_trusted`` (n_frames × n_angles).

    Attributes
    ----------
    name : str
        The run's name in a results file.
    options : SolveOptions
        The options it was solved with.
    result : KinematicResult
        The kinematic solution: q, θ and their rates, each frame's iterations, time, ‖Φ‖,
        max |Φ_top| and quality flags (docs/formulation.md §11).
    labels : tuple of str
        The tracked markers (n_markers), in the order of the marker arrays.
    rate : float
        Frame rate (Hz).
    reference, markers_input, model_points : ndarray
        n_frames × n_markers × 3 (m): the reference markers (the trial's, or a synthesized
        trial's exact ones), the markers the solver saw (with any artefact added), and the
        model's tracked points.
    ed, ed_input : ndarray
        n_frames × n_markers (m): each model point's distance to its reference marker and to
        its input marker.
    truth_theta : ndarray or None
        n_frames × n_angles (rad; m for distances): a synthesized trial's exact coordinates.
    dynamics : Dynamics or None
        The classical model's kinematics and inverse dynamics (docs/formulation.md §4).
    warnings, notes : tuple of str
        What the solve warned of, and what it reported.
    moment_flags : ndarray or None
        n_frames × n_angles: why each joint moment is not trusted (bits; 0 = trusted).
    start_time : float
        The first frame's time on the trial file's clock (s).
    clinical, gait, axes, uncertainty, plugin_gait, residuals, reduction
        The gait model's clinical curves, gait events and cycles, the lab's axes, the
        smoother's standard deviations, Plug-in Gait outputs, a floating base's residuals and
        their reduction, where the run has them (else None).
    """

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
    moment_flags: np.ndarray | None = None
    axes: LabAxes | None = None
    uncertainty: Uncertainty | None = None
    plugin_gait: PluginGaitResults | None = None
    start_time: float = 0.0  # s: the first frame's time on the trial file's clock
    residuals: ResidualReport | None = None
    reduction: Reduction | None = None

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
        unweighted = Method(self.options.method) is Method.NRM_LS
        return None if unweighted else self.options.tracking_weight

    @property
    def warm_start(self) -> str:
        return self.options.warm_start

    @property
    def hessian(self) -> str:
        return "" if Method(self.options.method).drives_angles else self.options.hessian

    @property
    def ad_drivers(self) -> str:
        return self.options.ad_drivers if Method(self.options.method).drives_angles else ""

    @property
    def filter_cutoff(self) -> float | None:
        return self.options.filter_cutoff

    # --- the Python API's view: named arrays with units ------------------------------------
    @cached_property
    def model(self) -> Model:
        """The model as solved (the run's YAML with the options' form and tracked markers, and
        the gravity of the lab's axes)."""
        from fccgrb_cli.model import parse_model
        from fccgrb_cli.pipeline.options import prepared

        model = prepared(parse_model(self.model_text, self.trial_path), self.options)
        return model if self.axes is None else model.with_gravity(self.axes.gravity)

    def _named(self, values: np.ndarray, names: tuple[str, ...], units: tuple[str, ...]
               ) -> NamedArray:
        return NamedArray(values, names, units, self.result.time + self.start_time)

    @property
    def angle_units(self) -> tuple[str, ...]:
        """Each coordinate's unit in the model's order: 'rad', or 'm' for a distance or a
        moving joint's translation (what storage writes beside the angles)."""
        return tuple("m" if in_metres(a) else "rad" for a in self.model.angles)

    @property
    def angles(self) -> NamedArray:
        """Every joint angle (rad; a distance coordinate in m) per frame."""
        return self._named(self.result.theta, self.result.angle_names, self.angle_units)

    @property
    def angular_velocities(self) -> NamedArray:
        """θ̇ (rad/s; m/s for distances), by central differences of the solved θ."""
        return self._named(self.result.theta_d, self.result.angle_names,
                           tuple(f"{u}/s" for u in self.angle_units))

    @property
    def angular_accelerations(self) -> NamedArray:
        """θ̈ (rad/s²; m/s² for distances)."""
        return self._named(self.result.theta_dd, self.result.angle_names,
                           tuple(f"{u}/s²" for u in self.angle_units))

    def _coordinates(self, values: np.ndarray, per: str) -> NamedArray:
        names, units = [], []
        for body in self.model.bodies:
            for vector in ("r", "u", "v", "w")[: 4 if body.form == "full" else 3]:
                names += [f"{body.name}.{vector}.{axis}" for axis in "xyz"]
                units += [("m" if vector == "r" else "1") + per] * 3
        if values.shape[1] > len(names):  # mixed coordinates: the angles follow
            names += list(self.result.angle_names)
            units += [u + per for u in self.angle_units]
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
                           tuple("N" if u == "m" else "N·m" for u in self.angle_units))

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
    def angle_sd(self) -> NamedArray | None:
        """The smoother's standard deviation of every angle (rad; m for distances), None
        without ``--smooth auto``."""
        u = self.uncertainty
        return None if u is None else self._named(u.theta_sd, self.result.angle_names,
                                                  self.angle_units)

    @property
    def moment_sd(self) -> NamedArray | None:
        """The joint moments' standard deviations (N·m; N for distances), None without the
        smoother or the dynamics."""
        u = self.uncertainty
        if u is None or u.moments_sd is None:
            return None
        return self._named(u.moments_sd, self.result.angle_names,
                           tuple("N" if unit == "m" else "N·m" for unit in self.angle_units))

    @property
    def clinical_sd(self) -> tuple[NamedArray, NamedArray | None] | None:
        """The clinical angles' standard deviations (deg) and their moments' (N·m/kg when the
        subject's mass is known, else N·m; None without the dynamics): the angles' own, as
        a clinical curve is ±(θ − 90°) and its moment ±τ."""
        c, u = self.clinical, self.uncertainty
        if c is None or u is None:
            return None
        index = [self.result.angle_names.index(name) for name in c.names]
        angles = self._named(np.degrees(u.theta_sd[:, index]), c.names, ("deg",) * len(index))
        if u.moments_sd is None:
            return angles, None
        per_kg = c.mass is not None
        values = u.moments_sd[:, index] / (c.mass if per_kg else 1.0)
        unit = "N·m/kg" if per_kg else "N·m"
        return angles, self._named(values, c.names, (unit,) * len(index))

    @property
    def trusted(self) -> np.ndarray:
        """Per frame: converged and not flagged by the quality checks."""
        return self.result.trusted

    @property
    def moments_trusted(self) -> np.ndarray | None:
        """Per frame and joint (frames × angles): the moment is trusted — the frame's
        kinematics and the moment's own checks (``solvers.quality.MOMENT_BITS``: the dynamics
        ran there, every contact load measured, accelerations not noise); None without the
        dynamics."""
        if self.dynamics is None:
            return None
        if self.moment_flags is None:  # a run read from a file written without them
            return np.broadcast_to(self.trusted[:, None],
                                   self.dynamics.inverse.joint_moments.shape).copy()
        return self.moment_flags == 0

    def summary(self) -> dict[str, float | str | int]:
        """The one-row summary the command line prints.

        Returns
        -------
        dict of str to float, str or int
            ``run``, ``method``; ``ms/frame`` and ``iter/frame`` (the solve's cost);
            ``mean |Phi|`` and ``max |Phi_top|`` (m and unitless); ``mean ED mm`` and
            ``max ED mm`` (model points to reference markers over the solved frames);
            ``jump mm``; ``failed`` and ``flagged`` frame counts; with a truth file
            ``max |dθ| deg`` (and ``max |dd| mm`` for distances); with a floating base's
            residual ``residual F %BW`` and ``residual M N·m``; with dynamics ``max |τ| N·m``
            (and ``max |F| N`` for distances).
        """
        return summary(self)

    def to_dataframe(self):
        """One row per frame: time, trusted, the angles, their moments and the clinical curves
        (columns 'name [unit]'); needs pandas.

        Returns
        -------
        pandas.DataFrame
            n_frames rows indexed by time (s); columns ``trusted``, then each angle, each
            moment (prefix ``moment``), each clinical angle and moment (prefixes ``clinical``,
            ``clinical moment``), in the units their names carry.
        """
        import pandas as pd

        parts = [self.angles.to_dataframe()]
        parts += [a.to_dataframe().add_prefix(prefix) for prefix, a in (
            ("moment ", self.moments), ("clinical ", self.clinical_angles),
            ("clinical moment ", self.clinical_moments)) if a is not None]
        frame = pd.concat(parts, axis=1)
        frame.insert(0, "trusted", self.trusted)
        return frame


def mean_jump(points: np.ndarray) -> float:
    """Mean frame-to-frame displacement of the model points (m): noise in a trajectory shows
    as a larger jump than the motion itself needs (compare runs of the same trial)."""
    if len(points) < 2:
        return 0.0
    if not points.shape[1]:  # no markers (a run of given coordinates)
        return float("nan")
    return float(np.nanmean(np.linalg.norm(np.diff(points, axis=0), axis=2)))


def summary(run: Run) -> dict[str, float | str | int]:
    """The one-row summary: method, ms/frame, iterations/frame, ‖Φ‖, topology, ED (mm)."""
    r = run.result
    ok = np.isfinite(run.ed).all(axis=1) & r.converged & bool(run.labels)  # markers solved
    per_frame = r.wall_s / r.n_frames if np.isfinite(r.wall_s) else float(np.nanmean(r.time_s))
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
    if not run.labels:  # a run of given coordinates (``--coordinates``) has no markers
        for key in ("mean ED mm", "max ED mm", "jump mm"):
            del row[key]
    if run.truth_theta is not None:
        err = np.abs(r.theta - run.truth_theta)[ok]
        distance = np.array(run.angle_units) == "m"
        angle_err = err[:, ~distance]
        row["max |dθ| deg"] = float(np.degrees(angle_err.max())) if angle_err.size else float("nan")
        if distance.any():
            row["max |dd| mm"] = 1e3 * float(err[:, distance].max()) if err.size else float("nan")
    if run.residuals is not None:
        over = run.residuals.over_measured
        row["residual F %BW"] = over.force_rms_bw
        row["residual M N·m"] = over.moment_rms
    if run.dynamics is not None:  # over the trusted moments only
        trusted = run.moments_trusted
        assert trusted is not None  # given with the dynamics
        loads = np.where(trusted, np.abs(run.dynamics.inverse.joint_moments), np.nan)
        distance = np.array(run.angle_units) == "m"
        for key, columns in (("max |τ| N·m", ~distance), ("max |F| N", distance)):
            if columns.any() and (key == "max |τ| N·m" or distance.any()):
                some = loads[:, columns]
                # a slide's joint force (N) is not a moment
                row[key] = float(np.nanmax(some)) if np.isfinite(some).any() else float("nan")
    return row

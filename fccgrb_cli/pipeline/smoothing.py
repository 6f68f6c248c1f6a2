"""The smoothing stage of a solve (``--smooth auto``, docs/formulation.md §12): the whole trial's
driver coordinates and their rates from every frame's markers at once (``solvers/smooth``), the
run's kinematics replaced by them, the classical model driven by them, and the uncertainty of every
angle, rate and joint moment.

What the stage hands on:

* the smoothed kinematic result: q from the topological equations at the smoothed coordinates
  (so every constraint holds to rounding on every frame), q̇ and q̈ from Φ_q q̇ = ν and
  Φ_q q̈ = γ with the smoothed θ̇, θ̈ (and a floating base's rates), ‖Φ‖ and max |Φ_top|
  evaluated there; each frame's iterations, time and quality flags stay the per-frame solve's
  (a frame not solved gave the smoother no data and stays flagged: the prior bridged it; a
  frame solved but flagged, e.g. for a poor fit, still gives its markers: bridging 70 such
  frames by the prior put a foot 0.8 m from its markers);
* the drives of the classical model (the smoothed θ, θ̇, θ̈ and base features with their rates),
  which the inverse dynamics takes instead of differencing θ;
* each force plate's cutoff: the smoother's own filter (``solvers/smooth/signal.py``) at the
  median of the equivalent cutoffs of the coordinates between the root (the ground or the
  floating base) and the body it loads, so that the ground reaction and the accelerations that
  balance it are smoothed alike (Bisseling & Hof 2006; Kristianslund et al. 2012);
* the standard deviations (``Uncertainty``) of θ, θ̇, θ̈ from the smoother's covariance and of
  the joint moments through the inverse dynamics linearized at each frame
  (``dynamics/uncertainty.py``).
"""

from __future__ import annotations

import time as clock
from collections.abc import Sequence
from dataclasses import dataclass, replace
from functools import partial
from itertools import pairwise
from typing import TYPE_CHECKING

import numpy as np

from fccgrb_cli.core.errors import InputError
from fccgrb_cli.dynamics.loads import ExternalLoad
from fccgrb_cli.model import Model
from fccgrb_cli.model.spatial import JointCoordinate
from fccgrb_cli.solvers.batched import Drives, Stacked, blocks
from fccgrb_cli.solvers.methods import Method
from fccgrb_cli.solvers.rates import consistent_rates
from fccgrb_cli.solvers.result import KinematicResult
from fccgrb_cli.system import System, compile_system
from fccgrb_cli.system.constraints import joint_neighbours
from fccgrb_cli.system.sparse import supported

if TYPE_CHECKING:  # the smoother itself is imported where a solve asks for it (--smooth auto)
    from fccgrb_cli.solvers.smooth import SmoothedMotion, SmoothSettings
    from fccgrb_cli.solvers.smooth.coordinates import Coordinates


@dataclass(frozen=True)
class Uncertainty:
    """Per frame the standard deviation of every angle (rad; m for a distance), its rate and
    acceleration, and its joint moment (N·m; N for a distance; None without the dynamics), as
    the marker noise makes them scatter; and how the smoother was set: the markers' white noise
    σ (m), and for every smoothed coordinate (the angles, then a floating base's origin and
    rotation vector) its equivalent cutoff (Hz) and its own noise beyond the markers' (rad or
    m), whether these were estimated from the data, and the smoother's wall time (s)."""

    theta_sd: np.ndarray
    theta_d_sd: np.ndarray
    theta_dd_sd: np.ndarray
    moments_sd: np.ndarray | None
    noise_m: float
    coordinates: tuple[str, ...]
    cutoffs_hz: np.ndarray
    extra_sd: np.ndarray
    estimated: bool
    seconds: float = float("nan")

    def describe(self) -> str:
        """The note a solve prints: the noise found and the cutoffs' range."""
        how = "maximum likelihood" if self.estimated else "as given"
        extra = float(np.max(self.extra_sd, initial=0.0))
        own = (f", the coordinates' own noise up to {np.degrees(extra):.2g} deg"
               if extra > 0 else "")
        return (f"smoothed (--smooth auto): marker noise {1e3 * self.noise_m:.3g} mm "
                f"(from the residuals){own}; equivalent cutoffs "
                f"{self.cutoffs_hz.min():.3g}–{self.cutoffs_hz.max():.3g} Hz ({how})")


@dataclass(frozen=True)
class Smoothing:
    """The stage's answer: the smoothed motion, the kinematic result made of it, the classical
    model's drives and the classical system."""

    motion: SmoothedMotion
    result: KinematicResult
    drives: Drives
    system: System
    seconds: float

    def plate_cutoff(self, body: str) -> float:
        """The cutoff (Hz) for a load on ``body`` (see the module's docstring)."""
        chain = chain_coordinates(self.system.model, body, self.motion.coordinates.names)
        return float(np.median(self.motion.cutoffs[chain]))

    def smoothed_loads(self, loads: Sequence[ExternalLoad], rate: float
                       ) -> list[ExternalLoad]:
        """Each load's force and free moment through the smoother's filter at its cutoff."""
        from fccgrb_cli.solvers.smooth.signal import smoothed_signal

        out = []
        for load in loads:
            cutoff = self.plate_cutoff(load.body)
            out.append(load.filtered(partial(smoothed_signal, rate=rate, cutoff_hz=cutoff)))
        return out

    def uncertainty(self, q: np.ndarray | None, loads: Sequence[ExternalLoad]) -> Uncertainty:
        """The standard deviations, the moments' at the classical model's positions ``q``
        (None: no dynamics)."""
        from fccgrb_cli.dynamics.uncertainty import moment_uncertainty

        motion = self.motion
        na = len(self.system.angle_rows)
        sd = motion.sd
        moments = None
        if q is not None:
            co = motion.coordinates
            lin = co.linearize(motion.d, q)
            moments = moment_uncertainty(co, lin.q, lin.S, motion.d, motion.d_d, motion.d_dd,
                                         motion.covariance, loads).sd
        return Uncertainty(sd[:, 0, :na], sd[:, 1, :na], sd[:, 2, :na], moments, motion.noise,
                           motion.coordinates.names, motion.cutoffs, motion.extra_sd,
                           motion.estimated, self.seconds)


def chain_coordinates(model: Model, body: str, names: tuple[str, ...]) -> np.ndarray:
    """Indices of the coordinates (among ``names``) that move ``body``: the angles and
    distances between consecutive bodies on its path from the root (the ground or its floating
    base) and that base's own coordinates; every coordinate where none is found."""
    neighbours = joint_neighbours(model)
    roots = ["ground", *model.floating_bases]
    path: list[str] = []
    for root in roots:
        found = _path(neighbours, root, body)
        if found:
            path = found
            break
    pairs = {frozenset(p) for p in pairwise(path)}
    picked = []
    for k, a in enumerate(model.angles):
        assert not isinstance(a, JointCoordinate)  # the smoother takes no moving joints
        if frozenset((a.body1, a.body2)) in pairs:
            picked.append(k)
    if path and path[0] != "ground":
        picked += [k for k, name in enumerate(names) if name.startswith(f"{path[0]}.")]
    return np.array(picked if picked else range(len(names)), dtype=int)


def _path(neighbours: dict[str, set[str]], start: str, goal: str) -> list[str]:
    """A path of joined bodies from ``start`` to ``goal`` (breadth first), [] if none."""
    previous = {start: ""}
    frontier = [start]
    while frontier:
        following = []
        for node in frontier:
            for other in sorted(neighbours.get(node, ())):
                if other not in previous:
                    previous[other] = node
                    following.append(other)
        frontier = following
    if goal not in previous:
        return []
    out = [goal]
    while out[-1] != start:
        out.append(previous[out[-1]])
    return out[::-1]


def smooth(model: Model, result: KinematicResult, markers: np.ndarray,
           settings: SmoothSettings) -> Smoothing:
    """The stage on a mixed-coordinate ``result`` whose frames followed ``markers`` (frames ×
    tracked points × 3, NaN where missing): frames not solved give no data."""
    from fccgrb_cli.solvers.smooth import smooth_motion

    started = clock.perf_counter()
    system = compile_system(model, angles="driver")
    use = result.converged & np.isfinite(result.q).all(axis=1)
    motion = smooth_motion(system, result.time, markers, use, result.q, settings)
    seconds = clock.perf_counter() - started
    co = motion.coordinates
    drives = co.drives(motion.d, motion.d_d, motion.d_dd)
    mixed = compile_system(model, angles="coordinate", track=True)
    na = co.n_angles
    q = np.concatenate([motion.q, motion.d[:, :na]], axis=1)
    qd, qdd = consistent_rates(mixed, q, motion.d_d[:, :na], motion.d_dd[:, :na],
                               _base_rates(co, drives),
                               compiled=settings.engine == "compiled" and supported(mixed))
    phi_norm, phi_top = _residuals(mixed, q, markers)
    smoothed = replace(result, q=q, qd=qd, qdd=qdd, theta=q[:, -na:] if na else q[:, :0],
                       theta_d=motion.d_d[:, :na], theta_dd=motion.d_dd[:, :na],
                       phi_norm=phi_norm, phi_top_max=phi_top)
    return Smoothing(motion, smoothed, drives, system, seconds)


def _base_rates(co: Coordinates, drives: Drives
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """Each floating base's q columns (r, u, v, w) with the smoothed rates of those features
    (ṙ, u̇ = ω × u, …; their second derivatives): the rows rates.consistent_rates adds to the
    topology for what it leaves free (None without a base)."""
    if not co.bases:
        return None
    columns = np.concatenate([chart.columns.ravel() for chart in co.bases])
    slots = np.concatenate([chart.slots for chart in co.bases])
    n = len(drives.theta)
    return (columns, drives.ref_d[:, slots].reshape(n, -1),
            drives.ref_dd[:, slots].reshape(n, -1))


def _residuals(mixed: System, q: np.ndarray, markers: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray]:
    """‖Φ‖ over the rows a frame's markers keep, and max |Φ_top|, of the mixed system at q
    (every frame at once: batched.Stacked with the angles as its drives)."""
    masks = mixed.masks()
    top, tracking = masks["topology"], np.flatnonzero(masks["tracking"])
    n_body = mixed.layout.n_body_q
    norm, top_max = np.empty(len(q)), np.empty(len(q))
    stacked = Stacked(mixed)
    for block in blocks(len(q)):
        present = np.isfinite(markers[block]).all(axis=2)
        ref = np.where(present[..., None], markers[block], 0.0)
        theta = q[block, n_body:]
        still = np.zeros_like(ref)
        phi = stacked.residual(q[block, :n_body], Drives(theta, np.zeros_like(theta),
                                                          np.zeros_like(theta), ref, still,
                                                          still))
        keep = np.broadcast_to(top, phi.shape).copy()
        keep[:, tracking] = np.repeat(present, 3, axis=1)
        norm[block] = np.sqrt(np.sum(np.where(keep, phi, 0.0) ** 2, axis=1))
        top_max[block] = np.abs(phi[:, top]).max(axis=1)
    return norm, top_max


def applies(options, model: Model) -> str | None:
    """Why ``--smooth auto`` does not apply to this solve (None: it does)."""
    if Method(options.method).drives_angles:
        return "the classical AD baseline keeps its own drivers (the paper's)"
    if options.filter_cutoff is not None:
        return "--filter-cutoff asks for the Butterworth filter instead"
    if model.tracked_vectors:
        return "the model tracks vectors; the smoother takes tracked points only"
    if model.moving_joints:
        return "the smoother does not take moving joints (an imported OpenSim model) yet"
    return None


def settings_of(options, model: Model) -> SmoothSettings:
    """The smoother's settings from a solve's options and its model."""
    from fccgrb_cli.solvers.smooth import SmoothSettings

    noise = None if options.smooth_noise is None else 1e-3 * options.smooth_noise
    engine = "numpy" if options.engine == "numpy" else "compiled"
    return SmoothSettings(noise=noise, cutoff=options.smooth_cutoff, engine=engine,
                          weights=marker_weights(model, options))


def marker_weights(model: Model, options) -> tuple[float, ...] | None:
    """Each tracked point's weight as the frames' own solve gave it, so that the smoother
    fits the markers as that solve did (None: all equal): NRM-LS none (W = I), NRM-WLS the
    point's own weight or --tracking-weight, the optimizers the point's own or 1."""
    method = Method(options.method)
    if method is Method.NRM_LS:
        return None
    default = options.tracking_weight if method.weighted else 1.0
    weights = tuple(default if tp.weight is None else tp.weight for tp in model.tracked_points)
    return None if len(set(weights)) <= 1 else weights


def smoothed_or_warned(model: Model, result: KinematicResult, markers: np.ndarray,
                       options, warnings: list[str]) -> Smoothing | None:
    """The stage where the options ask for it and it applies; a warning where it cannot run
    (a trial too short, a chart the base leaves), and the per-frame result then goes on."""
    if options.smooth != "auto":
        return None
    why = applies(options, model)
    if why is not None:
        warnings.append(f"--smooth auto not applied: {why}")
        return None
    try:
        return smooth(model, result, markers, settings_of(options, model))
    except InputError as error:
        warnings.append(f"{error}; the rates come from central differences instead")
        return None

"""The whole trial smoothed at once: Gauss–Newton on the maximum a posteriori motion.

The unknowns are the driver coordinates d(t) of every frame (``coordinates.py``) with their
derivatives; the prior says each coordinate is an integrated Wiener process of order p
(``prior.py``), the markers say y_f = p(d_f) + noise of σ per coordinate. Each iteration
linearizes p at the current d (positions by the topological equations, so every iterate is an
assembled mechanism), and the linear smoother (``filter.py``, compiled in ``kernels.py``) solves
the linearized problem over all frames in O(frames); the iteration stops when d moves less than
``STEP`` (a few iterations: the markers' model is nearly linear over the noise's size). The
first linearization, at each frame's own solution, also gives the smoothing strength
(``noise.py``) unless it is given.

A frame whose markers are not to be used (not solved, or flagged by the quality checks) or that
has none carries no information: the prior bridges it (a polynomial of degree 2p − 1 through the
neighbouring data, as a spline would, never a filter's ringing), with a standard deviation that
says how far it can be trusted.

The answer per frame: d, ḋ, d̈ (consistent by construction: the derivatives are the prior's own
states), the covariance the marker noise gives them, and q with the topology to 1e-12.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fccgrb_cli.errors import InputError
from fccgrb_cli.solvers.smooth import filter as reference
from fccgrb_cli.solvers.smooth.coordinates import Coordinates
from fccgrb_cli.solvers.smooth.noise import FrameEstimates, Strength, marker_noise, strength
from fccgrb_cli.solvers.smooth.prior import DERIVATIVES, ORDER, density
from fccgrb_cli.solvers.smooth.start import WINDOW, initial_state
from fccgrb_cli.system import System
from fccgrb_cli.system.sparse import compilable

STEP = 1e-6  # rad or m: Gauss–Newton stops when d moves less (its next step is ~1e-8)
ITERATIONS = 8


@dataclass(frozen=True)
class SmoothSettings:
    """The smoother's options: the markers' noise σ (m) and each coordinate's equivalent
    cutoff (Hz), None to estimate them from the data; the engine ('compiled': the numba
    passes, 'numpy': the reference)."""

    noise: float | None = None
    cutoff: float | None = None
    engine: str = "compiled"


@dataclass(frozen=True)
class Motion:
    """The smoothed motion: the coordinates' names and units, d, ḋ, d̈ (frames × n), the
    covariance of (d, ḋ, d̈) that the noise gives (frames × 3n × 3n, derivative-major), q of
    the classical system (frames × nq), the frames whose markers were used, the markers' noise
    σ (m), each coordinate's strength (noise.Strength: cutoff, extra noise), whether the
    cutoffs were estimated, the Gauss–Newton iterations, and the chart of the coordinates."""

    coordinates: Coordinates
    d: np.ndarray
    d_d: np.ndarray
    d_dd: np.ndarray
    covariance: np.ndarray
    q: np.ndarray
    used: np.ndarray
    noise: float
    strengths: tuple[Strength, ...]
    estimated: bool
    iterations: int

    @property
    def cutoffs(self) -> np.ndarray:
        """Each coordinate's equivalent cutoff (Hz)."""
        return np.array([s.cutoff for s in self.strengths])

    @property
    def extra_sd(self) -> np.ndarray:
        """Each coordinate's own noise beyond the markers' (its unit: rad or m)."""
        return np.sqrt([s.extra for s in self.strengths])

    @property
    def sd(self) -> np.ndarray:
        """Standard deviations of d, ḋ, d̈ (frames × 3 × n)."""
        n = self.d.shape[1]
        var = np.diagonal(self.covariance, axis1=1, axis2=2)
        return np.sqrt(np.maximum(var, 0.0)).reshape(len(var), DERIVATIVES, n)


def smooth_motion(system: System, time: np.ndarray, markers: np.ndarray, use: np.ndarray,
                  mixed_q: np.ndarray, settings: SmoothSettings = SmoothSettings()) -> Motion:
    """Smooth a trial: ``system`` the classical model (angles='driver'), ``markers`` the
    tracked points' targets (frames × markers × 3, NaN where missing), ``use`` the frames
    whose markers may be used, ``mixed_q`` each frame's mixed-coordinate solution (NaN where
    unsolved): the start of the iteration."""
    solved = np.isfinite(mixed_q).all(axis=1)
    usable = use & solved
    need = WINDOW * ORDER
    if usable.sum() < need:
        raise InputError(f"--smooth auto: the trial has {int(usable.sum())} frames the markers "
                         f"determine and the quality checks trust; the smoother needs {need}")
    coordinates = Coordinates.build(system, mixed_q, np.flatnonzero(usable))
    d = _bridged(time, coordinates.from_mixed(np.where(solved[:, None], mixed_q, 0.0)),
                 solved)
    q = _nearest(mixed_q[:, :system.layout.n_body_q], solved)
    present = np.isfinite(markers).all(axis=2) & usable[:, None]
    y = np.where(present[..., None], markers, 0.0)
    W = np.repeat(present, 3, axis=1).astype(float)
    passes = _passes(settings.engine)
    chains = None
    noise = settings.noise
    for iteration in range(ITERATIONS + 1):
        lin = coordinates.linearize(d, q, passes.compiled and compilable(system))
        r = (y - lin.points).reshape(len(d), -1) * W
        HW = lin.H * W[:, :, None]
        A = np.einsum("fri,frj->fij", HW, lin.H)
        b = np.einsum("fri,fr->fi", HW, r) + np.einsum("fij,fj->fi", A, d)
        if chains is None:
            noise = noise if noise is not None else _noise(A, b, d, lin.H, r, W)
            chains, strengths = _chains(time, A / noise**2, b / noise**2, coordinates,
                                        settings, passes)
            extra = np.array([s.extra for s in strengths])
        A_info, b_info = with_extra_noise(A / noise**2, b / noise**2, extra)
        last = iteration == ITERATIONS
        values, cov = passes(chains, A_info, b_info, last)
        step = float(np.abs(values[:, 0] - d).max())
        q = lin.q + np.einsum("fqk,fk->fq", lin.S, values[:, 0] - d)  # the next guesses
        d = values[:, 0]
        if last:
            break
        if step < STEP:  # one more pass at this linearization, with the covariance
            values, cov = passes(chains, A_info, b_info, True)
            d = values[:, 0]
            break
    q = coordinates.linearize(d, q, passes.compiled and compilable(system)).q
    return Motion(coordinates, d, values[:, 1], values[:, 2], cov, q, usable, float(noise),
                  strengths, settings.cutoff is None, iteration + 1)


def _noise(A: np.ndarray, b: np.ndarray, d: np.ndarray, H: np.ndarray, r: np.ndarray,
           W: np.ndarray) -> float:
    """σ from the residuals of each frame's own fit (noise.marker_noise)."""
    est = FrameEstimates.of(A, b)
    full = np.isfinite(est.z).all(axis=1)
    step = np.where(full[:, None], est.z - d, 0.0)
    e = r - np.einsum("fri,fi->fr", H, step)
    inverse = np.zeros_like(A)
    inverse[full] = np.linalg.inv(A[full])
    leverage = np.einsum("fri,fij,frj->fr", H, inverse, H)
    keep = (W > 0) & full[:, None]
    return marker_noise(np.where(keep, e, np.nan), np.where(keep, leverage, np.nan))


def with_extra_noise(A: np.ndarray, b: np.ndarray, extra: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray]:
    """A frame's information about d when its estimate also carries white noise of variance
    Σ = diag(extra) on the coordinates: (Σ + A⁻¹)⁻¹ = (I + A Σ)⁻¹ A and (I + A Σ)⁻¹ b, which
    stay defined where A is singular."""
    if not np.any(extra):
        return A, b
    G = np.eye(A.shape[1]) + A * extra[None, None, :]
    A_new = np.linalg.solve(G, A)
    return 0.5 * (A_new + A_new.transpose(0, 2, 1)), np.linalg.solve(G, b[..., None])[..., 0]


def _chains(time: np.ndarray, A: np.ndarray, b: np.ndarray, coordinates: Coordinates,
            settings: SmoothSettings, passes) -> tuple[reference.Chains, tuple[Strength, ...]]:
    """Each coordinate's prior: its strength (estimated by maximum likelihood, the cutoff
    given where it is), its spectral density at its frames' median variance, and its first
    frame's prior."""
    est = FrameEstimates.of(A, b)
    dt = float(time[1] - time[0])
    n = coordinates.n
    strengths = tuple(strength(time, est.z[:, k], est.variance[:, k], passes.log_likelihood,
                               settings.cutoff) for k in range(n))
    extra = np.array([s.extra for s in strengths])
    cutoffs = np.array([s.cutoff for s in strengths])
    seen = np.isfinite(est.variance)
    variance = est.variance + extra
    r = np.array([np.median(variance[seen[:, k], k]) for k in range(n)])
    scale = 2.0 * np.pi * cutoffs
    means, covs = zip(*(initial_state(time, np.where(seen[:, k], est.z[:, k], 0.0),
                                      variance[:, k], ORDER, scale[k]) for k in range(n)),
                      strict=True)
    return reference.Chains.build(ORDER, dt, scale, density(cutoffs, r, dt), np.array(means),
                                  np.array(covs)), strengths


class _Passes:
    """The linear smoother's passes and the scalar likelihood in one engine."""

    def __init__(self, compiled: bool) -> None:
        self.compiled = compiled
        if compiled:
            from fccgrb_cli.solvers.smooth import kernels

            self.log_likelihood = kernels.log_likelihood
            self._kernel = kernels.smooth_passes
        else:
            self.log_likelihood = reference.log_likelihood

    def __call__(self, chains: reference.Chains, A: np.ndarray, b: np.ndarray,
                 covariance: bool) -> tuple[np.ndarray, np.ndarray | None]:
        """(frames × 3 × n values, frames × 3n × 3n covariance or None), unscaled."""
        if not self.compiled:
            out = reference.smooth(chains, A, b, covariance=covariance)
            return out.values, out.covariance
        N, n = b.shape
        values = np.empty((N, DERIVATIVES * n))
        cov = np.empty((N if covariance else 0, DERIVATIVES * n, DERIVATIVES * n))
        self._kernel(chains.arrays(), np.ascontiguousarray(A), np.ascontiguousarray(b),
                     covariance, values, cov)
        unscale = chains.unscale()
        values = (values * unscale).reshape(N, DERIVATIVES, n)
        return values, (cov * unscale[:, None] * unscale[None, :]) if covariance else None


def _passes(engine: str) -> _Passes:
    return _Passes(engine != "numpy")


def _bridged(time: np.ndarray, d: np.ndarray, known: np.ndarray) -> np.ndarray:
    """d with the frames not known linearly interpolated (held at the ends): the start of the
    iteration there."""
    out = d.copy()
    if known.all():
        return out
    idx = np.flatnonzero(known)
    for k in range(d.shape[1]):
        out[~known, k] = np.interp(time[~known], time[idx], d[idx, k])
    return out


def _nearest(q: np.ndarray, known: np.ndarray) -> np.ndarray:
    """Each unknown frame's guess: the nearest known frame's q."""
    out = q.copy()
    if known.all():
        return out
    idx = np.flatnonzero(known)
    for f in np.flatnonzero(~known):
        out[f] = q[idx[np.argmin(np.abs(idx - f))]]
    return out

"""The whole trial smoothed at once: Gauss–Newton on the maximum a posteriori motion.

The unknowns are the driver coordinates d(t) of every frame (``coordinates.py``) with their
derivatives; the prior says each coordinate is an integrated Wiener process of order p
(``prior.py``), the markers say y_f = p(d_f) + noise of σ/√w_i per coordinate of marker i, w_i
its weight relative to the largest (1 for every marker unless the model weighs its tracked
points: the per-frame weighted least squares the smoother replaces, docs/formulation.md §3.1). Each
iteration linearizes p at the current d (positions by the topological equations, so every iterate is
an assembled mechanism), and the linear smoother (``filter.py``, compiled in ``kernels.py``) solves
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

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from fccgrb_cli.core.errors import InputError
from fccgrb_cli.solvers.smooth import filter as reference
from fccgrb_cli.solvers.smooth.coordinates import AssemblyError, Coordinates
from fccgrb_cli.solvers.smooth.noise import (
    ESTIMATE_FRAMES,
    FrameEstimates,
    Strength,
    marker_noise,
    strength,
)
from fccgrb_cli.solvers.smooth.prior import DERIVATIVES, ORDER, density
from fccgrb_cli.solvers.smooth.start import WINDOW, initial_state
from fccgrb_cli.system import System
from fccgrb_cli.system.sparse import compilable

SPAN_BYTES = 5e8  # the passes' arrays of one span of a long trial, at most
DECAY = 20.0  # e-folds of the smoother's influence a span's overlap covers
STEP = 1e-6  # rad or m: Gauss–Newton stops when d moves less (its next step is ~1e-8)
ITERATIONS = 8


@dataclass(frozen=True)
class SmoothSettings:
    """The smoother's options: the markers' noise σ (m; of the markers of the largest weight)
    and each coordinate's equivalent cutoff (Hz), None to estimate them from the data; the
    engine ('compiled': the numba passes, 'numpy': the reference); each tracked point's
    weight (None: all equal; a marker of weight w has noise σ √(w_max / w))."""

    noise: float | None = None
    cutoff: float | None = None
    engine: str = "compiled"
    weights: tuple[float, ...] | None = None


@dataclass(frozen=True)
class SmoothedMotion:
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


@dataclass(frozen=True)
class _Data:
    """What every span of the trial reads: the coordinates, the frame times, the markers
    (frames × 3 markers, 0 where missing) and their weights W (the marker's relative weight
    where present, 0 where not), and the passes' engine."""

    coordinates: Coordinates
    time: np.ndarray
    y: np.ndarray
    W: np.ndarray
    passes: _Passes
    compiled: bool


@dataclass(frozen=True)
class _Strength:
    """The markers' noise σ (m) and each coordinate's strength."""

    noise: float
    strengths: tuple[Strength, ...]


def smooth_motion(system: System, time: np.ndarray, markers: np.ndarray, use: np.ndarray,
                  mixed_q: np.ndarray, settings: SmoothSettings = SmoothSettings()
                  ) -> SmoothedMotion:
    """Smooth a trial: ``system`` the classical model (angles='driver'), ``markers`` the
    tracked points' targets (frames × markers × 3, NaN where missing), ``use`` the frames
    whose markers may be used, ``mixed_q`` each frame's mixed-coordinate solution (NaN where
    unsolved): the start of the iteration.

    A trial longer than ``span_frames`` plus twice the overlap is smoothed span by span, each
    with ``overlap`` frames of the neighbouring spans on either side that it computes and
    discards: the smoother's influence decays as e^(−ω_c sin(π/2p) |t|), so an overlap of
    ``DECAY`` / (ω_c sin(π/2p)) for the lowest cutoff leaves each span's answer within e^−20 of
    the whole trial's, with memory and linear algebra of one span at a time. The noise and the
    strengths are then estimated once, on the trial's middle ``noise.ESTIMATE_FRAMES``."""
    solved = np.isfinite(mixed_q).all(axis=1)
    usable = use & solved
    need = WINDOW * ORDER
    if usable.sum() < need:
        raise InputError(f"--smooth auto: the trial has {int(usable.sum())} frames the markers "
                         f"determine and the quality checks trust; the smoother needs {need}")
    known = np.flatnonzero(usable)
    inner = slice(int(known[0]), int(known[-1]) + 1)
    if inner.stop - inner.start < len(time):
        # before the first and after the last frame it may use the smoother has no data: its
        # prior would extrapolate from nothing (and the model need not assemble there)
        try:
            part = smooth_motion(system, time[inner], markers[inner], use[inner],
                                 mixed_q[inner], settings)
        except AssemblyError as error:
            raise error.shifted(inner.start) from None
        return _held(part, inner, len(time))
    coordinates = Coordinates.build(system, mixed_q, np.flatnonzero(usable))
    d = _bridged(time, coordinates.from_mixed(np.where(solved[:, None], mixed_q, 0.0)),
                 solved)
    q = _nearest(mixed_q[:, :system.layout.n_body_q], solved)
    present = np.isfinite(markers).all(axis=2) & usable[:, None]
    passes = _passes(settings.engine)
    data = _Data(coordinates, time, np.where(present[..., None], markers, 0.0),
                 np.repeat(present * _relative(settings.weights, markers.shape[1]), 3, axis=1),
                 passes,
                 passes.compiled and compilable(system))
    n = len(time)
    middle = _middle(n, min(n, ESTIMATE_FRAMES))
    try:
        strength = _estimate(data, middle, d[middle], q[middle], settings)
    except AssemblyError as error:
        raise error.shifted(middle.start) from None
    overlap = _overlap(strength.strengths, float(time[1] - time[0]))
    span = span_frames(coordinates.n)
    if n <= span + 2 * overlap:
        out = _span(data, slice(0, n), d, q, strength)
        return replace(out, used=usable, estimated=settings.cutoff is None)
    parts = []
    for start in range(0, n, span):
        stop = min(n, start + span)
        window = slice(max(0, start - overlap), min(n, stop + overlap))
        keep = slice(start - window.start, stop - window.start)
        parts.append((_span(data, window, d[window], q[window], strength), keep))
    joined_d, joined_d_d, joined_d_dd, joined_covariance, joined_q = (
        np.concatenate([getattr(m, key)[keep] for m, keep in parts])
        for key in ("d", "d_d", "d_dd", "covariance", "q"))
    return SmoothedMotion(coordinates, joined_d, joined_d_d, joined_d_dd, joined_covariance,
                          joined_q, usable, strength.noise, strength.strengths,
                          settings.cutoff is None, max(m.iterations for m, _ in parts))


def span_frames(n: int) -> int:
    """Frames a span of a long trial holds: the passes keep ~(4p + 24) n² numbers a frame for n
    coordinates (the output rows of P⁻, U, M, N, the covariances; p the prior's order), so that
    one span's arrays take ``SPAN_BYTES``: ~4400 frames of a lower limb with its floating
    pelvis (n = 18), ~17,500 of the five-bar (n = 9). The fewer the spans the less is smoothed
    twice: each overlap's frames are (10,000 frames of the five-bar in spans of 4000 cost 40 %
    more than at once)."""
    return max(1000, int(SPAN_BYTES / (8 * (4 * ORDER + 24) * n * n)))


def _held(motion: SmoothedMotion, inner: slice, n: int) -> SmoothedMotion:
    """A motion smoothed on the frames ``inner`` of a trial of ``n`` frames, its values held
    at the first and last of them on the frames outside (which it did not use: the caller
    leaves them unsolved)."""
    pad = ((inner.start, n - inner.stop),)

    def held(values: np.ndarray) -> np.ndarray:
        return np.pad(values, pad + ((0, 0),) * (values.ndim - 1), mode="edge")

    used = np.zeros(n, dtype=bool)
    used[inner] = motion.used
    return replace(motion, d=held(motion.d), d_d=held(motion.d_d), d_dd=held(motion.d_dd),
                   covariance=held(motion.covariance), q=held(motion.q), used=used)


def _relative(weights: tuple[float, ...] | None, n: int) -> np.ndarray:
    """Each marker's weight over the largest (all 1 without weights)."""
    if weights is None:
        return np.ones(n)
    w = np.asarray(weights, dtype=float)
    return w / w.max()


def _middle(n: int, frames: int) -> slice:
    start = max(0, (n - frames) // 2)
    return slice(start, start + frames)


def _overlap(strengths: tuple[Strength, ...], dt: float) -> int:
    """Frames a span shares with each neighbour (see smooth_motion)."""
    decay = min(2.0 * np.pi * s.cutoff for s in strengths) * np.sin(np.pi / (2 * ORDER))
    return int(np.ceil(DECAY / decay / dt))


def _linearized(data: _Data, part: slice, d: np.ndarray, q: np.ndarray, noise: float
                ) -> tuple:
    """The frames' measurement model at d: the linearization, the information A = HᵀWH / σ²,
    b = HᵀW(r + H d) / σ² (unscaled by σ² where ``noise`` is 1), and the residuals r = y − p(d)
    (0 where a marker is missing)."""
    lin = data.coordinates.linearize(d, q, data.compiled)
    W = data.W[part]
    r = np.where(W > 0, (data.y[part] - lin.points).reshape(len(d), -1), 0.0)
    HW = lin.H * W[:, :, None]
    A = np.einsum("fri,frj->fij", HW, lin.H)
    b = np.einsum("fri,fr->fi", HW, r) + np.einsum("fij,fj->fi", A, d)
    return lin, A / noise**2, b / noise**2, r


def _estimate(data: _Data, part: slice, d: np.ndarray, q: np.ndarray,
              settings: SmoothSettings) -> _Strength:
    """σ (given, or from the residuals) and the strengths (the cutoff given or estimated) on
    the frames ``part``, at the frames' own solutions."""
    lin, A, b, r = _linearized(data, part, d, q, 1.0)
    noise = settings.noise if settings.noise is not None else \
        _noise(A, b, d, lin.H, r, data.W[part])
    est = FrameEstimates.of(A / noise**2, b / noise**2)
    strengths = tuple(strength(data.time[part], est.z[:, k], est.variance[:, k],
                               data.passes.log_likelihood, settings.cutoff, ORDER)
                      for k in range(data.coordinates.n))
    return _Strength(float(noise), strengths)


def _span(data: _Data, part: slice, d: np.ndarray, q: np.ndarray, strength: _Strength
          ) -> SmoothedMotion:
    """Gauss–Newton over the frames ``part`` (see the module's docstring)."""
    try:
        return _gauss_newton(data, part, d, q, strength)
    except AssemblyError as error:
        raise error.shifted(part.start) from None


def _gauss_newton(data: _Data, part: slice, d: np.ndarray, q: np.ndarray,
                  strength: _Strength) -> SmoothedMotion:
    """_span's iteration (frame indices in its errors counted from ``part.start``). The
    covariance (3.5 times a pass without it) is asked of the pass expected to be the last: the
    one whose step the contraction so far puts below ``STEP`` (the five-bar's steps shrink
    ~100-fold per iteration, the walking trial's ~5-fold), else of one more pass at the
    linearization that converged."""
    time = data.time[part]
    extra = np.array([s.extra for s in strength.strengths])
    chains = None
    steps = [np.inf, np.inf]
    for iteration in range(ITERATIONS + 1):
        lin, A, b, _ = _linearized(data, part, d, q, strength.noise)
        if chains is None:
            chains = _chains(time, A, b, strength.strengths)
        A_info, b_info = with_extra_noise(A, b, extra)
        contraction = steps[-1] / steps[-2] if np.isfinite(steps[-2]) else 1.0
        expected = steps[-1] * min(1.0, contraction) < STEP
        covariance = iteration == ITERATIONS or expected
        values, cov = data.passes(chains, A_info, b_info, covariance)
        steps.append(float(np.abs(values[:, 0] - d).max()))
        q = lin.q + np.einsum("fqk,fk->fq", lin.S, values[:, 0] - d)  # the next guesses
        d = values[:, 0]
        if steps[-1] < STEP and not covariance:  # at this linearization, with the covariance
            values, cov = data.passes(chains, A_info, b_info, True)
            d = values[:, 0]
        if steps[-1] < STEP or iteration == ITERATIONS:
            break
    q = data.coordinates.linearize(d, q, data.compiled).q
    assert cov is not None  # the last pass asked for it (the docstring's rule)
    return SmoothedMotion(data.coordinates, d, values[:, 1], values[:, 2], cov, q,
                  np.ones(len(d), bool), strength.noise, strength.strengths, True,
                  iteration + 1)


def _noise(A: np.ndarray, b: np.ndarray, d: np.ndarray, H: np.ndarray, r: np.ndarray,
           W: np.ndarray) -> float:
    """σ from the residuals of each frame's own fit (noise.marker_noise), each row scaled by
    √W: a row of weight W has residual variance σ² (1 − h)/W, h = W Hᵣ A⁻¹ Hᵣᵀ its leverage."""
    est = FrameEstimates.of(A, b)
    full = np.isfinite(est.z).all(axis=1)
    step = np.where(full[:, None], est.z - d, 0.0)
    e = r - np.einsum("fri,fi->fr", H, step)
    inverse = np.zeros_like(A)
    inverse[full] = np.linalg.inv(A[full])
    leverage = W * np.einsum("fri,fij,frj->fr", H, inverse, H)
    keep = (W > 0) & full[:, None]
    return marker_noise(np.where(keep, e * np.sqrt(W), np.nan),
                        np.where(keep, leverage, np.nan))


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


def _chains(time: np.ndarray, A: np.ndarray, b: np.ndarray, strengths: tuple[Strength, ...]
            ) -> reference.Chains:
    """Each coordinate's prior: its strength's cutoff and spectral density (the trial's, one
    for every span), and its first frame's prior from these frames."""
    est = FrameEstimates.of(A, b)
    dt = float(time[1] - time[0])
    n = b.shape[1]
    extra = np.array([s.extra for s in strengths])
    cutoffs = np.array([s.cutoff for s in strengths])
    seen = np.isfinite(est.variance)
    variance = est.variance + extra
    r = np.array([s.total_variance for s in strengths])
    scale = 2.0 * np.pi * cutoffs
    means, covs = zip(*(initial_state(time, np.where(seen[:, k], est.z[:, k], 0.0),
                                      variance[:, k], ORDER, scale[k]) for k in range(n)),
                      strict=True)
    return reference.Chains.build(ORDER, dt, scale, np.asarray(density(cutoffs, r, dt, ORDER)),
                                  np.array(means), np.array(covs))


class _Passes:
    """The linear smoother's passes and the scalar likelihood in one engine."""

    def __init__(self, compiled: bool) -> None:
        self.compiled = compiled
        self.log_likelihood: Callable[..., float]  # the kernel or its reference, one signature
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

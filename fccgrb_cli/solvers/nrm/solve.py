"""Mixed coordinates solved with Newton–Raphson on weighted least squares (NRM LS / WLS).

Topology + MCR + TC/TOC is over-determined; each frame solves the Gauss–Newton normal equations
(Φ_qᵀ W Φ_q) Δq = −Φ_qᵀ W Φ with W = diag(1 for topological rows, w for tracking rows): LS is
W = I, WLS takes w = 1e-3 unless a tracked point has its own weight (FORMULATION §3, paper §2.5).
A marker missing in a frame (NaN) drops its tracking rows for that frame only.
"""

from __future__ import annotations

import time as clock
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from fccgrb_cli.blas import single_threaded
from fccgrb_cli.errors import InputError
from fccgrb_cli.solvers.initial import initial_guess
from fccgrb_cli.solvers.newton import Iterate, gauss_newton
from fccgrb_cli.solvers.rates import central_derivatives, consistent_rates
from fccgrb_cli.solvers.result import FrameStats, KinematicResult
from fccgrb_cli.system import Drive, System
from fccgrb_cli.system.constraints import floating_bases

if TYPE_CHECKING:
    from fccgrb_cli.options import SolveOptions

NEAR_SINGULAR = np.radians(5.0)


def row_weights(system: System, tracking_weight: float | None) -> np.ndarray:
    """W's diagonal: 1 on topological rows; on tracking rows 1 (LS, tracking_weight None) or the
    tracked element's own weight, else ``tracking_weight`` (WLS)."""
    w = np.ones(system.n_rows)
    if tracking_weight is not None:
        start = 3 * len(system.lin_a)
        for k, own in enumerate(system.trk_weight):
            w[start + 3 * k:start + 3 * k + 3] = tracking_weight if own is None else own
    return w


# Extrapolation through the last k solutions (binomial coefficients of the k-th difference).
_EXTRAPOLATION = {1: (1.0,), 2: (2.0, -1.0), 3: (3.0, -3.0, 1.0), 4: (4.0, -6.0, 4.0, -1.0),
                  5: (5.0, -10.0, 10.0, -5.0, 1.0)}
HISTORY = 5
COMPILED_FROM = 1000
SMOOTH = 5  # iterations of the last frame up to which the next guess extrapolates at order 4


def without_gaps(weights: np.ndarray, system: System, missing: np.ndarray) -> np.ndarray:
    """``weights`` with the tracking rows of the missing targets (n_targets booleans) at zero:
    a marker absent in a frame drops its equations for that frame only."""
    if not missing.any():
        return weights
    out = weights.copy()
    start = 3 * len(system.lin_a)
    for k in np.flatnonzero(missing):
        out[start + 3 * k:start + 3 * k + 3] = 0.0
    return out


def predict(history: list[np.ndarray], warm_start: str, points: int = HISTORY) -> np.ndarray:
    """The next frame's starting point: the previous solution ('previous'), or a polynomial
    extrapolation through the last ``points`` solutions ('extrapolate', fewer while the trial
    starts). On the five-bar at 100 Hz the quartic guess (5 points) is ~1e-5 from the NRM
    solution, so Newton meets a 1e-10 tolerance in 2 iterations instead of 3 (quadratic, 3
    points: ~3e-4). Solutions that jump from frame to frame (goal attainment's, on noisy
    markers) extrapolate badly at high order: the optimizers use 3 points."""
    if warm_start == "previous":
        return history[-1].copy()
    weights = _EXTRAPOLATION[min(len(history), points)]
    return sum(c * q for c, q in zip(weights, reversed(history), strict=False))


def solvable(system: System, q: np.ndarray, w: np.ndarray) -> bool:
    """Whether the weighted rows left (W's zeros are the missing markers' rows) determine every
    coordinate near q: full column rank of W^½ Φ_q."""
    J = system.jacobian(q)
    s = np.linalg.svd(J * np.sqrt(w)[:, None], compute_uv=False)
    return int((s > s[0] * max(J.shape) * 1e-10).sum()) == system.nq


def unsolvable_text(f: int, time: np.ndarray, missing: np.ndarray, labels: tuple[str, ...],
                    source: str) -> str:
    gone = ", ".join(labels[k] for k in np.flatnonzero(missing))
    where = f"{source}: " if source else ""
    return (f"{where}frame index {f} (t = {time[f]:.3f} s): the markers left cannot "
            f"determine the model (missing: {gone or 'none'})")


def no_convergence_text(f: int, time: np.ndarray, iterations: int) -> str:
    return f"frame index {f} (t = {time[f]:.3f} s): no convergence in {iterations} iterations"


@dataclass(frozen=True)
class NrmSettings:
    """NRM's options (FORMULATION §3.1): the tracking equations' weight (None: plain least
    squares, NRM-LS; else WLS with the topological equations weighing 1), the tolerance on
    ‖Δq‖∞ (m and rad), the iteration cap per frame, the warm start ('extrapolate' or
    'previous'), the iteration matrix ('auto', 'gauss-newton', 'exact'), and whether frames the
    remaining markers cannot determine are reported and skipped instead of stopping; ``engine``:
    'compiled' (the numba kernels of fccgrb_cli/solvers/kernels.py), 'numpy' (the same
    iteration in numpy, frame by frame) or 'auto' (compiled where numba is installed and the
    model has no reduced body)."""

    tracking_weight: float | None = 1e-3
    tol: float = 1e-10
    max_iter: int = 50
    warm_start: str = "extrapolate"
    hessian: str = "auto"
    skip_unsolvable: bool = False
    engine: str = "auto"

    @property
    def method(self) -> str:
        return "nrm-ls" if self.tracking_weight is None else "nrm-wls"

    @classmethod
    def from_options(cls, o: SolveOptions) -> NrmSettings:
        return cls(None if o.method == "nrm-ls" else o.tracking_weight, o.tol,
                   o.max_iter or 50, o.warm_start, o.hessian, o.skip_unsolvable, o.engine)

    def compiled(self, system: System, n_frames: int) -> bool:
        """Whether this solve runs in the compiled kernels (see :func:`use_kernels`)."""
        from fccgrb_cli.system.sparse import supported

        return use_kernels(self.engine, supported(system), n_frames)


def use_kernels(engine: str, takes: bool, n_frames: int, threshold: int = COMPILED_FROM
                ) -> bool:
    """Whether a solve runs in the compiled kernels, ``takes`` saying whether they take the
    model (no reduced body). 'compiled' insists (one-line errors where they cannot); 'auto'
    takes them for trials of ``threshold`` frames or more: loading numba and the cached machine
    code costs ~0.25 s once per process, about what the numpy path spends on 500–700 five-bar
    frames. The choice depends on the trial and the model only, never on what the process
    loaded before, so that a CLI run, a sweep cell and an API call give the same bits."""
    if engine == "numpy":
        return False
    if engine == "compiled":
        if not takes:
            raise InputError("--engine compiled: the compiled kernels take models without "
                             "reduced bodies (form: full); use --engine numpy or auto")
        if not numba_available():
            raise InputError("--engine compiled needs numba (pip install numba)")
        return True
    return takes and n_frames >= threshold and numba_available()


def numba_available() -> bool:
    from importlib.util import find_spec

    return find_spec("numba") is not None


@single_threaded
def solve_nrm(system: System, time: np.ndarray, targets: np.ndarray,
              settings: NrmSettings = NrmSettings(), *, labels: tuple[str, ...] = (),
              source: str = "", progress: Callable[[int, int], None] | None = None
              ) -> KinematicResult:
    """Solve every frame; ``targets`` is (frames × n_targets × 3), metres, NaN in gaps;
    ``labels`` name the targets and ``source`` the trial in messages."""
    tracking_weight, tol, max_iter = settings.tracking_weight, settings.tol, settings.max_iter
    warm_start, hessian = settings.warm_start, settings.hessian
    if not system.mixed or not system.n_targets:
        raise ValueError("solve_nrm needs angles='coordinate' and track=True")
    labels = labels or tuple(f"target {k}" for k in range(system.n_targets))
    if settings.compiled(system, len(time)):
        from fccgrb_cli.solvers.nrm.compiled import solve_compiled

        return solve_compiled(system, time, targets, settings, labels=labels, source=source,
                              progress=progress)
    n, nq = len(time), system.nq
    base_w = row_weights(system, tracking_weight)
    top = system.masks()["topology"]
    q_all = np.zeros((n, nq))
    iterations = np.zeros(n, dtype=int)
    seconds = np.zeros(n)
    phi_norm = np.full(n, np.nan)
    phi_top = np.full(n, np.nan)
    converged = np.zeros(n, dtype=bool)
    messages: list[str] = []
    checked: dict[bytes, bool] = {}
    history: list[np.ndarray] = []
    last_iterations = 0
    for f in range(n):
        started = clock.perf_counter()
        y = targets[f]
        missing = ~np.all(np.isfinite(y), axis=1)
        w = without_gaps(base_w, system, missing)
        if missing.any():
            y = np.where(missing[:, None], 0.0, y)
        drive = Drive(ref=y)
        # high-order extrapolation only while the motion is smooth (the last frame converged
        # quickly); on rough data it overshoots, and the quadratic guess is the safer one
        points = HISTORY if last_iterations <= SMOOTH else 3
        q = predict(history, warm_start, points) if history else initial_guess(system,
                                                                                targets[f])
        key = missing.tobytes()
        if key not in checked:
            checked[key] = solvable(system, q, w)
        if not checked[key]:
            text = unsolvable_text(f, time, missing, labels, source)
            if not settings.skip_unsolvable:
                raise InputError(text)
            messages.append(text + "; frame left unsolved")
            q_all[f] = np.nan
            continue
        it = gauss_newton(system, q, drive, w, tol, max_iter if history else 4 * max_iter,
                          hessian=hessian)
        if not it.converged and history and warm_start != "previous":
            # rough data can send an extrapolated guess astray: retry from the last solution
            again = gauss_newton(system, history[-1], drive, w, tol, max_iter, hessian=hessian)
            it = Iterate(again.q, it.iterations + again.iterations, again.converged)
        seconds[f] = clock.perf_counter() - started
        q_all[f] = it.q
        iterations[f], converged[f] = it.iterations, it.converged
        last_iterations = it.iterations
        if it.converged:
            history = [*history[-(HISTORY - 1):], it.q]
        else:
            messages.append(no_convergence_text(f, time, it.iterations))
            history = []
        phi = system.residual(it.q, drive)
        phi_norm[f] = np.linalg.norm(phi[w > 0])
        phi_top[f] = np.abs(phi[top]).max()
        if progress is not None:
            progress(f + 1, n)
    return mixed_result(system, time, q_all,
                        FrameStats(iterations, seconds, phi_norm, phi_top, converged),
                        method=settings.method, tol=tol, messages=messages)


def mixed_result(system: System, time: np.ndarray, q_all: np.ndarray, stats: FrameStats, *,
                 method: str, tol: float, messages: list[str] | tuple[str, ...] = (),
                 wall_s: float = float("nan"), compiled: bool = False) -> KinematicResult:
    """The result of any mixed-coordinate method: θ from q, θ̇ and θ̈ by central differences,
    consistent q̇ and q̈, and warnings for angles near 0 or π. A signed angle is the same
    configuration every 2π: frames solved apart (in parallel, or from a fresh guess after a gap)
    are brought onto one continuous count of turns, starting from the first solved frame's
    angle in (−π, π] (as the markers give it). ``compiled``: the rates through the compiled
    kernels (a solve that ran in them)."""
    n_body = system.layout.n_body_q
    full = n_body + np.flatnonzero(system.full_angles)
    if len(full):
        solved = np.flatnonzero(np.isfinite(q_all[:, full]).all(axis=1))
        q_all = q_all.copy()
        turns = q_all[np.ix_(solved, full)]
        turns[0] -= 2 * np.pi * np.round(turns[0] / (2 * np.pi))
        q_all[np.ix_(solved, full)] = np.unwrap(turns, axis=0)
    theta = q_all[:, n_body:]
    dt = float(time[1] - time[0]) if len(time) > 1 else 1.0
    theta_d, theta_dd = central_derivatives(theta, dt)
    columns = np.concatenate([np.arange(n_body)[system.layout.q_slice(b)]
                              for b in floating_bases(system.model)] or [np.zeros(0, int)])
    base = (columns, *central_derivatives(q_all[:, columns], dt)) if columns.size else None
    qd, qdd = consistent_rates(system, q_all, theta_d, theta_dd, base, compiled=compiled)
    return KinematicResult(
        method=method, tol=tol, time=np.asarray(time, dtype=float), q=q_all, qd=qd, qdd=qdd,
        theta=theta, theta_d=theta_d, theta_dd=theta_dd, angle_names=system.layout.angle_names,
        iterations=stats.iterations, time_s=stats.seconds, phi_norm=stats.phi_norm,
        phi_top_max=stats.phi_top, converged=stats.converged, messages=(*messages, *near_singular(
            theta, system.layout.angle_names, time,
            system.distance_rows | system.full_angles)), wall_s=wall_s,
        status=stats.status)


def near_singular(theta: np.ndarray, names: tuple[str, ...], time: np.ndarray,
                  distance: np.ndarray | None = None) -> list[str]:
    """Warnings for angles that come within 5° of 0 or π, where s1·s2 = cos θ loses θ's sign
    (coordinates marked in ``distance`` have no such point: distances and signed angles)."""
    out = []
    for k, name in enumerate(names):
        if distance is not None and distance[k]:
            continue
        close = np.flatnonzero(np.minimum(theta[:, k], np.pi - theta[:, k]) < NEAR_SINGULAR)
        if len(close):
            f = int(close[0])
            out.append(f"angle {name} comes within 5 deg of 0 or 180 deg ({len(close)} frames, "
                       f"first frame index {f}, t = {time[f]:.3f} s, "
                       f"{np.degrees(theta[f, k]):.1f} deg); "
                       "cos θ is ambiguous there: choose vectors 90 deg apart at the neutral pose")
    return out

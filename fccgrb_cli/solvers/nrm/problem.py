"""What both NRM engines (the numpy reference in nrm/solve.py, the compiled one in
nrm/compiled.py) share: the settings, each row's weight W (docs/formulation.md §3.1), the warm
start's extrapolation, the test that a frame's remaining markers determine the model, and the
messages."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from fccgrb_cli.solvers.engine import use_kernels
from fccgrb_cli.system import System

if TYPE_CHECKING:
    from fccgrb_cli.pipeline.options import SolveOptions

# Extrapolation through the last k solutions (binomial coefficients of the k-th difference).
_EXTRAPOLATION = {1: (1.0,), 2: (2.0, -1.0), 3: (3.0, -3.0, 1.0), 4: (4.0, -6.0, 4.0, -1.0),
                  5: (5.0, -10.0, 10.0, -5.0, 1.0)}
HISTORY = 5
SMOOTH = 5  # iterations of the last frame up to which the next guess extrapolates at order 4


def row_weights(system: System, tracking_weight: float | None) -> np.ndarray:
    """W's diagonal: 1 on topological rows; on tracking rows 1 (LS, tracking_weight None) or the
    tracked element's own weight, else ``tracking_weight`` (WLS)."""
    w = np.ones(system.n_rows)
    if tracking_weight is not None:
        start = 3 * len(system.lin_a)
        for k, own in enumerate(system.trk_weight):
            w[start + 3 * k:start + 3 * k + 3] = tracking_weight if own is None else own
    return w


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
    """NRM's options (docs/formulation.md §3.1): the tracking equations' weight (None: plain least
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

    def compiled(self, system: System) -> bool:
        """Whether this solve runs in the compiled kernels (see :func:`use_kernels`)."""
        from fccgrb_cli.system.sparse import supported

        return use_kernels(self.engine, supported(system))

"""The residual figure (``fccgrb plot --kind residuals``): per run, the magnitude of the floating
base's residual force (N, and % of body weight on the right axis) and moment (N·m) over the
trial, the first model's dashed beside the reduced one's after ``--reduce-residuals``, the
frames where a ground contact is not measured greyed (their residual is no check of anything,
and the axes are scaled to the measured frames: there the unmeasured reaction runs off them)."""

from __future__ import annotations

import numpy as np

from fccgrb_cli.core.errors import InputError
from fccgrb_cli.dynamics.reduction import Reduction
from fccgrb_cli.dynamics.residuals import ResidualReport


def _grey_unmeasured(ax, time: np.ndarray, measured: np.ndarray) -> None:
    """Shade each run of unmeasured frames."""
    edges = np.diff(np.concatenate([[0], (~measured).astype(np.int8), [0]]))
    dt = time[1] - time[0] if len(time) > 1 else 1.0
    for start, stop in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1),
                           strict=True):
        ax.axvspan(time[start] - dt / 2, time[stop - 1] + dt / 2, color="0.9", lw=0)


def draw_residuals(runs: dict[str, tuple[ResidualReport, Reduction | None]], rate: float):
    """One row per run: |F| and |M| against time (s)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if not runs:
        raise InputError("plot --kind residuals: expected a run with a residual report (a "
                         "model with one floating base, its dynamics solved)")
    fig, axes = plt.subplots(len(runs), 2, figsize=(11, 3.2 * len(runs)), squeeze=False)
    for row, (name, (report, reduction)) in zip(axes, runs.items(), strict=True):
        time = np.arange(len(report.force)) / rate
        weight = report.over_measured.weight
        for ax, key, unit in ((row[0], "force", "N"), (row[1], "moment", "N·m")):
            _grey_unmeasured(ax, time, report.measured)
            curves = [np.linalg.norm(getattr(report, key), axis=1)]
            if reduction is not None:
                curves.append(np.linalg.norm(getattr(reduction.before, key), axis=1))
                ax.plot(time, curves[1], "--", color="tab:red", lw=1.2, label="first model")
            ax.plot(time, curves[0], color="tab:blue", lw=1.5,
                    label="reduced" if reduction is not None else name)
            top = max((float(np.nanmax(c[report.measured], initial=0.0)) for c in curves),
                      default=0.0)
            if np.isfinite(top) and top > 0:
                ax.set_ylim(0.0, 1.4 * top)
            ax.set_xlabel("time (s)")
            ax.set_ylabel(f"|residual {key}| ({unit})")
            ax.set_title(f"{name}: residual {key} (grey: a contact not measured)", fontsize=9)
            ax.legend(fontsize=8, loc="upper right")
        if np.isfinite(weight) and weight > 0:
            right = row[0].twinx()
            low, high = row[0].get_ylim()
            right.set_ylim(100 * low / weight, 100 * high / weight)
            right.set_ylabel("% body weight")
    fig.tight_layout()
    return fig

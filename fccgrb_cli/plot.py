"""Figures of the paper's kinds from a results or sweep file (matplotlib, the 'plots' extra):
a point's x, y, z per run against the reference (Figs 5–6), its Euclidean distance over time
(Figs 6d, 8c), a joint angle per run against the truth (Fig 7), a point's velocity (Fig 8b)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fccgrb_cli.errors import InputError
from fccgrb_cli.io.atomic import atomic_path

KINDS = ("point", "ed", "angle", "velocity")
STYLES = ("-", "--", ":", "-.")  # runs that overlap (methods that agree) stay visible


@dataclass(frozen=True)
class Series:
    name: str
    time: np.ndarray
    points: np.ndarray
    reference: np.ndarray
    labels: tuple[str, ...]
    theta: np.ndarray
    angle_names: tuple[str, ...]
    truth: np.ndarray | None


def _series(h5, name: str, run, top) -> Series:
    ref = top["reference/markers"]
    rate = float(ref.attrs["rate"])
    truth = top["truth/theta"][()] if "truth" in top else None
    n = run["model_points"].shape[0]
    return Series(name, np.arange(n) / rate, run["model_points"][()], ref[()],
                  tuple(str(x) for x in ref.attrs["labels"]), run["theta"][()],
                  tuple(str(x) for x in run["theta"].attrs["names"]), truth)


def load_series(path: Path, wanted: tuple[str, ...]) -> list[Series]:
    """Runs of a results file (by run name) or cells of a sweep file (by key prefix)."""
    from fccgrb_cli.io.results import open_results

    h5 = open_results(path)
    out = []
    with h5:
        if "cells" in h5:
            items = [(key, cell["runs/run"], cell) for key, cell in h5["cells"].items()]
        elif "runs" in h5:
            items = [(key, run, h5) for key, run in h5["runs"].items()]
        else:
            raise InputError(f"{path}: expected /runs or /cells in a results file")
        for key, run, top in items:
            if not wanted or any(key == w or key.startswith(w) for w in wanted):
                out.append(_series(h5, key, run, top))
    if not out:
        names = ", ".join(key for key, _, _ in items)
        raise InputError(f"{path}: --runs: expected names among {names}")
    return out


def _velocity(points: np.ndarray, time: np.ndarray) -> np.ndarray:
    return np.gradient(points, time, axis=0)


def draw(series: list[Series], kind: str, marker: str | None, angle: str | None,
         axis: str = "x"):
    """A matplotlib figure of one kind."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    first = series[0]
    if kind in ("point", "ed", "velocity"):
        label = marker or first.labels[-1]
        if label not in first.labels:
            raise InputError(f"--marker: expected one of {', '.join(first.labels)}, got {label}")
        k = first.labels.index(label)
    if kind == "point":
        fig, axes = plt.subplots(3, 1, sharex=True, figsize=(8, 7))
        for c, ax in enumerate(axes):
            ax.plot(first.time, first.reference[:, k, c], color="k", lw=2.5, alpha=0.35,
                    label="reference")
            for i, s in enumerate(series):
                ax.plot(s.time, s.points[:, k, c], STYLES[i % 4], lw=1.2, label=s.name)
            ax.set_ylabel(f"{'xyz'[c]} of {label} (m)")
        axes[0].set_title(f"Point {label}: model against the reference")
    elif kind == "ed":
        fig, ax = plt.subplots(figsize=(8, 4))
        for i, s in enumerate(series):
            ax.plot(s.time, 1e3 * np.linalg.norm(s.points[:, k] - s.reference[:, k], axis=1),
                    STYLES[i % 4], lw=1.2, label=s.name)
        ax.set_ylabel(f"Euclidean distance at {label} (mm)")
        ax.set_title(f"Distance of {label} to the reference")
        axes = [ax]
    elif kind == "velocity":
        c = "xyz".index(axis)
        fig, ax = plt.subplots(figsize=(8, 4))
        ax.plot(first.time, _velocity(first.reference[:, k, c], first.time), color="k", lw=2.5,
                alpha=0.35, label="reference")
        for i, s in enumerate(series):
            ax.plot(s.time, _velocity(s.points[:, k, c], s.time), STYLES[i % 4], lw=1.2,
                    label=s.name)
        ax.set_ylabel(f"{axis} velocity of {label} (m/s)")
        ax.set_title(f"Velocity of {label} (central differences)")
        axes = [ax]
    else:
        name = angle or first.angle_names[0]
        if name not in first.angle_names:
            raise InputError(f"--angle: expected one of {', '.join(first.angle_names)}, "
                             f"got {name}")
        j = first.angle_names.index(name)
        fig, ax = plt.subplots(figsize=(8, 4))
        if first.truth is not None:
            ax.plot(first.time, np.degrees(first.truth[:, j]), color="k", lw=2.5, alpha=0.35,
                    label="truth")
        for i, s in enumerate(series):
            ax.plot(s.time, np.degrees(s.theta[:, j]), STYLES[i % 4], lw=1.2, label=s.name)
        ax.set_ylabel(f"angle {name} (deg)")
        ax.set_title(f"Joint angle {name}")
        axes = [ax]
    axes[-1].set_xlabel("time (s)")
    for ax in axes:
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8, loc="best")
    fig.tight_layout()
    return fig


def save(fig, output: str | Path) -> None:
    """Write PNG or PDF (by the ending) atomically."""
    import matplotlib.pyplot as plt

    suffix = Path(output).suffix.lower()
    if suffix not in (".png", ".pdf"):
        raise InputError(f"{output}: expected an output ending in .png or .pdf")
    with atomic_path(output) as tmp:
        fig.savefig(tmp, format=suffix[1:], dpi=150)
    plt.close(fig)

"""Figures of the paper's kinds from a results or sweep file (matplotlib, the 'plots' extra):
a point's x, y, z per run against the reference (Figs 5–6), its Euclidean distance over time
(Figs 6d, 8c), a joint angle per run against the truth (Fig 7), a point's velocity (Fig 8b);
and for gait, clinical angles and moments of both legs with the force-plate stances shaded."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fccgrb_cli.core.atomic import atomic_path
from fccgrb_cli.core.errors import InputError

KINDS = ("point", "ed", "angle", "velocity", "clinical")
SIDES = {"r": ("right", "tab:red"), "l": ("left", "tab:blue")}
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
    clinical: Clinical | None = None
    theta_sd: np.ndarray | None = None


@dataclass(frozen=True)
class Clinical:
    """A run's clinical angles (deg) and moments (per kg when known), and per angle the frames
    in which a force plate loads the foot beyond the joint (None: no contact body); with the
    smoother, their standard deviations (the same units)."""

    names: tuple[str, ...]
    angles: np.ndarray
    moments: np.ndarray | None
    moment_unit: str
    stance: tuple[np.ndarray | None, ...]
    trusted: np.ndarray | None = None
    angles_sd: np.ndarray | None = None
    moments_sd: np.ndarray | None = None


def _clinical(run) -> Clinical | None:
    if "clinical" not in run:
        return None
    c = run["clinical"]
    key = "moments_per_kg" if "moments_per_kg" in c else "moments"
    moments = c[key][()] if key in c else None
    stance = tuple(c["stance"][body][()] if body in c["stance"] else None
                   for body in (str(b) for b in c["angles"].attrs["contact"]))
    trusted = c["moments_trusted"][()] if "moments_trusted" in c else None
    names = tuple(str(x) for x in c["angles"].attrs["names"])
    angles_sd = moments_sd = None
    if "uncertainty" in run:  # a clinical curve is ±(θ − 90°), its moment ±τ (per kg)
        u = run["uncertainty"]
        index = [[str(x) for x in run["theta"].attrs["names"]].index(n) for n in names]
        angles_sd = np.degrees(u["theta_sd"][()][:, index])
        if "moments_sd" in u and moments is not None:
            per_kg = c["moments_per_kg"].attrs["mass"] if key == "moments_per_kg" else 1.0
            moments_sd = u["moments_sd"][()][:, index] / per_kg
    return Clinical(names, c["angles"][()], moments,
                    "N·m/kg" if key == "moments_per_kg" else "N·m", stance, trusted, angles_sd,
                    moments_sd)


def _series(h5, name: str, run, top) -> Series:
    ref = top["reference/markers"]
    rate = float(ref.attrs["rate"])
    truth = top["truth/theta"][()] if "truth" in top else None
    n = run["model_points"].shape[0]
    sd = run["uncertainty/theta_sd"][()] if "uncertainty" in run else None
    return Series(name, np.arange(n) / rate, run["model_points"][()], ref[()],
                  tuple(str(x) for x in ref.attrs["labels"]), run["theta"][()],
                  tuple(str(x) for x in run["theta"].attrs["names"]), truth, _clinical(run),
                  sd)


def load_series(path: Path, wanted: tuple[str, ...]) -> list[Series]:
    """Runs of a results file (by run name) or cells of a sweep file (by key prefix)."""
    from fccgrb_cli.core.datasets import open_results
    from fccgrb_cli.results.format import cells_group, check_run, reading, runs_group

    h5 = open_results(path)
    out = []
    with h5:
        if "cells" in h5:
            items = []
            for key, cell in cells_group(h5, path).items():
                with reading(path, f"/cells/{key}"):
                    items.append((key, cell["runs/run"], cell))
        elif "runs" in h5:
            items = [(key, run, h5) for key, run in runs_group(h5, path).items()]
        else:
            raise InputError(f"{path}: expected /runs or /cells in a results file")
        for key, run, top in items:
            if not wanted or any(key == w or key.startswith(w) for w in wanted):
                where = f"/runs/{key}" if top is h5 else f"/cells/{key}"
                with reading(path, where):
                    check_run(run, path, where)
                    out.append(_series(h5, key, run, top))
    if not out:
        names = ", ".join(key for key, _, _ in items)
        raise InputError(f"{path}: --runs: expected names among {names}")
    return out


def _velocity(points: np.ndarray, time: np.ndarray) -> np.ndarray:
    return np.gradient(points, time, axis=0)


def _sided(names: tuple[str, ...], wanted: tuple[str, ...]) -> list[str]:
    """The joint rows to draw: names without their _r/_l suffix, those containing one of
    ``wanted`` (default: the sagittal ones, whose names hold 'flexion'), in model order."""
    stems: list[str] = []
    for name in names:
        stem = name[:-2] if name[-2:] in ("_r", "_l") else name
        if stem not in stems and any(w in stem for w in (wanted or ("flexion",))):
            stems.append(stem)
    return stems


def _band(ax, time: np.ndarray, values: np.ndarray, sd: np.ndarray, colour) -> None:
    """The smoother's 95 % band, ±1.96 standard deviations."""
    ax.fill_between(time, values - 1.96 * sd, values + 1.96 * sd, color=colour, alpha=0.25,
                    lw=0)


def draw_clinical(series: list[Series], wanted: tuple[str, ...] = ()):
    """Clinical angles (left column) and moments (right) of both legs, one row per joint;
    shaded where a force plate loads that leg's foot (moments off the plates in stance lack
    the ground reaction); a moment is drawn faint and dotted where it is not trusted."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    runs = [s for s in series if s.clinical is not None]
    clinicals = [s.clinical for s in series if s.clinical is not None]  # runs' own, in order
    if not runs:
        raise InputError("--kind clinical: expected runs of a model whose angles declare a "
                         "clinical sign (e.g. configs/models/lower_limb.yaml)")
    c0 = clinicals[0]
    stems = _sided(c0.names, wanted)
    if not stems:
        raise InputError(f"--angle: expected parts of the clinical angle names "
                         f"({', '.join(c0.names)}), got {', '.join(wanted)}")
    columns = 2 if c0.moments is not None else 1
    fig, axes = plt.subplots(len(stems), columns, sharex=True, squeeze=False,
                             figsize=(5.5 * columns, 2.4 * len(stems) + 0.6))
    time = runs[0].time
    for row, stem in enumerate(stems):
        for side, (word, colour) in SIDES.items():
            name = f"{stem}_{side}" if f"{stem}_{side}" in c0.names else stem
            if name not in c0.names:
                continue
            k = c0.names.index(name)
            stance = c0.stance[k]
            for ax in axes[row]:
                if stance is not None and stance.any():
                    ax.fill_between(time, 0, 1, where=stance, color=colour, alpha=0.08,
                                    transform=ax.get_xaxis_transform(), lw=0)
            for i, (s, c) in enumerate(zip(runs, clinicals, strict=True)):
                label = f"{word} ({s.name})" if len(runs) > 1 else word
                curves = [(c.angles, c.angles_sd)]
                if columns == 2:
                    assert c.moments is not None  # runs compared all have moments, as the first
                    moment = c.moments[:, k]
                    trusted = np.ones(len(moment), dtype=bool) if c.trusted is None \
                        else c.trusted[:, k]
                    curves.append((np.where(trusted[:, None], c.moments, np.nan), c.moments_sd))
                    if not trusted.all():
                        axes[row, 1].plot(s.time, np.where(trusted, np.nan, moment), ":",
                                          color=colour, lw=0.8, alpha=0.4)
                for ax, (values, sd) in zip(axes[row], curves, strict=False):
                    ax.plot(s.time, values[:, k], STYLES[i % 4], color=colour, lw=1.3,
                            label=label)
                    if sd is not None:
                        _band(ax, s.time, values[:, k], sd[:, k], colour)
        axes[row, 0].set_ylabel(f"{stem.replace('_', ' ')} (deg)")
        if columns == 2:
            axes[row, 1].set_ylabel(c0.moment_unit)
            axes[row, 1].axhline(0, color="k", lw=0.6)
    for ax in axes.ravel():
        ax.grid(alpha=0.3)
    for ax in axes[-1]:
        ax.set_xlabel("time (s)")
    axes[0, 0].legend(fontsize=8, loc="best")
    axes[0, 0].set_title("clinical angle", fontsize=10)
    if columns == 2:
        axes[0, 1].set_title("internal joint moment (positive towards a positive angle)",
                             fontsize=10)
    banded = any(c.angles_sd is not None for c in clinicals)
    fig.suptitle("Shaded: a force plate loads that side's foot"
                 + ("; bands: the smoother's 95 % (±1.96 SD)" if banded else ""), fontsize=9)
    fig.tight_layout()
    return fig


def draw(series: list[Series], kind: str, marker: str | None, angle: str | None,
         axis: str = "x"):
    """A matplotlib figure of one kind."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if kind == "clinical":
        return draw_clinical(series, tuple(a for a in (angle or "").split(",") if a))
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
            line, = ax.plot(s.time, np.degrees(s.theta[:, j]), STYLES[i % 4], lw=1.2,
                            label=s.name)
            if s.theta_sd is not None:
                _band(ax, s.time, np.degrees(s.theta[:, j]), np.degrees(s.theta_sd[:, j]),
                      line.get_color())
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

"""The gait report's figure: each side's mean ± SD cycle of the clinical angles (and moments),
0–100 % of the stride, the mean toe-off as a vertical line, and an optional normative band from
a user's CSV (``gait.normative``: columns ``variable,percent,mean,sd``; the band is mean ± sd)."""

from __future__ import annotations

import numpy as np

from fccgrb_cli.core.errors import InputError
from fccgrb_cli.gait.analysis import GaitResults
from fccgrb_cli.gait.cycles import normalized

COLOURS = {"left": "tab:blue", "right": "tab:red"}


def _stem(name: str) -> str:
    return name[:-2] if name.endswith(("_r", "_l")) else name


def _cycle_sd(c, time: np.ndarray, sd: np.ndarray) -> np.ndarray:
    """A frames' standard deviation over one side's trusted strides, time-normalized like the
    curves (101 samples): each stride's, then their root mean square."""
    strides = [normalized(time, sd[:, None], a, b)[:, 0]
               for a, b, ok in zip(c.start, c.stop, c.trusted, strict=True) if ok]
    return np.sqrt(np.mean(np.square(strides), axis=0))


def draw_cycles(gaits: dict[str, GaitResults], wanted: tuple[str, ...] = (),
                normative: dict[str, np.ndarray] | None = None,
                bands: dict[str, tuple[np.ndarray, dict[str, np.ndarray]]] | None = None):
    """One panel per clinical variable whose name contains one of ``wanted`` (default the
    sagittal angles and moments: names holding 'flexion'), both sides' mean ± SD; ``bands``
    (run → its frame times and each curve's standard deviation from the smoother, by name):
    the mean's 95 % band from the marker noise, outlined."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if not gaits:
        raise InputError("--kind cycles: expected runs with a gait analysis (a lower-limb model "
                         "solved on a walking trial with events)")
    first = next(iter(gaits.values()))
    stems: list[str] = []
    for c in first.cycles.values():
        for name in c.names:
            stem = _stem(name)
            if stem not in stems and any(w in stem for w in (wanted or ("flexion",))):
                stems.append(stem)
    if not stems:
        names = sorted({_stem(n) for c in first.cycles.values() for n in c.names})
        raise InputError(f"--angle: expected parts of the cycle variables ({', '.join(names)}), "
                         f"got {', '.join(wanted)}")
    columns = 2 if len(stems) > 3 else 1
    rows = -(-len(stems) // columns)
    fig, axes = plt.subplots(rows, columns, sharex=True, squeeze=False,
                             figsize=(5.2 * columns, 2.3 * rows + 0.7))
    percent = np.linspace(0.0, 100.0, 101)
    for k, stem in enumerate(stems):
        ax = axes[k % rows, k // rows]
        if normative and stem in normative:
            band = normative[stem]
            ax.fill_between(band[:, 0], band[:, 1] - band[:, 2], band[:, 1] + band[:, 2],
                            color="0.6", alpha=0.3, lw=0, label="normative ± SD")
        unit = ""
        for name, gait in gaits.items():
            for side, c in gait.cycles.items():
                matches = [j for j, n in enumerate(c.names) if _stem(n) == stem]
                if not matches or not c.trusted_per_variable[:, matches[0]].any():
                    continue
                j = matches[0]
                unit = c.units[j]
                mean, sd = c.mean()[:, j], c.sd()[:, j]
                count = int(c.trusted_per_variable[:, j].sum())
                label = f"{side} (n={count})" + (f", {name}" if len(gaits) > 1 else "")
                ax.plot(percent, mean, color=COLOURS.get(side, "k"), lw=1.4, label=label)
                if np.isfinite(sd).all():
                    ax.fill_between(percent, mean - sd, mean + sd, color=COLOURS.get(side, "k"),
                                    alpha=0.18, lw=0)
                if bands and name in bands and c.names[j] in bands[name][1]:
                    time, curves = bands[name]
                    half = 1.96 * _cycle_sd(c, time, curves[c.names[j]])
                    for edge in (mean - half, mean + half):
                        ax.plot(percent, edge, color=COLOURS.get(side, "k"), lw=0.6, ls=":")
                stance = c.parameter("stance")[c.trusted]
                if np.isfinite(stance).any():
                    ax.axvline(float(np.nanmean(stance)), color=COLOURS.get(side, "k"), lw=0.8,
                               ls="--")
        ax.set_ylabel(f"{stem.replace('_', ' ')} ({unit})", fontsize=9)
        ax.grid(alpha=0.3)
        if "moment" in stem:
            ax.axhline(0, color="k", lw=0.6)
    for ax in axes[-1]:
        ax.set_xlabel("gait cycle (%)")
    for ax in axes.ravel()[len(stems):]:
        ax.set_visible(False)
    axes[0, 0].legend(fontsize=7, loc="best")
    title = "Mean ± SD per side over trusted strides; dashed: mean toe-off"
    if bands:
        title += "; dotted: the smoother's 95 % band"
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    return fig

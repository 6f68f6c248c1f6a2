"""Gait-cycle plots as inline SVG, written here (no plotting library at run time, nothing for the
browser to fetch): each side's mean curve with its ± SD band, a normative band behind them,
the mean toe-off per side as a dashed line, axes with round ticks, a legend. Vector output
prints sharply at any size.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from html import escape

import numpy as np

WIDTH, HEIGHT = 300, 190
LEFT, RIGHT, TOP, BOTTOM = 44, 8, 30, 30  # margins inside the view box
COLOURS = {"left": "#1f5fbf", "right": "#c8302c", "norm": "#8c8c8c"}


@dataclass(frozen=True)
class Curve:
    """A mean curve over 0–100 % of the cycle (101 samples), its SD (NaN: no band), how many
    strides or subjects it is over, and the mean toe-off (% of the cycle; NaN: none)."""

    side: str
    mean: np.ndarray
    sd: np.ndarray
    n: int
    toe_off: float = math.nan


def nice_ticks(low: float, high: float, count: int = 5) -> list[float]:
    """Round tick values (1, 2 or 5 × 10^k apart) covering [low, high]."""
    if not (math.isfinite(low) and math.isfinite(high)):
        return [0.0, 1.0]
    if high - low < 1e-9:
        low, high = low - 1.0, high + 1.0
    raw = (high - low) / max(count - 1, 1)
    power = 10.0 ** math.floor(math.log10(raw))
    step = next(m * power for m in (1, 2, 5, 10) if m * power >= raw)
    first = math.floor(low / step) * step
    ticks = []
    value = first
    while value < high + step * 0.5:
        ticks.append(round(value, 10) + 0.0)  # + 0.0: no "-0" label
        value += step
    if ticks[-1] < high:
        ticks.append(round(ticks[-1] + step, 10) + 0.0)
    return ticks


def _fmt(value: float) -> str:
    return f"{value:.1f}".rstrip("0").rstrip(".") if abs(value) < 1e4 else f"{value:.0f}"


class _Frame:
    """The plot area: data (percent, value) → view-box coordinates."""

    def __init__(self, ticks: list[float]):
        self.low, self.high = ticks[0], ticks[-1]
        self.width = WIDTH - LEFT - RIGHT
        self.height = HEIGHT - TOP - BOTTOM

    def x(self, percent: float) -> float:
        return LEFT + self.width * percent / 100.0

    def y(self, value: float) -> float:
        return TOP + self.height * (self.high - value) / (self.high - self.low)

    def path(self, percent: np.ndarray, values: np.ndarray) -> str:
        return " ".join(f"{'M' if k == 0 else 'L'}{self.x(p):.2f},{self.y(v):.2f}"
                        for k, (p, v) in enumerate(zip(percent, values, strict=True)))

    def band(self, percent: np.ndarray, low: np.ndarray, high: np.ndarray) -> str:
        """A closed outline: along the upper edge, back along the lower."""
        return self.path(np.concatenate([percent, percent[::-1]]),
                         np.concatenate([high, low[::-1]])) + " Z"


def cycle_plot(title: str, unit: str, curves: list[Curve],
               norm: np.ndarray | None = None) -> str:
    """One variable's plot: ``curves`` (a side each), ``norm`` rows of (percent, mean, sd)
    drawn as a grey mean ± SD band. An empty plot says there is nothing to draw."""
    percent = np.linspace(0.0, 100.0, 101)
    values = [c.mean for c in curves if np.isfinite(c.mean).all()]
    values += [c.mean + c.sd for c in curves if np.isfinite(c.mean + c.sd).all()]
    values += [c.mean - c.sd for c in curves if np.isfinite(c.mean - c.sd).all()]
    if norm is not None and len(norm):
        values += [norm[:, 1] - norm[:, 2], norm[:, 1] + norm[:, 2]]
    span = np.concatenate(values) if values else np.array([0.0, 1.0])
    ticks = nice_ticks(float(np.min(span)), float(np.max(span)))
    f = _Frame(ticks)
    parts = [f'<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {WIDTH} {HEIGHT}" '
             f'class="plot" role="img" aria-label="{escape(title)} ({escape(unit)})">',
             f'<title>{escape(title)} ({escape(unit)})</title>',
             f'<text x="{WIDTH / 2:.1f}" y="11" class="title">{escape(title)}</text>']
    for t in ticks:
        y = f.y(t)
        parts.append(f'<line x1="{LEFT}" x2="{WIDTH - RIGHT}" y1="{y:.2f}" y2="{y:.2f}" '
                     f'class="{"zero" if t == 0 else "grid"}"/>')
        parts.append(f'<text x="{LEFT - 4}" y="{y + 3:.2f}" class="tick" '
                     f'text-anchor="end">{_fmt(t)}</text>')
    for p in range(0, 101, 20):
        parts.append(f'<text x="{f.x(p):.2f}" y="{HEIGHT - BOTTOM + 12}" class="tick" '
                     f'text-anchor="middle">{p}</text>')
    parts.append(f'<text x="{LEFT + f.width / 2:.1f}" y="{HEIGHT - 4}" class="axis" '
                 f'text-anchor="middle">% gait cycle</text>')
    parts.append(f'<text transform="translate(11,{TOP + f.height / 2:.1f}) rotate(-90)" '
                 f'class="axis" text-anchor="middle">{escape(unit)}</text>')
    if norm is not None and len(norm):
        outline = f.band(norm[:, 0], norm[:, 1] - norm[:, 2], norm[:, 1] + norm[:, 2])
        parts.append(f'<path d="{outline}" class="norm" fill="{COLOURS["norm"]}"/>')
    drawn = 0
    for c in curves:
        colour = COLOURS.get(c.side, "#000")
        if not np.isfinite(c.mean).all():
            continue
        drawn += 1
        if np.isfinite(c.sd).all():
            parts.append(f'<path d="{f.band(percent, c.mean - c.sd, c.mean + c.sd)}" '
                         f'class="sd" fill="{colour}"/>')
        parts.append(f'<path d="{f.path(percent, c.mean)}" class="mean" stroke="{colour}" '
                     f'data-side="{c.side}"/>')
        if math.isfinite(c.toe_off):
            parts.append(f'<line x1="{f.x(c.toe_off):.2f}" x2="{f.x(c.toe_off):.2f}" '
                         f'y1="{TOP}" y2="{HEIGHT - BOTTOM}" class="toe-off" '
                         f'stroke="{colour}"/>')
    parts.append(f'<rect x="{LEFT}" y="{TOP}" width="{f.width}" height="{f.height}" '
                 'class="frame"/>')
    legend = [(COLOURS.get(c.side, "#000"), f"{c.side} (n={c.n})") for c in curves
              if np.isfinite(c.mean).all()]
    if norm is not None and len(norm):
        legend.append((COLOURS["norm"], "norm ± SD"))
    for k, (colour, label) in enumerate(legend):  # above the plot area, below the title
        x = LEFT + 82 * k
        parts.append(f'<rect x="{x}" y="{TOP - 9}" width="9" height="4" fill="{colour}"/>'
                     f'<text x="{x + 12}" y="{TOP - 4}" class="legend">{escape(label)}</text>')
    if not drawn:
        parts.append(f'<text x="{LEFT + f.width / 2:.1f}" y="{TOP + f.height / 2:.1f}" '
                     'class="empty" text-anchor="middle">no trusted strides</text>')
    parts.append("</svg>")
    return "".join(parts)

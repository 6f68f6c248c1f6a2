"""Strides cut at the events, time-normalized to 0–100 % of the gait cycle (101 samples), and the
spatiotemporal parameters of each stride.

A stride of one foot runs from its strike to its next strike. Each clinical curve of that side
(names ending ``_r`` / ``_l``) is sampled at 101 equally spaced instants over the stride, by
linear interpolation between frames. A stride that contains a frame the quality checks do not
trust is kept but marked, and left out of the mean ± SD (which says over how many strides).

Spatiotemporal parameters of a stride (per side, from the heel markers and the events): stride
time (s); cadence 120 / stride time (steps/min); stride length, the heel's displacement along the
direction of walking from strike to strike (m); walking speed, stride length / stride time
(m/s); step length, how far this heel is ahead of the other heel along the direction of walking
at this foot's strike (m); step width, their distance across it then (m); stance and swing, the
time from strike to this foot's off and from off to the next strike (% of the stride); double
support, the time both feet are down (from this strike to the other foot's off, and from the
other foot's strike to this foot's off; % of the stride).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from fccgrb_cli.gait.events import Events

SAMPLES = 101
PARAMETERS = (("stride_time", "s"), ("cadence", "steps/min"), ("stride_length", "m"),
              ("walking_speed", "m/s"), ("step_length", "m"), ("step_width", "m"),
              ("stance", "%"), ("swing", "%"), ("double_support", "%"))
SUFFIX = {"left": "_l", "right": "_r"}


@dataclass(frozen=True)
class SideCycles:
    """One side's strides: start and end times (s); ``trusted`` per stride (its frames'
    kinematics); ``curves`` (strides × 101 × variables) of ``names`` in ``units``; the
    spatiotemporal ``parameters`` (strides × PARAMETERS, NaN where an event is missing);
    ``trusted_curves`` (strides × variables, None: as ``trusted``) where a variable can be
    untrusted on a trusted stride (a moment whose ground reaction no plate measured)."""

    side: str
    start: np.ndarray
    stop: np.ndarray
    trusted: np.ndarray
    names: tuple[str, ...]
    units: tuple[str, ...]
    curves: np.ndarray
    parameters: np.ndarray
    trusted_curves: np.ndarray | None = None

    @property
    def n(self) -> int:
        return len(self.start)

    @property
    def trusted_per_variable(self) -> np.ndarray:
        """strides × variables: each variable's strides that enter its mean."""
        if self.trusted_curves is not None:
            return self.trusted_curves & self.trusted[:, None]
        return np.repeat(self.trusted[:, None], self.curves.shape[2], axis=1)

    def mean(self) -> np.ndarray:
        """101 × variables, each over its trusted strides (NaN where there are none)."""
        use = self.trusted_per_variable
        count = use.sum(axis=0)
        total = np.einsum("spv,sv->pv", np.nan_to_num(self.curves), use.astype(float))
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(count > 0, total / np.maximum(count, 1), np.nan)

    def sd(self) -> np.ndarray:
        """Sample standard deviation, each variable over its trusted strides (NaN with fewer
        than two)."""
        use = self.trusted_per_variable
        count = use.sum(axis=0)
        deviation = np.where(use[:, None, :], np.nan_to_num(self.curves) - self.mean(), 0.0)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(count > 1, np.sqrt((deviation**2).sum(axis=0)
                                               / np.maximum(count - 1, 1)), np.nan)

    def parameter(self, name: str) -> np.ndarray:
        return self.parameters[:, [p for p, _ in PARAMETERS].index(name)]


@dataclass(frozen=True)
class Walk:
    """What the spatiotemporal parameters are measured on: the frame times (s), each side's heel
    trajectory (frames × 3, m; absent sides give NaN lengths), the direction of walking and the
    vertical (unit vectors)."""

    time: np.ndarray
    heels: dict[str, np.ndarray]
    forward: np.ndarray
    vertical: np.ndarray


def normalized(time: np.ndarray, values: np.ndarray, start: float, stop: float) -> np.ndarray:
    """values (frames × n) at 101 instants from ``start`` to ``stop`` (linear in time)."""
    at = np.linspace(start, stop, SAMPLES)
    return np.column_stack([np.interp(at, time, values[:, k]) for k in range(values.shape[1])])


def side_cycles(side: str, events: Events, trusted: np.ndarray,
                curves: tuple[tuple[str, ...], tuple[str, ...], np.ndarray],
                walk: Walk, trusted_curves: np.ndarray | None = None) -> SideCycles:
    """The strides of ``side`` (``curves``: every clinical name, unit and frames × n values;
    ``trusted``: per frame; ``trusted_curves``: per frame and curve, when a curve can be
    untrusted on a trusted frame)."""
    names, units, values = curves
    time = walk.time
    mine = [k for k, n in enumerate(names) if n.endswith(SUFFIX[side])]
    strikes = events.of(side, "strike")
    other = "left" if side == "right" else "right"
    rate = 1.0 / float(time[1] - time[0]) if len(time) > 1 else 1.0
    starts, stops, ok, cycles, params, per = [], [], [], [], [], []
    for a, b in itertools.pairwise(strikes):
        # the frames the 101 samples interpolate between (an event within 1/1000 of a frame
        # of one, as the C3D's times are, uses that frame alone)
        first, last = int(np.floor(a * rate + 1e-3)), int(np.ceil(b * rate - 1e-3))
        starts.append(a)
        stops.append(b)
        span = slice(max(first, 0), min(last, len(time) - 1) + 1)
        ok.append(bool(trusted[span].all()))
        if trusted_curves is not None:
            per.append(trusted_curves[span][:, mine].all(axis=0))
        cycles.append(normalized(time, values[:, mine], a, b))
        params.append(_parameters(side, other, events, (a, b), walk))
    return SideCycles(side, np.array(starts), np.array(stops), np.array(ok, dtype=bool),
                      tuple(names[k] for k in mine), tuple(units[k] for k in mine),
                      np.array(cycles).reshape(len(cycles), SAMPLES, len(mine)),
                      np.array(params).reshape(len(params), len(PARAMETERS)),
                      None if trusted_curves is None else
                      np.array(per, dtype=bool).reshape(len(per), len(mine)))


def _first_in(times: np.ndarray, a: float, b: float) -> float:
    inside = times[(times > a) & (times < b)]
    return float(inside[0]) if len(inside) else np.nan


def _at(trajectory: np.ndarray, time: np.ndarray, t: float) -> np.ndarray:
    return np.array([np.interp(t, time, trajectory[:, k]) for k in range(3)])


def _parameters(side: str, other: str, events: Events, stride_span: tuple[float, float],
                walk: Walk) -> list[float]:
    a, b = stride_span
    heels, forward, time = walk.heels, walk.forward, walk.time
    stride = b - a
    off = _first_in(events.of(side, "off"), a, b)
    other_off = _first_in(events.of(other, "off"), a, b)
    other_strike = _first_in(events.of(other, "strike"), a, b)
    across = np.cross(walk.vertical, forward)
    if side in heels and other in heels:
        here, there = _at(heels[side], time, a), _at(heels[other], time, a)
        length = float((_at(heels[side], time, b) - here) @ forward)
        step = float((here - there) @ forward)
        width = float(abs((here - there) @ across))
    else:
        length = step = width = np.nan
    double = ((other_off - a) + (off - other_strike)) / stride * 100.0
    stance = (off - a) / stride * 100.0
    return [stride, 120.0 / stride, length, length / stride, step, width, stance,
            100.0 - stance, double]


def pooled(per_trial: list[dict[str, SideCycles]]) -> dict[str, SideCycles]:
    """Each side's strides of several trials of one subject together (for the subject's mean ±
    SD over every trusted stride); the trials' variables must be the same."""
    out: dict[str, SideCycles] = {}
    for side in per_trial[0]:
        parts = [trial[side] for trial in per_trial if side in trial]
        first = parts[0]
        if any(p.names != first.names for p in parts):
            raise ValueError(f"{side}: the trials' cycle variables differ")
        out[side] = SideCycles(
            side, np.concatenate([p.start for p in parts]),
            np.concatenate([p.stop for p in parts]),
            np.concatenate([p.trusted for p in parts]), first.names, first.units,
            np.concatenate([p.curves for p in parts]),
            np.concatenate([p.parameters for p in parts]),
            np.concatenate([p.trusted_per_variable for p in parts]))
    return out

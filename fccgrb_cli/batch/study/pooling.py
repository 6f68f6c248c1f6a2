"""Strides pooled per subject and per group.

A subject's cycles are every trial's strides of one side together (``gait.cycles.pooled``); its
mean ± SD curve and spatiotemporal parameters are over its trusted strides (a stride holding a
frame the quality checks do not trust is counted and left out). A group weighs its subjects
equally: the group's curve is the mean of its subjects' mean curves, its SD the between-subject
sample SD of those means (n − 1; NaN with fewer than two subjects), and likewise each
spatiotemporal parameter over the subjects' means. A subject with no trusted stride of a side
(or without a variable) does not count for that side (or variable); ``n`` says how many did.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fccgrb_cli.gait.cycles import PARAMETERS, SAMPLES, SideCycles


@dataclass(frozen=True)
class Spread:
    """Mean, sample SD and count over some rows (subjects or strides), per column: ``values``
    holds the rows (NaN where a row has no value), ``rows`` names them."""

    rows: tuple[str, ...]
    values: np.ndarray

    @property
    def n(self) -> np.ndarray:
        return np.isfinite(self.values).sum(axis=0)

    @property
    def mean(self) -> np.ndarray:
        return _mean(self.values)

    @property
    def sd(self) -> np.ndarray:
        return _sd(self.values)


def _mean(values: np.ndarray) -> np.ndarray:
    n = np.isfinite(values).sum(axis=0)
    total = np.where(np.isfinite(values), values, 0.0).sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(n > 0, total / np.maximum(n, 1), np.nan)


def _sd(values: np.ndarray) -> np.ndarray:
    """Sample SD (n − 1) over the finite values of each column; NaN with fewer than two."""
    n = np.isfinite(values).sum(axis=0)
    centred = np.where(np.isfinite(values), values - _mean(values), 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(n > 1, np.sqrt((centred ** 2).sum(axis=0) / np.maximum(n - 1, 1)),
                        np.nan)


def stride_parameters(cycles: SideCycles) -> Spread:
    """One side's spatiotemporal parameters over its trusted strides (rows: the strides)."""
    rows = tuple(f"{a:.3f}-{b:.3f} s" for a, b, ok in
                 zip(cycles.start, cycles.stop, cycles.trusted, strict=True) if ok)
    return Spread(rows, cycles.parameters[cycles.trusted].reshape(-1, len(PARAMETERS)))


@dataclass(frozen=True)
class GroupCycles:
    """A group's curves of one side: ``names``/``units`` of the variables; ``subjects`` holds
    each subject's mean curve (subjects × 101 × variables, NaN where the subject lacks it)."""

    names: tuple[str, ...]
    units: tuple[str, ...]
    subjects: tuple[str, ...]
    means: np.ndarray

    @property
    def mean(self) -> np.ndarray:
        return _mean(self.means)

    @property
    def sd(self) -> np.ndarray:
        return _sd(self.means)

    @property
    def n(self) -> np.ndarray:
        """Subjects per variable."""
        return np.isfinite(self.means).all(axis=1).sum(axis=0)


def group_cycles(side: dict[str, SideCycles]) -> GroupCycles:
    """One side's group curves from each subject's pooled cycles (subject → SideCycles); the
    variables in the order they first appear."""
    names: list[str] = []
    units: list[str] = []
    for c in side.values():
        for name, unit in zip(c.names, c.units, strict=True):
            if name not in names:
                names.append(name)
                units.append(unit)
    means = np.full((len(side), SAMPLES, len(names)), np.nan)
    for k, c in enumerate(side.values()):
        if not c.trusted.any():
            continue
        mean = c.mean()
        for j, name in enumerate(c.names):
            means[k, :, names.index(name)] = mean[:, j]
    return GroupCycles(tuple(names), tuple(units), tuple(side), means)


def group_parameters(side: dict[str, SideCycles]) -> Spread:
    """One side's spatiotemporal parameters: each subject's mean over its trusted strides (rows:
    the subjects), whose mean and SD are the group's (between-subject)."""
    values = np.array([stride_parameters(c).mean for c in side.values()]).reshape(
        len(side), len(PARAMETERS))
    return Spread(tuple(side), values)

"""A lab's normative data: a CSV with the columns ``variable,percent,mean,sd``.

A row with a percent (0–100) is a sample of a normative gait-cycle curve: ``variable`` is a
clinical name without its side suffix (``knee_flexion``, deg; ``knee_flexion_moment``, N·m/kg).
A row with the percent left empty is the norm of a spatiotemporal parameter (``walking_speed``,
``cadence``, …, in the units of ``gait.cycles.PARAMETERS``). Either is drawn or printed as
mean ± sd."""

from __future__ import annotations

import csv
import io
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fccgrb_cli.core.errors import InputError
from fccgrb_cli.core.inputs import read_text


@dataclass(frozen=True)
class Norms:
    """``curves``: variable → rows (percent, mean, sd) sorted by percent; ``values``: parameter
    → (mean, sd)."""

    curves: dict[str, np.ndarray]
    values: dict[str, tuple[float, float]]


def read_norms(path: str | Path) -> Norms:
    """The curves and parameter norms of a normative CSV; a malformed line is one error naming
    it."""
    curves: dict[str, list[tuple[float, float, float]]] = {}
    values: dict[str, tuple[float, float]] = {}
    rows = list(csv.DictReader(io.StringIO(read_text(path, "normative data"), newline="")))
    if not rows:
        raise InputError(f"{path}: expected rows of normative data (columns variable, percent, "
                         "mean, sd)")
    for line, row in enumerate(rows, start=2):
        try:
            name, percent = row["variable"].strip(), (row["percent"] or "").strip()
            mean, sd = float(row["mean"]), float(row["sd"])
            if not (math.isfinite(mean) and math.isfinite(sd) and sd >= 0 and name):
                raise ValueError
            if percent:
                at = float(percent)
                if not 0.0 <= at <= 100.0:
                    raise ValueError
                curves.setdefault(name, []).append((at, mean, sd))
            else:
                values[name] = (mean, sd)
        except (KeyError, TypeError, ValueError, AttributeError):
            raise InputError(f"{path}: line {line}: expected the columns variable, percent, "
                             "mean, sd (percent 0–100, or empty for a spatiotemporal "
                             "parameter; finite numbers, sd ≥ 0)") from None
    return Norms({k: np.array(sorted(v)) for k, v in curves.items()}, values)

"""Markers a lab's set may lack, and what stands for them, as Plug-in Gait decides: a trial
without the sacrum marker ``SACR`` has the midpoint of its posterior superior iliac spine
markers ``LPSI`` and ``RPSI`` in its place.

The choice is made once per trial, by what the trial holds: ``SACR`` is used wherever the
trial has it in any frame (its gaps stay gaps: the PSIS midpoint lies a few centimetres from
where the sacrum marker sits, so filling a gap with it would move the pelvis), and the PSIS
midpoint only where the trial has no ``SACR`` at all (no such label, or the label without a
single sample), and has both PSIS markers.
"""

from __future__ import annotations

import numpy as np

from fccgrb_cli.trial.record import Trial

STAND_INS: dict[str, str] = {"SACR": "mid(LPSI,RPSI)"}
ARGUMENTS: dict[str, tuple[str, ...]] = {"SACR": ("LPSI", "RPSI")}


def _has_data(trial: Trial, name: str) -> bool:
    label = trial.find(name)
    if label is None:
        return False
    return bool(np.isfinite(trial.select([label])).all(axis=2).any())


def stand_ins(trial: Trial, names: set[str]) -> dict[str, str]:
    """The stand-in expression (``mid(A, B)``, model/virtual.py) for each of ``names`` that
    the trial lacks wholly and whose stand-in's markers the trial has.

    Parameters
    ----------
    trial : Trial
        The trial whose labels and samples decide.
    names : set of str
        The marker names the caller reads and no label map or model file defines.

    Returns
    -------
    dict
        Marker name → the expression standing for it; empty where nothing is needed.
    """
    return {name: STAND_INS[name] for name in sorted(names & set(STAND_INS))
            if not _has_data(trial, name)
            and all(_has_data(trial, arg) for arg in ARGUMENTS[name])}


def stand_in_warning(trial: Trial, name: str, expression: str) -> str:
    """The line saying what stands for ``name`` in ``trial``."""
    return (f"{trial.path}: no marker {name}: {expression} stands for it, as Plug-in Gait "
            f"takes it")

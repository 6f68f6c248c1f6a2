"""A solved walking trial's gait analysis: its events (from the chosen source, the other sources
beside them), each side's normalized cycles of the clinical curves, and the spatiotemporal
parameters. Runs where the model reports clinical curves of both sides (lower-limb models)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TypeGuard

import numpy as np

from fccgrb_cli.anatomy.clinical import ClinicalResults
from fccgrb_cli.anatomy.lab_axes import LabAxes
from fccgrb_cli.core.errors import InputError
from fccgrb_cli.gait.cycles import SUFFIX, SideCycles, Walk, side_cycles
from fccgrb_cli.gait.events import (
    SIDES,
    SOURCES,
    Events,
    bridged,
    c3d_events,
    kinematic_events,
    plate_events,
)
from fccgrb_cli.model import Model
from fccgrb_cli.trial.record import Trial

CHOICES = ("auto", *SOURCES)
PELVIS = ("right_asis", "left_asis", "right_psis", "left_psis", "sacrum")
TOES = ("second_metatarsal", "first_metatarsal", "fifth_metatarsal", "toe")


@dataclass(frozen=True)
class GaitResults:
    """``events``: the events used (their ``source`` says which); ``found``: every source's
    events that could be found; ``cycles``: side → SideCycles; ``forward``: the direction of
    walking (unit vector); ``notes``: why a source was not available."""

    events: Events
    found: dict[str, Events]
    cycles: dict[str, SideCycles]
    forward: np.ndarray
    notes: tuple[str, ...] = ()


def landmark_labels(model: Model, trial: Trial) -> dict[str, str]:
    """The trial's label of each landmark the analysis reads (pelvis, heels, toes) that the model
    names and the trial has: all of the trial ``analyse_gait`` needs besides its path, rate and
    frame count."""
    labels = dict(model.landmarks)
    wanted = [*PELVIS, *(f"{side}_{name}" for side in SIDES for name in ("heel", *TOES))]
    found = {landmark: trial.find(labels[landmark]) for landmark in wanted if landmark in labels}
    return {landmark: label for landmark, label in found.items() if label is not None}


def _landmark_markers(model: Model, trial: Trial) -> dict[str, np.ndarray]:
    """Pelvis centre, heels and toes (frames × 3, m) from the model's calibration landmarks."""
    labels = landmark_labels(model, trial)

    def seen(landmark: str) -> np.ndarray | None:
        found = labels.get(landmark)
        return trial.select([found])[:, 0] if found is not None else None

    out: dict[str, np.ndarray] = {}
    pelvis = [m for m in (seen(name) for name in PELVIS) if m is not None]
    if pelvis:
        stacked = np.stack(pelvis)
        with np.errstate(invalid="ignore"):
            counts = np.isfinite(stacked).sum(axis=0)
            out["pelvis"] = np.where(counts > 0, np.nansum(stacked, axis=0) /
                                     np.maximum(counts, 1), np.nan)
    for side in SIDES:
        heel = seen(f"{side}_heel")
        if heel is not None:
            out[f"{side}_heel"] = heel
        toe = next((m for m in (seen(f"{side}_{name}") for name in TOES) if m is not None), None)
        if toe is not None:
            out[f"{side}_toe"] = toe
    return out


def _curves(clinical: ClinicalResults) -> tuple[tuple[str, ...], tuple[str, ...], np.ndarray]:
    """Every clinical angle (deg) and, with the dynamics, its moment (N·m/kg, else N·m)."""
    names, units, columns = list(clinical.names), ["deg"] * len(clinical.names), \
        [clinical.angles]
    moments = clinical.moments_per_kg if clinical.moments_per_kg is not None else \
        clinical.moments
    if moments is not None:
        unit = "N·m/kg" if clinical.moments_per_kg is not None else "N·m"
        # the side suffix stays last so each side's strides pick their own moments
        names += [_moment_name(n) for n in clinical.names]
        units += [unit] * len(clinical.names)
        columns.append(moments)
    return tuple(names), tuple(units), np.column_stack(columns)


def curve_sd(names: tuple[str, ...], angles_sd: np.ndarray, moments_sd: np.ndarray | None
             ) -> dict[str, np.ndarray]:
    """The smoother's standard deviation of every curve ``_curves`` gives (frames each): the
    clinical angles' (deg) and their moments' (in the moments' unit), by the curves' names."""
    out = {name: angles_sd[:, k] for k, name in enumerate(names)}
    if moments_sd is not None:
        out |= {_moment_name(name): moments_sd[:, k] for k, name in enumerate(names)}
    return out


def _moment_name(name: str) -> str:
    for suffix in SUFFIX.values():
        if name.endswith(suffix):
            return f"{name[: -len(suffix)]}_moment{suffix}"
    return f"{name}_moment"


@dataclass(frozen=True)
class FoundEvents:
    """A trial's gait events: the ones chosen, every source's, why a source is missing, the
    landmark trajectories and vertical they were found with, and the lab axes' direction of
    walking (None when the axes did not say)."""

    chosen: Events
    found: dict[str, Events]
    notes: tuple[str, ...]
    markers: dict[str, np.ndarray]
    vertical: np.ndarray
    walking: np.ndarray | None = None


def _has_both_sides(clinical: ClinicalResults | None) -> TypeGuard[ClinicalResults]:
    """True when ``clinical`` is given and names angles of both legs."""
    return clinical is not None and all(any(n.endswith(SUFFIX[s]) for n in clinical.names)
                                        for s in SIDES)


def find_events(model: Model, trial: Trial, clinical: ClinicalResults | None,
                choice: str = "auto", solved: np.ndarray | None = None,
                lab: LabAxes | None = None) -> FoundEvents | None:
    """The gait events of a solved trial from every source (``choice`` the one used), or None
    when the model has no clinical curves of both sides (not a lower-limb model) — unless
    ``choice`` names a source, then that is an error saying why. ``solved``: the frames with a
    solution; events elsewhere, of any source, are left out (no data, no event). ``lab``: the
    run's lab axes (``anatomy.lab_axes``; default: up against the model's gravity), whose vertical
    the events, step lengths and widths are measured with."""
    if not _has_both_sides(clinical):
        if choice != "auto":
            raise InputError(f"{model.source}: --events {choice}: expected a model with "
                             "clinical angles of both legs (names ending _l and _r)")
        return None
    vertical = _vertical(model, lab)
    markers = _landmark_markers(model, trial)
    found: dict[str, Events] = {}
    notes: list[str] = []
    if trial.path.lower().endswith(".c3d"):
        events = c3d_events(trial.path, trial.n_frames, trial.rate)
        if events is not None:
            found["c3d"] = events
        else:
            notes.append("c3d: the file has no foot events")
        events = plate_events(trial.path, trial.rate, clinical.stance)
        if events is not None:
            found["plates"] = events
        else:
            notes.append("plates: no force plate loaded a foot (or the dynamics did not run)")
    try:
        found["kinematic"] = kinematic_events(markers, trial.rate, vertical,
                                              f"{trial.path} with {model.source}")
    except InputError as error:
        notes.append(f"kinematic: {str(error).split(': ', 2)[-1]}")
    if solved is not None:
        found = {source: _with_data(events, solved, trial.rate, notes)
                 for source, events in found.items()}
        found = {source: events for source, events in found.items() if len(events)}
    chosen = _choose(found, choice, trial.path, notes)
    if chosen is None:
        return None
    return FoundEvents(chosen, found, tuple(notes), markers, vertical,
                      None if lab is None else lab.forward)


def analyse_gait(model: Model, trial: Trial, clinical: ClinicalResults | None,
                 trusted: np.ndarray, choice: str = "auto", *, solved: np.ndarray | None = None,
                 trusted_curves: np.ndarray | None = None,
                 events: FoundEvents | None = None) -> GaitResults | None:
    """The gait analysis of a solved trial (its events by :func:`find_events` unless
    ``events`` holds them), or None as there. ``trusted``: per frame (the kinematics);
    ``trusted_curves``: per frame and clinical curve (angles, then moments), where a moment can
    be untrusted on a trusted frame (each variable's mean over the strides it is trusted on)."""
    events = events or find_events(model, trial, clinical, choice, solved)
    if events is None or clinical is None:
        return None
    markers, vertical, chosen = events.markers, events.vertical, events.chosen
    forward = _forward(markers, vertical, events.walking)
    heels = {side: markers[f"{side}_heel"] for side in SIDES if f"{side}_heel" in markers}
    curves = _curves(clinical)
    filled = {k: bridged(v) for k, v in heels.items()}
    walk = Walk(trial.time, {k: v for k, v in filled.items() if v is not None}, forward,
                vertical)
    cycles = {side: side_cycles(side, chosen, trusted, curves, walk, trusted_curves)
              for side in SIDES}
    return GaitResults(chosen, events.found, cycles, forward, events.notes)


def _with_data(events: Events, solved: np.ndarray, rate: float, notes: list[str]) -> Events:
    """The events at frames with a solution (the nearest frame's); a note counts the others."""
    frames = np.clip(np.round(events.time * rate).astype(int), 0, len(solved) - 1)
    keep = solved[frames]
    if keep.all():
        return events
    notes.append(f"{events.source}: {int((~keep).sum())} events at frames without a solution "
                 "left out")
    return Events(events.source, events.time[keep],
                  tuple(s for s, k in zip(events.side, keep, strict=True) if k),
                  tuple(s for s, k in zip(events.kind, keep, strict=True) if k))


def _choose(found: dict[str, Events], choice: str, path: str, notes: list[str]
            ) -> Events | None:
    if choice != "auto":
        if choice not in found:
            why = next((n for n in notes if n.startswith(choice)), f"{choice}: none found")
            raise InputError(f"{path}: --events {choice}: expected events from that source; "
                             f"{why}")
        return found[choice]
    for source in SOURCES:
        if source in found and (source == "c3d" or found[source].has_strides()):
            return found[source]
    return next(iter(found.values()), None)


def _vertical(model: Model, lab: LabAxes | None) -> np.ndarray:
    """The unit vector up: the lab axes', else against the model's gravity, else +z."""
    up = -np.asarray(model.gravity, dtype=float) if lab is None else lab.up
    norm = np.linalg.norm(up)
    return up / norm if norm else np.array([0.0, 0.0, 1.0])


def _forward(markers: dict[str, np.ndarray], vertical: np.ndarray,
             walking: np.ndarray | None) -> np.ndarray:
    """The direction of walking: the pelvis's horizontal travel; else the lab axes' (the
    markers' mean velocity); else x (y when x is up)."""
    pelvis = bridged(markers["pelvis"]) if "pelvis" in markers else None
    if pelvis is not None:
        travel = pelvis[-1] - pelvis[0]
        travel -= (travel @ vertical) * vertical
        norm = np.linalg.norm(travel)
        if norm > 0:
            return travel / norm
    if walking is not None:
        return walking
    return np.eye(3)[1 if abs(vertical[0]) > 0.5 else 0]

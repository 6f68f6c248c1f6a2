"""The scene of a results file's runs: the solved model per frame from q (rebuilt from the
model text every run stores), the markers the solver saw with their model points and
distances, the plates' forces at their centres of pressure, the flags with the file's own
explanations, and the chosen angle with its joint moment."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from fccgrb_cli.core.datasets import open_results
from fccgrb_cli.core.errors import InputError
from fccgrb_cli.pipeline.run import Run
from fccgrb_cli.results.format import reading
from fccgrb_cli.results.runs import read_runs
from fccgrb_cli.solvers.quality import FRAME_BITS
from fccgrb_cli.view.camera import lab_axes
from fccgrb_cli.view.scene import (
    FORCE_M_PER_N,
    Bit,
    Curve,
    Layer,
    Scene,
    display_frames,
    floor_height,
    marker_limit_m,
    positions_bytes,
    skeleton_layer,
)
from fccgrb_cli.view.skeleton import Skeleton, body_coordinates, skeleton

MAX_RUNS = 2


def chosen_runs(path: str | Path, names: tuple[str, ...]) -> list[Run]:
    """The runs to draw: those named (at most two, in the order given), or the file's runs
    when it holds one or two; they must share the trial's frames and clock."""
    runs = read_runs(path)
    if not names:
        if len(runs) > MAX_RUNS:
            raise InputError(f"{path}: holds {len(runs)} runs ({', '.join(runs)}); choose one "
                             "or two with --run")
        names = tuple(runs)
    if len(names) > MAX_RUNS:
        raise InputError(f"--run: expected one or two runs to overlay, got {len(names)}")
    unknown = [n for n in names if n not in runs]
    if unknown:
        raise InputError(f"--run: expected a run of {path} ({', '.join(runs)}), got "
                         f"{', '.join(unknown)}")
    chosen = [runs[n] for n in names]
    first = chosen[0]
    for run in chosen[1:]:
        if len(run.result.time) != len(first.result.time) or \
                run.start_time != first.start_time:
            raise InputError(f"--run: {first.name!r} and {run.name!r} are not the same "
                             f"trial's frames ({len(first.result.time)} and "
                             f"{len(run.result.time)} frames); overlay runs of one trial")
    return chosen


def motion_scene(path: str | Path, names: tuple[str, ...] = (), curve: str | None = None,
                 frames: np.ndarray | None = None) -> Scene:
    """The scene of one or two runs of a results file.

    Parameters
    ----------
    path : the results file.
    names : the runs to draw (see :func:`chosen_runs`).
    curve : the angle drawn under the scene with its joint moment [default: the first angle
        with a clinical sign, else the first angle].
    frames : the frames to place (indices); default: :func:`display_frames` of the trial.

    Returns
    -------
    The scene; its time on the trial's clock (the first frame at the run's start time).
    """
    runs = chosen_runs(path, names)
    skeletons = [skeleton(run.model) for run in runs]
    n = len(runs[0].result.time)
    if frames is not None and not ((frames >= 0) & (frames < n)).all():
        raise InputError(f"--frame: expected a frame index from 0 to {n - 1} of {path}, got "
                         f"{', '.join(str(f) for f in frames[(frames < 0) | (frames >= n)])}")
    if frames is None:
        frames = display_frames(n, positions_bytes(
            [(s, len(run.labels), len(run.dynamics.loads) if run.dynamics else 0)
             for s, run in zip(skeletons, runs, strict=True)]))
    bits = _bits(path, [run.name for run in runs])
    layers = tuple(_layer(run, s, frames, bits[run.name], curve)
                   for run, s in zip(runs, skeletons, strict=True))
    first = runs[0]
    axes = lab_axes(first.axes.up, first.axes.forward) if first.axes is not None else \
        lab_axes(-np.asarray(first.model.gravity, dtype=float))
    notes = [_vertical_note(first)]
    if 1 < len(frames) < n:
        notes.append(f"shown: every {int(frames[1] - frames[0])}th of the trial's {n} frames "
                     "and the last (for display only; the results file keeps every frame, "
                     "the flags and curves here too)")
    time = first.start_time + np.asarray(first.result.time, dtype=float)
    return Scene(f"{Path(path).name}: {' vs '.join(r.name for r in runs)}", time,
                 np.asarray(frames, dtype=int), layers, axes,
                 floor_height(list(layers), axes), tuple(notes),
                 vertical=first.axes.vertical if first.axes is not None else "")


def _vertical_note(run: Run) -> str:
    if run.axes is None:
        return f"the lab's vertical: against the model's gravity {tuple(run.model.gravity)} m/s²"
    a = run.axes
    return f"the lab's vertical: {a.vertical} (chosen by {a.chosen_by}: {a.why})"


def _bits(path: str | Path, names: list[str]) -> dict[str, tuple[Bit, ...]]:
    """Each run's flag bits as its file describes them (meaning and this run's detail), the
    package's own for a file without the description."""
    out = {}
    with open_results(path) as h5:
        for name in names:
            with reading(path, f"/runs/{name}/flags"):
                text = h5["runs"][name]["flags"].attrs.get("bits")
                described: list[dict[str, Any]] = json.loads(text) if text is not None else \
                    [{"value": b.value, "name": b.name, "meaning": b.meaning}
                     for b in FRAME_BITS]
                out[name] = tuple(Bit(int(b["value"]), str(b["name"]), str(b["meaning"]),
                                      str(b.get("detail", ""))) for b in described)
    return out


def _layer(run: Run, s: Skeleton, frames: np.ndarray, bits: tuple[Bit, ...],
           curve: str | None) -> Layer:
    """The run's skeleton from its q, then its markers, model points and plate loads as
    further points (they are not body-fixed: their places come from the file)."""
    x = body_coordinates(run.model, np.asarray(run.result.q)[frames])
    base = skeleton_layer(run.name, s, x)
    labels, kinds = list(base.labels), list(base.kinds)
    lines, line_kinds, line_labels = base.lines.tolist(), list(base.line_kinds), \
        list(base.line_labels)
    blocks = [base.positions]

    def add(points: np.ndarray, names: list[str], kind: str) -> np.ndarray:
        start = len(labels)
        labels.extend(names)
        kinds.extend([kind] * len(names))
        blocks.append(points)
        return np.arange(start, start + len(names))

    marker_names = list(run.labels)
    model_points = add(np.asarray(run.model_points)[frames], marker_names, "model_point")
    markers = add(np.asarray(run.markers_input)[frames], marker_names, "marker")
    for m, p, name in zip(markers, model_points, marker_names, strict=True):
        lines.append([int(m), int(p)])
        line_kinds.append("gap")
        line_labels.append(name)
    for load in run.dynamics.loads if run.dynamics is not None else ():
        force = np.asarray(load.force, dtype=float)[frames]
        point = np.asarray(load.point, dtype=float)[frames].copy()
        point[np.linalg.norm(force, axis=1) < run.model.plate_threshold] = np.nan  # unloaded
        tip = point + FORCE_M_PER_N * force
        cop, end = add(point[:, None], [f"{load.name} on {load.body}"], "cop")[0], \
            add(tip[:, None], [""], "hidden")[0]
        lines.append([int(cop), int(end)])
        line_kinds.append("force")
        line_labels.append(load.name)
    return Layer(run.name, tuple(labels), tuple(kinds), np.concatenate(blocks, axis=1),
                 np.asarray(lines, dtype=int).reshape(-1, 2), tuple(line_kinds),
                 tuple(line_labels), markers, model_points,
                 np.asarray(run.ed_input, dtype=float)[frames],
                 marker_limit_m(run.perturb_level_m), np.asarray(run.result.flags),
                 np.asarray(run.trusted, dtype=bool), bits, _curves(run, curve))


def _curves(run: Run, curve: str | None) -> tuple[Curve, ...]:
    """The chosen angle (its clinical value in degrees where it declares a clinical sign, else
    degrees or metres) and its joint moment, conjugate to the value shown (N·m; N for a
    distance), each with its standard deviation where the file has one."""
    model, names = run.model, tuple(run.result.angle_names)
    if not names:
        return ()
    if curve is None:
        signed = [a.name for a in model.angles if a.clinical_sign is not None]
        curve = signed[0] if signed else names[0]
    if curve not in names:
        raise InputError(f"--curve: expected an angle of run {run.name!r} "
                         f"({', '.join(names)}), got {curve}")
    k = names.index(curve)
    angle = model.angles[k]
    theta = np.asarray(run.result.theta, dtype=float)[:, k]
    u = run.uncertainty
    theta_sd = None if u is None else np.asarray(u.theta_sd, dtype=float)[:, k]
    distance = angle.kind == "distance"
    sign = 1.0 if distance or angle.clinical_sign is None else float(angle.clinical_sign)
    if distance:
        values, unit, sd = theta, "m", theta_sd
    else:
        clinical = angle.clinical(theta)
        values = clinical if clinical is not None else np.degrees(theta)
        unit, sd = "deg", None if theta_sd is None else np.degrees(theta_sd)
    label = f"{curve} (clinical)" if angle.clinical_sign is not None else curve
    out = [Curve(label, unit, values, sd, np.asarray(run.trusted, dtype=bool))]
    if run.dynamics is not None:
        moment = sign * np.asarray(run.dynamics.inverse.joint_moments, dtype=float)[:, k]
        moment_sd = None if u is None or u.moments_sd is None else \
            np.asarray(u.moments_sd, dtype=float)[:, k]
        trusted = np.asarray(run.trusted, dtype=bool) if run.moment_flags is None else \
            np.asarray(run.moment_flags)[:, k] == 0
        out.append(Curve(f"{label} moment", "N" if distance else "N·m", moment, moment_sd,
                         trusted))
    return tuple(out)

"""A solved run in the files other tools read: OpenSim motion (.mot) and storage (.sto) files, a
tidy CSV for pandas or a spreadsheet, and the trial's C3D with the model's outputs added as
points, as Vicon and Visual3D store theirs.

What is exported: the clinical angles and moments when the model declares clinical signs (the
gait convention), else every joint angle and its moment. Angles in degrees (a distance
coordinate in metres), moments in N·m (a distance's joint force in N). Frames the quality checks
do not trust are exported with their values, and counted: in the CSV's ``trusted`` column, in
the .mot/.sto header (``untrustedFrames``) and in the C3D (``FCCGRB:UNTRUSTED``, the frame
numbers); the command line says how many on stderr. Moments have their own trust on top of
their frame's (a ground reaction no plate measured, unfiltered accelerations: README, "What
fccgrb checks for you"): the CSV's ``moments trusted`` column, the .sto's ``untrustedFrames``
and the C3D's residual of the moment points count a frame whose exported moments are not all
trusted.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from fccgrb_cli.errors import InputError
from fccgrb_cli.io.atomic import atomic_path
from fccgrb_cli.run import Run

FORMATS = ("mot", "sto", "csv", "c3d")


@dataclass(frozen=True)
class Curves:
    """Frames × columns of one kind (angles or moments) with their names and units."""

    names: tuple[str, ...]
    units: tuple[str, ...]
    values: np.ndarray


def angle_curves(run: Run) -> Curves:
    """Clinical angles (deg) where the model declares them, else the joint angles in degrees
    (distances in m)."""
    clinical = run.clinical_angles
    if clinical is not None:
        return Curves(clinical.names, clinical.units, clinical.values)
    a = run.angles
    degrees = np.array([u == "rad" for u in a.units])
    values = np.where(degrees, np.degrees(a.values), a.values)
    return Curves(a.names, tuple("deg" if d else u for d, u in zip(degrees, a.units,
                                                                     strict=True)), values)


def moment_curves(run: Run) -> Curves | None:
    """Clinical moments (N·m, internal) where declared, else the joint moments; None without
    the dynamics. Named after OpenSim's inverse dynamics output: ``<coordinate>_moment`` (a
    distance's: ``_force``)."""
    clinical = run.clinical
    if clinical is not None and clinical.moments is not None:
        return Curves(tuple(f"{n}_moment" for n in clinical.names),
                      ("N·m",) * len(clinical.names), clinical.moments)
    m = run.moments
    if m is None:
        return None
    return Curves(tuple(f"{n}_{'force' if u == 'N' else 'moment'}" for n, u in
                        zip(m.names, m.units, strict=True)), m.units, m.values)


def moments_trusted(run: Run) -> np.ndarray:
    """Per frame: the frame is trusted and so is every exported moment (the clinical ones where
    the model declares them, else every joint's)."""
    trusted = run.moments_trusted
    if trusted is None:
        return run.trusted
    clinical = run.clinical
    if clinical is not None and clinical.moments is not None:
        model = [a.name for a in run.model.angles]
        trusted = trusted[:, [model.index(name) for name in clinical.names]]
    return run.trusted & trusted.all(axis=1)


def _storage_text(run: Run, curves: Curves, title: str, in_degrees: bool,
                  trusted: np.ndarray | None = None) -> str:
    """OpenSim's Storage layout (read by OpenSim 3 and 4): a name line, key=value lines,
    ``endheader``, then a tab-separated table whose first column is time; ``trusted``: per
    frame (default the run's)."""
    time = run.result.time
    untrusted = int((~(run.trusted if trusted is None else trusted)).sum())
    lines = [title, "version=1", f"nRows={len(time)}", f"nColumns={1 + len(curves.names)}",
             f"inDegrees={'yes' if in_degrees else 'no'}", f"untrustedFrames={untrusted}",
             f"units={' '.join(sorted(set(curves.units)))}", "endheader",
             "\t".join(["time", *curves.names])]
    table = np.column_stack([time, curves.values])
    lines += ["\t".join(f"{v:.10g}" for v in row) for row in table]
    return "\n".join(lines) + "\n"


def write_mot(run: Run, path: str | Path) -> None:
    """The angles as an OpenSim motion file (degrees, ``inDegrees=yes``)."""
    _write_text(path, _storage_text(run, angle_curves(run), f"{run.name}_angles", True))


def write_sto(run: Run, path: str | Path) -> None:
    """The joint moments as an OpenSim storage file, as OpenSim's inverse dynamics writes them
    (N·m; ``inDegrees=no``)."""
    moments = _needs_moments(run, path)
    _write_text(path, _storage_text(run, moments, f"{run.name}_moments", False,
                                    moments_trusted(run)))


def sd_curves(run: Run) -> list[Curves]:
    """The smoother's standard deviations of the exported curves (``name sd``, same units),
    [] without ``--smooth auto``."""
    angles = angle_curves(run)
    moments = moment_curves(run)
    if run.clinical is not None:
        clinical = run.clinical_sd
        if clinical is None:
            return []
        a_sd, m_sd = clinical
        if m_sd is not None and moments is not None and run.clinical.mass is not None:
            m_sd = replace(m_sd, values=m_sd.values * run.clinical.mass)  # the export's N·m
        per = [(angles, a_sd.values), (moments, None if m_sd is None else m_sd.values)]
    else:
        if run.angle_sd is None:
            return []
        a = run.angle_sd
        degrees = np.array([u == "rad" for u in a.units])
        per = [(angles, np.where(degrees, np.degrees(a.values), a.values)),
               (moments, None if run.moment_sd is None else run.moment_sd.values)]
    return [Curves(tuple(f"{n} sd" for n in curves.names), curves.units, values)
            for curves, values in per if curves is not None and values is not None]


def write_csv(run: Run, path: str | Path) -> None:
    """One row per frame: ``time [s]``, ``trusted``, ``moments trusted`` (with moments: the frame
    and every moment in the row trusted), then every angle and moment as ``name [unit]`` and,
    with ``--smooth auto``, each one's standard deviation as ``name sd [unit]``;
    ``pandas.read_csv(path)`` reads it in one call."""
    parts = [angle_curves(run)]
    moments = moment_curves(run)
    if moments is not None:
        parts.append(moments)
    flags = [run.trusted] + ([moments_trusted(run)] if moments is not None else [])
    parts += sd_curves(run)
    header = ["time [s]", "trusted"] + (["moments trusted"] if moments is not None else []) + [
        f"{n} [{u}]" for c in parts for n, u in zip(c.names, c.units, strict=True)]
    values = np.column_stack([c.values for c in parts])
    rows = [",".join(header)]
    for t, *ok, row in zip(run.result.time, *flags, values, strict=True):
        rows.append(",".join([f"{t:.10g}", *("true" if o else "false" for o in ok),
                              *(f"{v:.10g}" for v in row)]))
    _write_text(path, "\n".join(rows) + "\n")


def write_c3d(run: Run, path: str | Path, trial: str | Path | None = None) -> None:
    """The trial's C3D (``trial``, default the file the run was solved from) with its markers,
    analogs, force plates and events kept, and the angles and moments added as points: one
    point per variable, the value in X (Y, Z zero), listed in ``POINT:ANGLES`` / ``POINT:MOMENTS``
    with ``POINT:ANGLE_UNITS`` (deg) and ``POINT:MOMENT_UNITS`` (N.m), as Vicon Nexus and
    Visual3D store model outputs."""
    import ezc3d

    from fccgrb_cli.io.c3d import save
    from fccgrb_cli.io.c3d_header import read_layout

    source = Path(trial if trial is not None else run.trial_path)
    if source.suffix.lower() != ".c3d" or not source.is_file():
        raise InputError(f"{source}: expected the run's C3D trial to add the outputs to "
                         "(--trial FILE.c3d when it has moved)")
    if read_layout(source).truncated:  # ezc3d reads past the end of a cut file
        raise InputError(f"{source}: the file is truncated: expected the trial the run was "
                         "solved from")
    try:
        c3d = ezc3d.c3d(str(source))
    except Exception as error:  # ezc3d raises bare RuntimeErrors for unreadable files
        raise InputError(f"{source}: not a readable C3D file ({error})") from None
    points = c3d["data"]["points"]
    n_frames = points.shape[2]
    if n_frames != len(run.result.time):
        raise InputError(f"{source}: {n_frames} frames, but run {run.name!r} has "
                         f"{len(run.result.time)}: expected the trial it was solved from")
    labels = list(c3d["parameters"]["POINT"]["LABELS"]["value"])
    angles, moments = angle_curves(run), moment_curves(run)
    added = [angles] + ([moments] if moments is not None else [])
    names = [n for c in added for n in c.names]
    clash = sorted(set(names) & set(labels))
    if clash:
        raise InputError(f"{source}: already has points named {', '.join(clash)}")
    extra = np.zeros((4, len(names), n_frames))
    extra[0] = np.column_stack([c.values for c in added]).T
    extra[3] = np.where(run.trusted, 0.0, -1.0)  # residual −1: Vicon's "invalid" frame
    if moments is not None:
        extra[3, len(angles.names):] = np.where(moments_trusted(run), 0.0, -1.0)
    c3d["parameters"]["POINT"]["LABELS"]["value"] = labels + names
    descriptions = list(c3d["parameters"]["POINT"].get("DESCRIPTIONS", {}).get("value", []))
    if descriptions:
        c3d["parameters"]["POINT"]["DESCRIPTIONS"]["value"] = (
            descriptions + [f"fccgrb {run.name}"] * len(names))
    c3d["data"]["points"] = np.concatenate([points, extra], axis=1)
    del c3d["data"]["meta_points"]
    c3d.add_parameter("POINT", "ANGLES", list(angles.names))
    c3d.add_parameter("POINT", "ANGLE_UNITS", ["deg"])
    if moments is not None:
        c3d.add_parameter("POINT", "MOMENTS", list(moments.names))
        c3d.add_parameter("POINT", "MOMENT_UNITS", ["N.m"])
    untrusted = [int(f) + 1 for f in np.flatnonzero(~run.trusted)]
    c3d.add_parameter("FCCGRB", "RUN", [run.name])
    c3d.add_parameter("FCCGRB", "UNTRUSTED", untrusted or [0])
    save(c3d, path)


def _needs_moments(run: Run, path: str | Path) -> Curves:
    moments = moment_curves(run)
    if moments is None:
        raise InputError(f"{path}: run {run.name!r} has no joint moments (solved without the "
                         "dynamics); expected a run solved with --dynamics")
    return moments


def _write_text(path: str | Path, text: str) -> None:
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


def export(run: Run, fmt: str, path: str | Path, trial: str | Path | None = None) -> None:
    """Write ``run`` to ``path`` in one of FORMATS."""
    writers = {"mot": write_mot, "sto": write_sto, "csv": write_csv}
    if fmt == "c3d":
        write_c3d(run, path, trial)
    elif fmt in writers:
        writers[fmt](run, path)
    else:
        raise InputError(f"--format: expected one of {', '.join(FORMATS)}, got {fmt!r}")


def choose_run(runs: dict[str, Run], name: str | None, source: str | Path) -> Run:
    """The run named ``name``, or the file's only run."""
    if name is not None:
        if name not in runs:
            raise InputError(f"{source}: no run {name!r}; expected one of {', '.join(runs)}")
        return runs[name]
    if len(runs) != 1:
        raise InputError(f"{source}: holds runs {', '.join(runs)}; expected --run NAME")
    return next(iter(runs.values()))


def default_output(results: str | Path, run: Run, fmt: str, many: Sequence[str]) -> Path:
    """``RESULTS.mot`` beside the results file (``RESULTS.<run>.mot`` when it holds several)."""
    stem = Path(results).with_suffix("")
    return Path(f"{stem}.{run.name}.{fmt}" if len(many) > 1 else f"{stem}.{fmt}")

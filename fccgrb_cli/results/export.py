"""A solved run in the files other tools read: OpenSim motion (.mot) and storage (.sto) files, a
tidy CSV for pandas or a spreadsheet, and the trial's C3D with the model's outputs added as
points, as Vicon and Visual3D store theirs; for a Plug-in Gait model also its outputs under
Plug-in Gait's names (C3D, ``convention='plugin-gait'``) and OpenSim's coordinate names (.mot,
``convention='opensim'``). Times are on the trial's clock (its first frame's time).

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

from fccgrb_cli.core.atomic import atomic_path
from fccgrb_cli.core.errors import InputError
from fccgrb_cli.opensim.storage import storage_text
from fccgrb_cli.pipeline.run import Run

FORMATS = ("mot", "sto", "csv", "c3d")
CONVENTIONS = ("fccgrb", "plugin-gait", "opensim")
# Which conventions each format takes (fccgrb: the model's own angles or clinical angles).
FORMAT_CONVENTIONS = {"mot": ("fccgrb", "opensim"), "sto": ("fccgrb",), "csv": ("fccgrb",),
                      "c3d": ("fccgrb", "plugin-gait")}
# Plug-in Gait's point groups as Nexus writes them: kind → (POINT group, its units parameter,
# the unit Nexus writes; its moments and powers are per kg of body mass whatever the unit says).
PIG_GROUPS = {"angles": ("ANGLES", "ANGLE_UNITS", "deg"),
              "moments": ("MOMENTS", "MOMENT_UNITS", "Nmm"),
              "powers": ("POWERS", "POWER_UNITS", "W")}


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
    """OpenSim's Storage layout (``opensim.storage``: read by OpenSim 3 and 4): a name line,
    ``version``, ``nRows``, ``nColumns``, ``inDegrees`` and fccgrb's ``untrustedFrames`` and
    ``units``, ``endheader``, then a tab-separated table whose first column is time (on the
    trial file's clock); ``trusted``: per frame (default the run's)."""
    time = run.result.time + run.start_time
    untrusted = int((~(run.trusted if trusted is None else trusted)).sum())
    return storage_text(curves.names, time, curves.values, in_degrees, title,
                        {"untrustedFrames": str(untrusted),
                         "units": " ".join(sorted(set(curves.units))),
                         "clock": f"the trial file's, first frame at {run.start_time:.10g} s"})


def write_mot(run: Run, path: str | Path) -> None:
    """The angles as an OpenSim motion file (degrees, ``inDegrees=yes``)."""
    _write_text(path, _storage_text(run, angle_curves(run), f"{run.name}_angles", True))


def opensim_curves(run: Run) -> Curves:
    """A Plug-in Gait run's motion in OpenSim's coordinate names and signs (Rajagopal et al.
    2015's full-body model; gait2354/2392 take the same names and signs but count knee flexion
    negative): pelvis_tilt, pelvis_list, pelvis_rotation (deg: the pelvis's Z–X–Y body-fixed
    rotations from OpenSim's ground, X the direction of progression, Y up, Z to the right, so
    that an anterior tilt is a negative pelvis_tilt), pelvis_tx, _ty, _tz (m: the pelvis
    origin, mid-ASIS, in that frame), and per side hip_flexion, hip_adduction, hip_rotation,
    knee_angle, ankle_angle (deg; flexion, adduction, internal rotation and dorsiflexion
    positive on both sides). Plug-in Gait's Cardan sequences are OpenSim's with its y axis (to
    the left) for OpenSim's z (to the right), so: tilt = −PelvisAngles X, list = LPelvisAngles
    Y, rotation = RPelvisAngles Z; the hip's three = HipAngles X, Y, Z; knee_angle = KneeAngles
    X; ankle_angle = AnkleAngles X."""
    pig = run.plugin_gait
    if pig is None:
        raise InputError(f"run {run.name!r} has no Plug-in Gait outputs: --convention opensim "
                         "expects a run of a model calibrated from configs/models/"
                         "plugin_gait.yaml")
    a = pig.angles
    x, left, up = pig.progression.T
    origin = np.column_stack([run.q[f"pelvis.r.{c}"] for c in "xyz"])
    columns = {"pelvis_tilt": -a["LPelvisAngles"][:, 0], "pelvis_list": a["LPelvisAngles"][:, 1],
               "pelvis_rotation": a["RPelvisAngles"][:, 2], "pelvis_tx": origin @ x,
               "pelvis_ty": origin @ up, "pelvis_tz": origin @ -left}
    for s, side in (("r", "R"), ("l", "L")):
        hip = a[f"{side}HipAngles"]
        columns.update({f"hip_flexion_{s}": hip[:, 0], f"hip_adduction_{s}": hip[:, 1],
                        f"hip_rotation_{s}": hip[:, 2],
                        f"knee_angle_{s}": a[f"{side}KneeAngles"][:, 0],
                        f"ankle_angle_{s}": a[f"{side}AnkleAngles"][:, 0]})
    units = tuple("m" if name in ("pelvis_tx", "pelvis_ty", "pelvis_tz") else "deg"
                  for name in columns)
    return Curves(tuple(columns), units, np.column_stack(list(columns.values())))


def write_mot_opensim(run: Run, path: str | Path) -> None:
    """:func:`opensim_curves` as an OpenSim motion file (``inDegrees=yes``)."""
    _write_text(path, _storage_text(run, opensim_curves(run), f"{run.name}_opensim", True))


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
    """One row per frame: ``trial time [s]`` (the trial file's clock), ``trusted``, ``moments
    trusted`` (with moments: the frame and every moment in the row trusted), then every angle
    and moment as ``name [unit]`` and, with ``--smooth auto``, each one's standard deviation as
    ``name sd [unit]``;
    ``pandas.read_csv(path)`` reads it in one call."""
    parts = [angle_curves(run)]
    moments = moment_curves(run)
    if moments is not None:
        parts.append(moments)
    flags = [run.trusted] + ([moments_trusted(run)] if moments is not None else [])
    parts += sd_curves(run)
    header = ["trial time [s]", "trusted"] + \
        (["moments trusted"] if moments is not None else []) + \
        [f"{n} [{u}]" for c in parts for n, u in zip(c.names, c.units, strict=True)]
    values = np.column_stack([c.values for c in parts])
    rows = [",".join(header)]
    for t, *ok, row in zip(run.result.time + run.start_time, *flags, values, strict=True):
        rows.append(",".join([f"{t:.10g}", *("true" if o else "false" for o in ok),
                              *(f"{v:.10g}" for v in row)]))
    _write_text(path, "\n".join(rows) + "\n")


def _source_c3d(run: Run, trial: str | Path | None):
    """The run's trial (``trial``, default the file it was solved from) as an ezc3d object,
    checked to have the run's frames."""
    import ezc3d

    from fccgrb_cli.trial.c3d_header import read_layout

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
    n_frames = c3d["data"]["points"].shape[2]
    if n_frames != len(run.result.time):
        raise InputError(f"{source}: {n_frames} frames, but run {run.name!r} has "
                         f"{len(run.result.time)}: expected the trial it was solved from")
    from fccgrb_cli.results.same_trial import check_same_trial

    check_same_trial(run, source)
    return c3d, source


def _point_texts(point: dict, key: str) -> list[str]:
    """A POINT text parameter continued past 255 entries (LABELS, LABELS2, …)."""
    values = list(point.get(key, {}).get("value", []))
    k = 2
    while f"{key}{k}" in point:
        values += list(point[f"{key}{k}"]["value"])
        k += 1
    return values


def _set_points(c3d, keep: list[int], names: list[str], extra: np.ndarray,
                description: str) -> None:
    """The file's points ``keep`` (indices) followed by new points ``names`` (extra: 4 ×
    names × frames: x, y, z, residual), labels and descriptions continued past 255 entries
    (ezc3d writes LABELS2, … itself; DESCRIPTIONS2, … are written here)."""
    point = c3d["parameters"]["POINT"]
    labels = _point_texts(point, "LABELS")
    descriptions = _point_texts(point, "DESCRIPTIONS")
    for key in [k for k in point if k.startswith(("LABELS", "DESCRIPTIONS")) and
                k not in ("LABELS", "DESCRIPTIONS")]:
        del point[key]
    point["LABELS"]["value"] = [labels[k] for k in keep] + names
    if descriptions:
        descriptions += [""] * (len(labels) - len(descriptions))
        texts = [descriptions[k] for k in keep] + [description] * len(names)
        point["DESCRIPTIONS"]["value"] = texts[:255]  # a C3D dimension holds 255 at most
        for k in range(255, len(texts), 255):
            c3d.add_parameter("POINT", f"DESCRIPTIONS{k // 255 + 1}", texts[k:k + 255])
    c3d["data"]["points"] = np.concatenate([c3d["data"]["points"][:, keep], extra], axis=1)
    del c3d["data"]["meta_points"]


def write_c3d(run: Run, path: str | Path, trial: str | Path | None = None) -> None:
    """The trial's C3D (``trial``, default the file the run was solved from) with its markers,
    analogs, force plates and events kept, and the angles and moments added as points: one
    point per variable, the value in X (Y, Z zero), listed in ``POINT:ANGLES`` / ``POINT:MOMENTS``
    with ``POINT:ANGLE_UNITS`` (deg) and ``POINT:MOMENT_UNITS`` (N.m), as Vicon Nexus and
    Visual3D store model outputs."""
    from fccgrb_cli.trial.c3d import save

    c3d, source = _source_c3d(run, trial)
    n_frames = c3d["data"]["points"].shape[2]
    labels = _point_texts(c3d["parameters"]["POINT"], "LABELS")
    angles, moments = angle_curves(run), moment_curves(run)
    added = [angles] + ([moments] if moments is not None else [])
    names = [n for c in added for n in c.names]
    clash = sorted(set(names) & {label.strip() for label in labels})
    if clash:
        raise InputError(f"{source}: already has points named {', '.join(clash)}")
    extra = np.zeros((4, len(names), n_frames))
    extra[0] = np.column_stack([c.values for c in added]).T
    extra[3] = np.where(run.trusted, 0.0, -1.0)  # residual −1: Vicon's "invalid" frame
    if moments is not None:
        extra[3, len(angles.names):] = np.where(moments_trusted(run), 0.0, -1.0)
    _set_points(c3d, list(range(len(labels))), names, extra, f"fccgrb {run.name}")
    c3d.add_parameter("POINT", "ANGLES", list(angles.names))
    c3d.add_parameter("POINT", "ANGLE_UNITS", ["deg"])
    if moments is not None:
        c3d.add_parameter("POINT", "MOMENTS", list(moments.names))
        c3d.add_parameter("POINT", "MOMENT_UNITS", ["N.m"])
    _mark_run(c3d, run)
    save(c3d, path)


def _mark_run(c3d, run: Run) -> None:
    untrusted = [int(f) + 1 for f in np.flatnonzero(~run.trusted)]
    c3d.add_parameter("FCCGRB", "RUN", [run.name])
    c3d.add_parameter("FCCGRB", "UNTRUSTED", untrusted or [0])


def write_c3d_plugin_gait(run: Run, path: str | Path, trial: str | Path | None = None) -> int:
    """The trial's C3D with the run's Plug-in Gait outputs as Nexus writes them: one point of
    three components per output, named as Plug-in Gait names it (``LHipAngles``,
    ``LKneeMoment``, ``LAnklePower``, …: angles in deg, moments in N·mm/kg, powers in W/kg in
    Z), listed in ``POINT:ANGLES``, ``MOMENTS``, ``POWERS`` with the units Nexus writes (deg,
    Nmm, W); an untrusted or unsolved frame has residual −1 (Vicon's invalid frame). Points
    of the same names already in the file (Vicon's own outputs) are replaced; returns how many
    were."""
    from fccgrb_cli.trial.c3d import save

    pig = run.plugin_gait
    if pig is None:
        raise InputError(f"run {run.name!r} has no Plug-in Gait outputs: expected a run of a "
                         "model calibrated from configs/models/plugin_gait.yaml")
    c3d, _ = _source_c3d(run, trial)
    point = c3d["parameters"]["POINT"]
    labels = [label.strip() for label in _point_texts(point, "LABELS")]
    curves = {name: values for kind in PIG_GROUPS for name, values in pig.kinds()[kind].items()}
    names = list(curves)
    keep = [k for k, label in enumerate(labels) if label not in curves]
    n_frames = c3d["data"]["points"].shape[2]
    extra = np.zeros((4, len(names), n_frames))
    for k, name in enumerate(names):
        values = curves[name]
        valid = np.isfinite(values).all(axis=1) & run.trusted
        extra[:3, k] = np.where(valid, values.T, 0.0)
        extra[3, k] = np.where(valid, 0.0, -1.0)
    _set_points(c3d, keep, names, extra, f"fccgrb {run.name}")
    for kind, (group, units, unit) in PIG_GROUPS.items():
        listed = [n for n in _point_texts(point, group) if n.strip() not in curves]
        c3d.add_parameter("POINT", group, listed + list(pig.kinds()[kind]))
        c3d.add_parameter("POINT", units, [unit])
    _mark_run(c3d, run)
    save(c3d, path)
    return len(labels) - len(keep)


def _needs_moments(run: Run, path: str | Path) -> Curves:
    moments = moment_curves(run)
    if moments is None:
        raise InputError(f"{path}: run {run.name!r} has no joint moments (solved without the "
                         "dynamics); expected a run solved with --dynamics")
    return moments


def _write_text(path: str | Path, text: str) -> None:
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


def export(run: Run, fmt: str, path: str | Path, trial: str | Path | None = None,
           convention: str = "fccgrb") -> int:
    """Write ``run`` to ``path`` in one of FORMATS and one of the CONVENTIONS its format
    takes; returns how many points of the trial a Plug-in Gait C3D replaced (else 0)."""
    if fmt not in FORMATS:
        raise InputError(f"--format: expected one of {', '.join(FORMATS)}, got {fmt!r}")
    if convention not in FORMAT_CONVENTIONS[fmt]:
        raise InputError(f"--convention: expected one of {', '.join(FORMAT_CONVENTIONS[fmt])} "
                         f"for --format {fmt}, got {convention!r}")
    if fmt == "c3d":
        if convention == "plugin-gait":
            return write_c3d_plugin_gait(run, path, trial)
        write_c3d(run, path, trial)
    elif convention == "opensim":
        write_mot_opensim(run, path)
    else:
        {"mot": write_mot, "sto": write_sto, "csv": write_csv}[fmt](run, path)
    return 0


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

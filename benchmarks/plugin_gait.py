"""Plug-in Gait compatibility against Vicon's own outputs: calibrate configs/models/plugin_gait.yaml
on each subject's static trial (measurements from its PROCESSING group, nothing typed), solve each
walking trial by mixed coordinates (NRM-WLS, the default), and compare every Plug-in Gait angle
the run computes with the one Vicon's Plug-in Gait stored in the same C3D file.

    python benchmarks/plugin_gait.py [--rigid-knees]        # the shared pair HC030A01/HC030A05
    python benchmarks/plugin_gait.py --trials DIR           # every subject of a folder
    python benchmarks/plugin_gait.py --session DIR --reference CSV   # a full-body session

``--session``: a folder with a static C3D (its PROCESSING says ``Static``, or its name says
static), the walking trial the ``--reference`` CSV was exported from (the CSV's name with
``.c3d``), and the subject's ``.vsk``; the CSV is Nexus's export of its model outputs (``Model
Outputs``, the rate, the ``Subject:Output`` names, components, units, then one row per frame
numbered as the C3D's frames). Printed: the angles (lower and upper body), moments and powers
of the run (calibrated with nothing typed but the ``.vsk``), and the angles of the direct
construction (the upper body's from the ``.vsk``'s arm and head measurements read here), each
as RMS per joint and component against the CSV.

A folder's trials are grouped by subject (the file name without its last two digits); a
subject's static trial is the one whose PROCESSING group says ``Static``, else its first.
Printed per walking trial: RMS differences (deg) of X, Y, Z over the frames the run trusts and
Vicon computed (``frames``: those compared, of the frames where Vicon wrote the side's hip
angles; in brackets the run's trusted frames of the file's), per side. Foot progression X and
Y are compared only where the foot points within 60° of the progression axis: their Cardan
sequence's middle angle is the foot progression itself (Z), and as the child turns at the end
of the walkway towards 90° X and Y become indeterminate — an orientation difference δ shows
in them as δ / cos Z (2δ at 60°, 11δ at 85°) — which Vicon's documentation acknowledges by
giving them no meaning; ``turning`` counts the frames left out, and the summary also gives the
worst over all frames. Two references explain the differences:

* ``direct``: the same Plug-in Gait definitions applied frame by frame to the markers with the
  file's own measurements (anatomy/plugin_gait.py, no solve): how far Vicon's processing of this
  file differs from its PROCESSING group's values (0 when they agree);
* ``frames``: how far the solved segments stay from those per-frame segments (RMS angle between
  their axes, deg, worst segment): the rigid model against Plug-in Gait's frame-by-frame
  construction, which follows the skin markers;
"""

from __future__ import annotations

import fccgrb_cli  # noqa: F401  (first: pins BLAS to one thread before numpy loads)
import argparse
import warnings
from pathlib import Path

import ezc3d
import numpy as np
import yaml

from fccgrb_cli.pipeline.calibration import Subject, calibrate_subject
from fccgrb_cli.plugin_gait import segments as pg
from fccgrb_cli.plugin_gait import upper
from fccgrb_cli.plugin_gait.calibration import side_geometry
from fccgrb_cli.api import calibrate
from fccgrb_cli.plugin_gait.angles import JOINTS, pig_angles, pig_axes, progression_frame
from fccgrb_cli.trial.forceplates import read_force_plates
from fccgrb_cli.trial.record import read_trial
from fccgrb_cli.model import load_model, parse_model
from fccgrb_cli.pipeline.options import SolveOptions
from fccgrb_cli.pipeline.solve import solve_trial

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared" / "data" / "c3d" / "plugin_gait"
TEMPLATE = ROOT / "configs" / "models" / "plugin_gait.yaml"
SEGMENTS = ("pelvis", "thigh_l", "shank_l", "foot_l", "thigh_r", "shank_r", "foot_r")


def vicon(path: Path) -> tuple[dict[str, np.ndarray], dict[str, float]]:
    """A Nexus file's points (frames × 3, NaN where Vicon wrote none) and PROCESSING values."""
    c3d = ezc3d.c3d(str(path))
    point = c3d["parameters"]["POINT"]
    labels = [s.strip() for key in ("LABELS", "LABELS2") if key in point
              for s in point[key]["value"]]
    xyz = c3d["data"]["points"][:3]
    residual = c3d["data"]["meta_points"]["residuals"][0]
    points = {}
    for k, label in enumerate(labels[: xyz.shape[1]]):
        values = xyz[:, k, :].T.copy()
        values[(residual[k] < 0) | np.all(values == 0, axis=1)] = np.nan
        points[label] = values
    processing = c3d["parameters"].get("PROCESSING", {})
    proc = {k: float(v["value"][0]) for k, v in processing.items()
            if isinstance(v, dict) and len(v.get("value", [])) and not isinstance(
                v["value"][0], str)}
    return points, proc


def pairs(folder: Path) -> list[tuple[Path, list[Path]]]:
    """(static, walking trials) per subject of a folder."""
    subjects: dict[str, list[Path]] = {}
    for path in sorted(folder.glob("*.c3d")):
        subjects.setdefault(path.stem[:-2], []).append(path)
    out = []
    for trials in subjects.values():
        statics = [t for t in trials if vicon(t)[1].get("Static", 0) == 1]
        static = statics[0] if statics else trials[0]
        out.append((static, [t for t in trials if t != static]))
    return out


GIMBAL_DEG = 60.0  # foot progression X and Y compared where |Z| (or |Z ± 180°|) is below this


def rms(ours: np.ndarray, theirs: np.ndarray, frames: np.ndarray) -> np.ndarray:
    """RMS (deg) per component over ``frames`` (frames, or frames × 3 per component), modulo
    whole turns (Vicon's angles run on past ±180°); NaN where no frame is compared."""
    frames = np.broadcast_to(frames[:, None] if frames.ndim == 1 else frames, ours.shape)
    error = np.where(frames, (ours - theirs + 180.0) % 360.0 - 180.0, np.nan)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return np.sqrt(np.nanmean(error ** 2, axis=0))


def conditioned(joint: str, theirs: np.ndarray) -> np.ndarray:
    """Per frame and component (frames × 3): whether the angle is defined well enough to
    compare — every component but foot progression X and Y where the foot turns more than
    ``GIMBAL_DEG`` from the progression axis (their Cardan sequence's gimbal lock at 90°)."""
    ok = np.ones(theirs.shape, dtype=bool)
    if joint == "FootProgress":
        facing = np.abs(np.cos(np.radians(theirs[:, 2]))) >= np.cos(np.radians(GIMBAL_DEG))
        ok[:, :2] = facing[:, None]
    return ok


def direct_angles(model, trial, up: np.ndarray) -> tuple[dict, dict]:
    """Plug-in Gait frame by frame from the markers with the model's measurements."""
    m = model.measurements
    offsets = {"l": (m.static_plantar_flexion.left, m.static_rotation_offset.left),
               "r": (m.static_plantar_flexion.right, -m.static_rotation_offset.right)}
    mark = {label: trial.markers[:, trial.labels.index(label)] for label in trial.labels}
    sacrum = mark["SACR"] if "SACR" in mark else 0.5 * (mark["LPSI"] + mark["RPSI"])
    lm = {"pelvis": (mark["RASI"], mark["LASI"], sacrum)}
    for s, p in (("l", "L"), ("r", "R")):
        lm[f"thigh_{s}"] = (mark[p + "THI"], mark[p + "KNE"])
        lm[f"shank_{s}"] = (mark[p + "TIB"], mark[p + "ANK"])
        lm[f"toe_{s}"] = mark[p + "TOE"]
    seg = pg.segments(lm, side_geometry(m, offsets))
    lab = progression_frame(seg["pelvis"].origin, seg["pelvis"].axes[:, :, 0], up)
    torsion = {"l": m.tibial_torsion.left, "r": m.tibial_torsion.right}
    return pig_angles({k: v.axes for k, v in seg.items()}, torsion, lab), seg


def rigid_knees(text: str) -> str:
    """The template with spherical knees instead of the sliding ones (its variant without the
    tibia's slide)."""
    doc = yaml.safe_load(text)
    for joint in doc["joints"]:
        if joint["type"] == "line":
            joint.update(type="spherical", bodies=joint["bodies"][::-1])
            del joint["axis"]
    del doc["distances"]
    return yaml.safe_dump(doc, sort_keys=False)


def evaluate(static: Path, walk: Path, rigid: bool = False) -> dict:
    template = load_model(TEMPLATE)
    if rigid:
        template = parse_model(rigid_knees(template.text), "plugin_gait.yaml (rigid knees)")
    model = calibrate(template, read_trial(static))
    trial = read_trial(walk)
    run = solve_trial(model, trial, SolveOptions(dynamics=False, events="none",
                                                 skip_unsolvable=True))
    points, _ = vicon(walk)
    up = -np.asarray(model.gravity) / np.linalg.norm(model.gravity)
    direct, seg = direct_angles(model, trial, up)
    out: dict = {"trial": walk.name, "trusted": int(run.trusted.sum()), "of": len(run.trusted)}
    for joint in JOINTS:
        for side in "LR":
            name = f"{side}{joint}Angles"
            theirs = points.get(name, np.full((len(run.trusted), 3), np.nan))
            written = np.isfinite(theirs).all(axis=1)
            frames = (run.trusted & written)[:, None] & conditioned(joint, theirs)
            for kind, source in (("solve", run.plugin_gait.angles), ("direct", direct)):
                out[(kind, joint, side)] = rms(source[name], theirs, frames)
            out[("all frames", joint, side)] = rms(run.plugin_gait.angles[name], theirs,
                                                   run.trusted & written)
            if joint == "Hip":
                out[("frames", side)] = (int((run.trusted & written).sum()), int(written.sum()))
            if joint == "FootProgress":
                out[("turning", side)] = int((frames[:, 2] & ~frames[:, 0]).sum())
    out["frames_deg"] = max(_axes_rms(run, model, seg, name) for name in SEGMENTS)
    out["tibia_mm"] = max(float(np.nanmax(length) - np.nanmin(length)) for length in (
        1e3 * np.linalg.norm(seg[f"shank_{s}"].origin - seg[f"foot_{s}"].origin, axis=1)
        for s in "lr"))
    return out


def _axes_rms(run, model, seg, name: str) -> float:
    """RMS over the trusted frames of the largest angle (deg) between a solved segment's axes
    and the per-frame Plug-in Gait segment's."""
    solved = np.stack([np.column_stack([run.q[f"{name}.{e}.{c}"] for c in "xyz"])
                       for e in "uvw"], axis=2)
    cosines = np.clip(np.einsum("fij,fij->fj", solved, seg[name].axes), -1, 1)
    angle = np.degrees(np.arccos(cosines)).max(axis=1)[run.trusted]
    return float(np.sqrt(np.nanmean(angle ** 2)))


def table(results: list[dict]) -> list[str]:
    head = ("| trial | side | frames | " + " | ".join(f"{j} X / Y / Z" for j in JOINTS)
            + " | turning | direct (worst) | solve vs PiG frames | tibia length range mm |")
    lines = [head, "|" + "---|" * (len(JOINTS) + 7)]
    for r in results:
        direct = np.nanmax([r[("direct", j, side)] for j in JOINTS for side in "LR"])
        for side in "LR":
            cells = [" / ".join(f"{v:.2f}" for v in r[("solve", j, side)]) for j in JOINTS]
            compared, written = r[("frames", side)]
            frames = f"{compared} of {written}" + (
                f" ({r['trusted']}/{r['of']})" if side == "L" else "")
            extra = (f"{direct:.2f} | {r['frames_deg']:.2f} | {r['tibia_mm']:.0f}"
                     if side == "L" else " | | ")
            lines.append(f"| {r['trial'] if side == 'L' else ''} | {side} | {frames} | "
                         + " | ".join(cells) + f" | {r[('turning', side)]} | {extra} |")
    return lines


def worst(r: dict, kind: str = "solve") -> tuple[float, float]:
    """A trial's worst RMS (deg): sagittal (X), and the others (Y, Z)."""
    rows = [r[(kind, j, s)] for j in JOINTS for s in "LR"]
    return (float(np.nanmax([v[0] for v in rows])), float(np.nanmax([v[1:] for v in rows])))


def summary(results: list[dict]) -> list[str]:
    """Per trial its worst X and worst Y/Z (when several), then the worst over the trials and
    how many meet the compatibility targets (RMS X ≤ 1°, Y and Z ≤ 2°)."""
    lines = []
    if len(results) > 1:
        lines += ["| trial | worst X | worst Y, Z | both targets |", "|---|---|---|---|"]
        for r in results:
            x, yz = worst(r)
            lines.append(f"| {r['trial']} | {x:.2f} | {yz:.2f} | "
                         f"{'yes' if x <= 1.0 and yz <= 2.0 else 'no'} |")
        lines.append("")
    x, yz = np.max([worst(r) for r in results], axis=0)
    meet = sum(1 for r in results if worst(r)[0] <= 1.0 and worst(r)[1] <= 2.0)
    fx, fyz = np.max([worst(r, "all frames") for r in results], axis=0)
    lines.append(f"worst: sagittal (X) {x:.2f} deg, others (Y, Z) {yz:.2f} deg over "
                 f"{len(results)} walking trials; {meet} of {len(results)} meet both targets "
                 f"(X ≤ 1, Y and Z ≤ 2 deg); with the turning frames' foot progression X and Y: "
                 f"{fx:.2f}, {fyz:.2f} deg")
    return lines


def reference_csv(path: Path) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """A Nexus model-outputs CSV: its frame numbers and each output (name without the subject
    prefix → frames × components, NaN where empty)."""
    lines = path.read_text().splitlines()
    names, rows = lines[2].split(","), [line.split(",") for line in lines[5:] if line.strip()]
    values = np.array([[float(v) if v.strip() else np.nan for v in row[:len(names)]]
                       + [np.nan] * (len(names) - len(row)) for row in rows])
    starts = [k for k, name in enumerate(names) if name.strip()]
    out = {}
    for k, start in enumerate(starts):
        stop = starts[k + 1] if k + 1 < len(starts) else len(names)
        out[names[start].split(":")[-1].strip()] = values[:, start:stop]
    return values[:, 0].astype(int), out


def vsk_values(path: Path) -> dict[str, float]:
    """A Vicon .vsk's static parameters (name → value as written) that have a value."""
    import xml.etree.ElementTree as ET

    return {e.get("NAME", ""): float(e.get("VALUE", "nan")) for e in
            ET.parse(path).iter("StaticParameter") if e.get("VALUE") is not None}


def upper_geometry(values: dict[str, float], marker_diameter: float) -> upper.UpperGeometry:
    """Plug-in Gait's upper-body measurements (mm, the head offset in rad) from a .vsk."""
    def sided(key: str) -> dict[str, float]:
        return {s: 1e-3 * values[f"{side}{key}"] for s, side in (("l", "Left"), ("r", "Right"))}

    return upper.UpperGeometry(marker_diameter / 2.0, values.get("HeadOffset", 0.0),
                               sided("ShoulderOffset"), sided("ElbowWidth"),
                               sided("WristWidth"), sided("HandThickness"))


def session(folder: Path, reference: Path) -> list[str]:
    """The held-out comparison of a full-body session (``--session``, ``--reference``)."""
    walk = folder / f"{reference.stem}.c3d"
    vsks = sorted(folder.glob("*.vsk"))
    statics = [p for p in sorted(folder.glob("*.c3d")) if p != walk and (
        vicon(p)[1].get("Static", 0) == 1 or "static" in p.stem.lower())]
    if not walk.exists() or not statics:
        raise SystemExit(f"{folder}: expected {walk.name} and a static trial beside it")
    files = (str(vsks[0]),) if vsks else ()
    model = calibrate_subject(load_model(TEMPLATE), read_trial(statics[0]),
                              Subject(files=files)).model
    trial = read_trial(walk)
    run = solve_trial(model, trial, SolveOptions(events="none", skip_unsolvable=True))
    frames, theirs = reference_csv(reference)
    first = round(trial.start * trial.rate) + 1
    index = frames - first
    up = -np.asarray(model.gravity) / np.linalg.norm(model.gravity)
    direct, seg = direct_angles(model, trial, up)

    def compared(ours: np.ndarray, name: str) -> np.ndarray:
        mine = np.full((len(index), 3), np.nan)
        ok = (index >= 0) & (index < len(ours))
        mine[ok] = ours[index[ok]]
        return mine, theirs.get(name, np.full((len(index), 3), np.nan))[:, :3]

    trusted = np.zeros(len(index), dtype=bool)
    trusted[(index >= 0) & (index < len(run.trusted))] = run.trusted[index[
        (index >= 0) & (index < len(run.trusted))]]
    lines = [f"{walk.name}: {len(index)} frames in the CSV, {int(trusted.sum())} trusted by the "
             f"run; static {statics[0].name}, subject {files[0] if files else 'none'}", "",
             "| output | side | kind | X | Y | Z |", "|---|---|---|---|---|---|"]

    def row(name: str, kind: str, ours: np.ndarray, frames_ok: np.ndarray,
            angle: bool = True) -> None:
        mine, ref = compared(ours, name)
        written = np.isfinite(ref).all(axis=1) & frames_ok
        if written.any():
            value = rms(mine, ref, written) if angle else np.sqrt(np.nanmean(
                (mine - ref)[written] ** 2, axis=0))
            lines.append(f"| {name[1:]} | {name[0]} | {kind} | "
                         + " | ".join(f"{v:.2f}" for v in value) + " |")

    pig = run.plugin_gait
    assert pig is not None  # a Plug-in Gait template's run
    for joint in JOINTS:
        for side in "LR":
            name = f"{side}{joint}Angles"
            row(name, "solve", pig.angles[name], trusted)
            row(name, "direct", direct[name], np.ones(len(index), dtype=bool))
    # Where the plates' vertical loads (N) equal the ground reactions Nexus applied (its
    # L/RGroundReactionForce, N/kg): Nexus leaves a plate out where it judges a foot not wholly
    # on it, and its files do not record that choice.
    plates = read_force_plates(walk, trial.n_frames)
    loaded = np.nansum([np.abs(p.force[:, 2]) for p in plates], axis=0)
    applied = sum(np.nan_to_num(np.abs(theirs.get(f"{side}GroundReactionForce", np.zeros(
        (len(index), 3)))[:, 2])) for side in "LR") * (model.subject_mass or np.nan)
    same, _ = compared(np.column_stack([loaded] * 3), "")
    same_load = np.abs(same[:, 2] - applied) < 20.0
    lines.insert(1, f"plates' vertical load equal to Nexus's applied ground reactions (20 N) "
                    f"on {int((same_load & trusted).sum())} of the trusted frames")
    for kind, curves in (("moments", pig.moments), ("powers", pig.powers)):
        for name, curve in curves.items():
            row(name, kind, curve, trusted, angle=False)
            row(name, f"{kind}, same plate loads", curve, trusted & same_load, angle=False)
    mark = {label: trial.markers[:, trial.labels.index(label)] for label in trial.labels}
    diameter = model.measurements.marker_diameter or 0.014
    values = vsk_values(vsks[0]) if vsks else {}
    axes, _ = upper.segments(mark, upper_geometry(values, diameter))
    lab = progression_frame(seg["pelvis"].origin, seg["pelvis"].axes[:, :, 0], up)
    direct_upper = upper.upper_angles({**axes, "pelvis": pig_axes(seg["pelvis"].axes)}, lab)
    for joint in upper.UPPER_JOINTS:
        for side in "LR":
            name = f"{side}{joint}Angles"
            if name in pig.angles:
                row(name, "solve", pig.angles[name], trusted)
            row(name, "direct", direct_upper[name], np.ones(len(index), dtype=bool))
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--trials", type=Path, default=None,
                        help="a folder of Nexus C3D files (default: the shared pair)")
    parser.add_argument("--rigid-knees", action="store_true",
                        help="also the template with spherical knees (no slide of the tibia)")
    parser.add_argument("--session", type=Path, default=None,
                        help="a full-body session's folder (static, walk, .vsk)")
    parser.add_argument("--reference", type=Path, default=None,
                        help="with --session: Nexus's model outputs CSV of its walk")
    args = parser.parse_args()
    if args.session or args.reference:
        if not (args.session and args.reference):
            parser.error("--session and --reference go together")
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            print("RMS difference to Vicon's Plug-in Gait outputs (deg; moments N.mm/kg; "
                  "powers W/kg):")
            print("\n".join(session(args.session, args.reference)))
        return
    todo = pairs(args.trials) if args.trials else [(SHARED / "HC030A01.c3d",
                                                     [SHARED / "HC030A05.c3d"])]
    for rigid in (False, True) if args.rigid_knees else (False,):
        results = []
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            for static, walks in todo:
                for walk in walks:
                    results.append(evaluate(static, walk, rigid))
        print("RMS difference to Vicon's Plug-in Gait angles (deg), X / Y / Z"
              + (", spherical knees (no slide):" if rigid else ":"))
        print("\n".join(table(results)))
        print("\n".join(summary(results)) + "\n")


if __name__ == "__main__":
    main()

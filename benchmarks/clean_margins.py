"""How far clean trials stay from each check's threshold (README, "What fccgrb checks for you"):
each check's own measure on trials nothing is wrong with, beside the threshold that flags a
frame, and on the broken cases the checks exist for.

    python benchmarks/clean_margins.py [--heldout FOLDER]

Clean: the Qualisys walking trial (calibrated from itself; 6 Hz, and with --smooth auto),
the Plug-in Gait child's walking trial (Helen Hayes model calibrated from the child's static,
6 Hz), the five-bar at 30 mm (NRM-WLS and CNO-SQP), the crank-rocker at 10 mm. Broken: the
Qualisys trial neither filtered nor smoothed (noise), the uncalibrated
template on it, the parallelogram through its change points. With
``--heldout`` every Plug-in Gait subject of another collection in that folder (files
``<subject>A01.c3d`` static, the others walking) is run too, one line each: they are not part
of the project and are never copied into it. Shared files absent: those rows are left out.
"""

from __future__ import annotations

import fccgrb_cli  # noqa: F401  (first: pins BLAS to one thread before numpy loads)
import argparse
import warnings
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

import fccgrb_cli as fc
from fccgrb_cli.anatomy.calibrate import Calibration, Measurements, calibrate
from fccgrb_cli.trial.record import Trial
from fccgrb_cli.model import parse_model
from fccgrb_cli.anatomy.plausibility import ASYMMETRY, FOOT_M, KNEE_FLEXION_DEG, SEGMENT_M
from fccgrb_cli.anatomy.plausibility import TWIST_DEG
from fccgrb_cli.signals.butterworth import noise_share
from fccgrb_cli.solvers import quality
from fccgrb_cli.solvers.conditioning import SINGULAR_RATIO, conditioning

ROOT = Path(__file__).resolve().parents[1]
MODELS = ROOT / "configs" / "models"
C3D = ROOT.parent / "shared" / "data" / "c3d"
PIG_MAP = (("sacrum", "SACR"), ("r asis", "RASI"), ("l asis", "LASI"), ("r bar 1", "RTHI"),
           ("r knee 1", "RKNE"), ("r bar 2", "RTIB"), ("r mall", "RANK"), ("r heel", "RHEE"),
           ("r met", "RTOE"), ("l bar 1", "LTHI"), ("l knee 1", "LKNE"), ("l bar 2", "LTIB"),
           ("l mall", "LANK"), ("l heel", "LHEE"), ("l met", "LTOE"))
COLUMNS = ("mean fit mm", "marker mm", "jump ratio", "range use", "min |sin θ|", "σ ratio",
           "noise", "flagged", "moments out")
LIMITS = (f"≤ {quality.FIT_MEAN_MM:g}", f"≤ {quality.FIT_MARKER_MM:g}",
          f"≤ {quality.JUMP_RATIO:g}", "≤ 1", f"≥ {np.sin(np.radians(quality.FLAT_DEG)):.3f}",
          f"≥ {SINGULAR_RATIO:g}", f"≤ {quality.NOISE_SHARE:g}", "frames", "frames")


def measures(run: fc.Run) -> list[float]:
    """Each check's measure over the run's solved frames: the largest per-frame mean and single
    marker distance (mm), jump ratio, the largest share of a clinical range used (1: at its
    edge; a measure about the range's middle), the smallest |sin θ| of a paper-style angle, the
    smallest σ_min/σ_max of the classical model over its well-conditioned value, the noise
    share of the angular accelerations, the frames flagged, and the trusted frames with an
    untrusted moment."""
    r = run.result
    solved = r.converged
    fit = 1e3 * run.ed_input[solved]
    model = run.model
    use = np.nan
    clinical = [k for k, a in enumerate(model.angles) if a.clinical_range is not None]
    if clinical:
        spans = []
        for k in clinical:
            low, high = model.angles[k].clinical_range
            values = model.angles[k].clinical(r.theta[solved, k])
            spans.append(np.nanmax(np.abs(values - (low + high) / 2) / ((high - low) / 2)))
        use = float(max(spans))
    half = np.array([a.kind == "angle" and not a.full for a in model.angles], dtype=bool)
    sine = float(np.nanmin(np.abs(np.sin(r.theta[solved][:, half])))) if half.any() else np.nan
    ratio, noise = np.nan, np.nan
    if run.dynamics is not None:
        condition = conditioning(model, run.dynamics.kinematics.q)
        ratio = float(np.nanmin(condition.ratio) / condition.reference)
        share = noise_share(run.dynamics.kinematics.theta, run.rate)
        noise = float(np.nanmedian(share)) if np.isfinite(share).any() else np.nan
    jump = quality.jump_ratio(run.model_points, run.markers_input)
    moments = run.moments_trusted
    out = 0 if moments is None else int((run.trusted & ~moments.all(axis=1)).sum())
    return [float(np.nanmax(np.nanmean(fit, axis=1))), float(np.nanmax(fit)),
            float(np.nanmax(jump[solved])) if r.method != "ad" else np.nan, use, sine, ratio,
            noise, int((~run.trusted).sum()), out]


def synth(model: Path, trial: Path) -> None:
    """``fccgrb synth MODEL -o TRIAL``."""
    subprocess.run([sys.executable, "-c", "from fccgrb_cli.cli.main import main; main()", "synth",
                    str(model), "-o", str(trial)], check=True, capture_output=True)


def row(name: str, values: list) -> str:
    cells = [("–" if np.isnan(v) else f"{v:.3g}") if isinstance(v, float) else str(v)
             for v in values]
    return f"{name:<36}" + "".join(f"{c:>12}" for c in cells)


def pig_calibration(static: Path, trial: fc.Trial | None = None) -> Calibration:
    """The Helen Hayes template calibrated from a Plug-in Gait static (or ``trial``, a copy of
    it) with the subject's measurements from its PROCESSING group."""
    import ezc3d

    p = ezc3d.c3d(str(static))["parameters"]["PROCESSING"]

    def value(key: str) -> float:
        return float(p[key]["value"][0])

    return calibrate(fc.load_model(MODELS / "helen_hayes.yaml"), trial or fc.read_trial(static),
                     mass=value("Bodymass"), mapping=dict(PIG_MAP),
                     measurements=Measurements.from_mm(
                         (value("LKneeWidth") + value("RKneeWidth")) / 2,
                         (value("LAnkleWidth") + value("RAnkleWidth")) / 2,
                         value("MarkerDiameter")))


def calibration_line(name: str, result: Calibration) -> str:
    """The calibration's largest twists and knee flexion and its warnings."""
    pose = result.pose or {}
    twist = max(abs(v) for k, v in pose.items() if "twist" in k)
    knee = [pose[f"knee_flexion_{s}"] for s in "rl"]
    lengths = ", ".join(f"{1e3 * v:.0f}" for v in result.lengths.values())
    return (f"{name:<36}largest twist {twist:.0f}°, knee flexion {min(knee):.0f}…"
            f"{max(knee):.0f}°, segments {lengths} mm; {len(result.warnings)} warnings")


def wrong_face(trial: fc.Trial, wand: str, knee: str, ankle: str) -> fc.Trial:
    """The wand turned half a turn about the line from the knee marker to the ankle marker."""
    markers = trial.markers.copy()
    labels = list(trial.labels)
    a, b = markers[:, labels.index(knee)], markers[:, labels.index(ankle)]
    axis = (b - a) / np.linalg.norm(b - a, axis=1, keepdims=True)
    k = labels.index(wand)
    rel = markers[:, k] - a
    markers[:, k] = a + 2 * np.sum(rel * axis, axis=1, keepdims=True) * axis - rel
    return Trial(trial.path, trial.labels, markers, trial.rate)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--heldout", type=Path, default=None)
    args = parser.parse_args()
    warnings.simplefilter("ignore", RuntimeWarning)  # numpy's on empty analog slices
    print(row("case", list(COLUMNS)))
    print(row("threshold (flagged beyond)", list(LIMITS)))
    with tempfile.TemporaryDirectory() as folder:
        for model_name, level, methods in (("five_bar", 30, ("nrm-wls", "cno-sqp")),
                                           ("crank_rocker", 10, ("nrm-wls",))):
            if model_name == "five_bar":
                trial = ROOT / "sample_data" / "five_bar.c3d"
            else:
                trial = Path(folder) / f"{model_name}.c3d"
                synth(MODELS / f"{model_name}.yaml", trial)
            for method in methods:
                run = fc.solve(fc.load_model(MODELS / f"{model_name}.yaml"),
                               fc.read_trial(trial), method=method, perturb_mm=level)
                allowance = np.sqrt(3.0) * level
                print(row(f"{model_name} P{level} {method} (fit +{allowance:.0f})",
                          measures(run)))
        qualisys = C3D / "Qualisys.c3d"
        if qualisys.exists():
            trial = fc.read_trial(qualisys)
            personal = fc.calibrate(fc.load_model(MODELS / "lower_limb.yaml"), trial,
                                    mass=67.0)
            print(row("Qualisys nrm-wls 6 Hz", measures(
                fc.solve(personal, trial, method="nrm-wls", filter_cutoff=6.0))))
            print(row("Qualisys cno-sqp 6 Hz", measures(
                fc.solve(personal, trial, method="cno-sqp", filter_cutoff=6.0))))
            print(row("Qualisys nrm-wls smoothed", measures(
                fc.solve(personal, trial, method="nrm-wls", smooth="auto"))))
            print(row("broken: Qualisys unfiltered", measures(
                fc.solve(personal, trial, method="nrm-wls", smooth="none"))))
            print(row("broken: template on Qualisys", measures(
                fc.solve(fc.load_model(MODELS / "lower_limb.yaml"), trial, method="nrm-wls",
                         dynamics=False))))
        static, walk = C3D / "plugin_gait" / "HC030A01.c3d", C3D / "plugin_gait" / "HC030A05.c3d"
        if walk.exists():
            child = pig_calibration(static)
            print(row("PiG HC030A05 nrm-wls 6 Hz", measures(
                fc.solve(parse_model(child.text, str(static)), fc.read_trial(walk),
                         method="nrm-wls", filter_cutoff=6.0, mapping=PIG_MAP))))
        trial = Path(folder) / "parallelogram.c3d"
        synth(MODELS / "parallelogram.yaml", trial)
        print(row("broken: parallelogram P0 nrm-wls", measures(
            fc.solve(fc.load_model(MODELS / "parallelogram.yaml"), fc.read_trial(trial),
                     method="nrm-wls"))))
    if qualisys.exists():
        print(calibration_line("Qualisys (its walking frames)", calibrate(
            fc.load_model(MODELS / "lower_limb.yaml"), fc.read_trial(qualisys), mass=67.0)))
    standing = C3D / "FP_Type1.c3d"
    if standing.exists():
        print(calibration_line("FP_Type1 static (Helen Hayes)", calibrate(
            fc.load_model(MODELS / "helen_hayes.yaml"), fc.read_trial(standing), mass=70.0)))
    if walk.exists():
        print(calibration_line("PiG HC030A01 static", child))
        broken = pig_calibration(static, wrong_face(fc.read_trial(static), "RTIB", "RKNE",
                                                    "RANK"))
        print(calibration_line("broken: HC030A01, RTIB wrong face", broken))
    print(f"calibration thresholds: twist ±{TWIST_DEG:g}°, knee flexion {KNEE_FLEXION_DEG}°, "
          f"segments {SEGMENT_M} m, feet {FOOT_M} m, left/right {100 * ASYMMETRY:g} %")
    if args.heldout is not None:
        heldout(args.heldout)
    return 0


def heldout(folder: Path) -> None:
    """Every subject of a Plug-in Gait collection: static <subject>A01/D02, the rest walking."""
    files = sorted(folder.glob("*.c3d"))
    subjects: dict[str, list[Path]] = {}
    for f in files:
        subjects.setdefault(f.name[:5], []).append(f)
    for _, trials in subjects.items():
        static, *walks = trials
        result = pig_calibration(static)
        model = parse_model(result.text, str(static))
        print(calibration_line(static.name, result))
        for walk in walks:
            run = fc.solve(model, fc.read_trial(walk), method="nrm-wls", filter_cutoff=6.0,
                           mapping=PIG_MAP, skip_unsolvable=True)
            print(row(walk.name, measures(run)))


if __name__ == "__main__":
    raise SystemExit(main())

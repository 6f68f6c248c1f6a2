"""A long trial end to end: calibrate the lower-limb template on Qualisys.c3d (200 Hz, 340
frames), tile one stride of it into a 10-minute walk (120,000 frames by default), write that as a
C3D, and time ``fccgrb solve <personal model> <long.c3d> --method nrm-wls`` under
``/usr/bin/time -v``: wall time, ms/frame, peak resident memory and the results file's size.

    nice python benchmarks/long_trial.py [--frames 120000] [--keep DIR] [-- extra solve options]

The tiles are continuous: the tile is the stretch of frames [i, j) whose last posture best matches
its first one a stride later (the markers at j, less the horizontal distance the pelvis travelled
from i to j, closest to the markers at i, with j - i at least 0.6 s), and each tile is the same
stretch translated forward by that distance, so the subject walks on without jumping back (the
largest marker step at a seam is printed beside the trial's own largest step). Markers only: the
force plates stay where the lab put them while the tiled walker moves on, so their analogs would
load thin air (a plate per tile would mean thousands of channels at 2 kHz); the dynamics stage
runs without ground reactions, which costs the same. Nothing is written to the repository: the
trial, the personal model and the results go to a temporary folder (``--keep DIR`` keeps them).
Speed and memory goals live here, never in tests.
"""

from __future__ import annotations

import fccgrb_cli  # noqa: F401  (first: pins BLAS to one thread before numpy loads)
import argparse
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from fccgrb_cli.anatomy.calibrate import calibrate
from fccgrb_cli.trial.c3d import save
from fccgrb_cli.trial.record import Trial, read_trial
from fccgrb_cli.model import load_model

ROOT = Path(__file__).resolve().parents[1]
TRIAL = ROOT.parent / "shared" / "data" / "c3d" / "Qualisys.c3d"
PELVIS = ("L_IAS", "L_IPS", "R_IPS", "R_IAS")
FCCGRB = Path(sys.executable).with_name("fccgrb")  # the command beside this interpreter
UP = 2  # the lab's vertical axis (z in Qualisys.c3d)


def stride(trial: Trial, min_seconds: float = 0.6) -> tuple[int, int, np.ndarray]:
    """The frames [i, j) that tile best, and the pelvis's horizontal travel from i to j (m):
    the pair minimizing the mean marker distance between frame j and frame i moved by it."""
    m = trial.markers
    pelvis = m[:, [trial.labels.index(label) for label in PELVIS]].mean(axis=1)
    best = (np.inf, 0, 0)
    for i in range(trial.n_frames):
        for j in range(i + int(min_seconds * trial.rate), trial.n_frames):
            shift = pelvis[j] - pelvis[i]
            shift[UP] = 0.0
            mismatch = float(np.nanmean(np.linalg.norm(m[j] - m[i] - shift, axis=1)))
            if mismatch < best[0]:
                best = (mismatch, i, j)
    _, i, j = best
    shift = pelvis[j] - pelvis[i]
    shift[UP] = 0.0
    return i, j, shift


def tiled(trial: Trial, frames: int) -> tuple[np.ndarray, float, float]:
    """``frames`` frames of the tiled walk (frames × markers × 3, m), the largest marker step
    at a seam and the largest step inside the trial (m)."""
    i, j, shift = stride(trial)
    tile = trial.markers[i:j]
    count = -(-frames // len(tile))
    walk = tile[None] + (np.arange(count)[:, None, None, None] * shift)
    walk = walk.reshape(-1, *tile.shape[1:])[:frames]
    seam = float(np.nanmax(np.linalg.norm(tile[0] + shift - tile[-1], axis=1)))
    inside = float(np.nanmax(np.linalg.norm(np.diff(trial.markers, axis=0), axis=2)))
    print(f"tile: frames {i}:{j} of {trial.path} ({(j - i) / trial.rate:.2f} s), "
          f"{1e3 * np.linalg.norm(shift):.0f} mm forward each; largest step at a seam "
          f"{1e3 * seam:.1f} mm, inside the trial {1e3 * inside:.1f} mm")
    return walk, seam, inside


def write_walk(path: Path, labels: tuple[str, ...], markers: np.ndarray, rate: float) -> None:
    """The markers (frames × markers × 3, m) as C3D points in mm, with the frame range in
    TRIAL:ACTUAL_START_FIELD/ACTUAL_END_FIELD (two 16-bit words each, low first), where
    POINT:FRAMES (one word) stops at 65535 (see fccgrb_cli/trial/c3d_header.py)."""
    import ezc3d

    c3d = ezc3d.c3d()
    point = c3d["parameters"]["POINT"]
    point["RATE"]["value"], point["LABELS"]["value"] = [float(rate)], list(labels)
    point["UNITS"]["value"] = ["mm"]
    points = np.ones((4, markers.shape[1], len(markers)))
    points[:3] = np.transpose(markers * 1e3, (2, 1, 0))
    c3d["data"]["points"] = points
    last = len(markers)
    c3d.add_parameter("TRIAL", "ACTUAL_START_FIELD", [1, 0])
    c3d.add_parameter("TRIAL", "ACTUAL_END_FIELD", [last & 0xFFFF, last >> 16])
    save(c3d, path)


def time_report(text: str) -> dict[str, str]:
    """GNU time -v's 'key: value' lines."""
    return dict(m.groups() for m in re.finditer(r"^\s*(.+?): (.*)$", text, re.MULTILINE))


def seconds(clock: str) -> float:
    """'h:mm:ss' or 'm:ss.ss' in seconds."""
    total = 0.0
    for part in clock.split(":"):
        total = 60 * total + float(part)
    return total


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=120_000)
    parser.add_argument("--trial", type=Path, default=TRIAL)
    parser.add_argument("--method", default="nrm-wls")
    parser.add_argument("--keep", type=Path, help="write the files here and keep them")
    parser.add_argument("extra", nargs="*", help="further options for fccgrb solve (after --)")
    args = parser.parse_args()
    if not args.trial.exists():
        raise SystemExit(f"{args.trial}: not found (the shared data folder is not here)")
    if not Path("/usr/bin/time").exists():
        raise SystemExit("/usr/bin/time: not found (GNU time measures the peak memory)")
    trial = read_trial(args.trial)
    folder = Path(tempfile.mkdtemp(prefix="fccgrb-long-")) if args.keep is None else args.keep
    folder.mkdir(parents=True, exist_ok=True)
    try:
        personal = folder / "personal.yaml"
        template = load_model(ROOT / "configs" / "models" / "lower_limb.yaml")
        personal.write_text(calibrate(template, trial, mass=67.0).text, encoding="utf-8")
        walk, _, _ = tiled(trial, args.frames)
        long_c3d = folder / "long.c3d"
        write_walk(long_c3d, trial.labels, walk, trial.rate)
        del walk
        results, report = folder / "long.h5", folder / "time.txt"
        # run in the folder with its files' own names, so that what it prints is the same
        # from run to run (docs/generate.py compares it)
        command = ["/usr/bin/time", "-v", "-o", str(report), str(FCCGRB), "solve",
                   personal.name, long_c3d.name, "--method", args.method, "-o", results.name,
                   *args.extra]
        print(f"{args.frames} frames ({args.frames / trial.rate / 60:.1f} min at "
              f"{trial.rate:g} Hz), C3D {long_c3d.stat().st_size / 2**20:.0f} MiB; "
              f"running: fccgrb solve {' '.join(command[6:])}", flush=True)
        done = subprocess.run(command, stdout=subprocess.PIPE, text=True, check=False,
                              cwd=folder)
        lines = done.stdout.rstrip().splitlines()
        print("\n".join([*lines[:2], "…", lines[-1]] if len(lines) > 3 else lines))
        measured = time_report(report.read_text(encoding="utf-8"))
        if done.returncode != 0:
            raise SystemExit(f"fccgrb solve exited with status {done.returncode}")
        wall = seconds(measured["Elapsed (wall clock) time (h:mm:ss or m:ss)"])
        peak_mib = int(measured["Maximum resident set size (kbytes)"]) / 1024
        print(f"{'frames':>8} {'wall s':>8} {'ms/frame':>9} {'peak RSS MiB':>13} "
              f"{'HDF5 MiB':>9}")
        print(f"{args.frames:8d} {wall:8.1f} {1e3 * wall / args.frames:9.3f} {peak_mib:13.0f} "
              f"{results.stat().st_size / 2**20:9.1f}")
    finally:
        if args.keep is None:
            shutil.rmtree(folder, ignore_errors=True)


if __name__ == "__main__":
    main()

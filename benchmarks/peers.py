"""fccgrb against OpenSim's inverse kinematics on the same five-bar and the same markers, and on
the gait example's lower limb and walking trial, in one run.

    python benchmarks/peers.py [--frames 300] [--repeat 3] [--no-gait] [--no-cli]

Gait: the lower-limb template calibrated on ../shared/data/c3d/Qualisys.c3d (as
benchmarks/gait.py does: 340 frames at 200 Hz, 28 markers, skipped without the shared data),
built in OpenSim the same way, its floating pelvis on a ``FreeJoint`` at its YAML pose, each
joint turning about each body's own axis (the calibrated pose satisfies the joints only
approximately). OpenSim's IK and CNO-SQP reach the same optimum there too (tests/test_peers.py).

The default command line: after the in-process table, each trial again through ``fccgrb solve
MODEL TRIAL --method M -o out.h5`` in a fresh process (every other option at its default: the
auto engine, each frame's own solution and its rates (``--smooth none``), the inverse dynamics,
the results file; the five-bar's
trial written by ``fccgrb synth`` and perturbed with ``--perturb``): ms/frame from the solve's
own summary (the per-frame position solve, which leaves the process's start-up, the kernels'
load and the later stages out), beside the whole process's wall time and the kernels' load the
command reports apart; 'OpenSim/this' against the in-process OpenSim row of the same trial.

The five-bar's YAML (configs/models/five_bar.yaml) is built a second time in OpenSim 4.6
(``pip install '.[peers]'``): one ``opensim.Body`` per body (the YAML's mass, centre of mass and
inertia tensor, the body frame being fccgrb's (r; u, v, w)), a ``PinJoint`` per revolute,
``UniversalJoint`` per universal and ``BallJoint`` per spherical joint at the YAML's joint points
and axes, a marker at every tracked point, the YAML's gravity. Its joint frames are chosen so
that, with every OpenSim coordinate at zero, each body sits at its YAML ``pose``: the two models
span the same configuration space from the same neutral pose (tests/test_peers.py checks the
frames against the YAML's axes, and that at P0 OpenSim reproduces the prescribed angles).

Markers: fccgrb's synthesized trial (300 frames at 100 Hz, the prescribed motion of the YAML's
``angles``, docs/formulation.md §7) perturbed at P0, P7.5 and P30 (docs/formulation.md §5, seed 0);
every solver gets exactly these arrays. Solvers:

- fccgrb NRM-WLS (docs/formulation.md §3, tracking weight 1e-3, tolerance 1e-10 on ‖Δq‖∞);
- fccgrb CNO-SQP with the TC objective (docs/formulation.md §3, Eq. 29–36 as the objective, the
  topological equations exact): min Σ ‖r_P(q) − r*_P‖² subject to Φ_top(q) = 0;
- OpenSim's ``InverseKinematicsSolver``, every marker weight 1 and the constraint weight
  infinite (the five-bar is an open chain: OpenSim's coordinates satisfy its joints by
  construction): min Σ ‖r_P(q) − r*_P‖² over the nine joint coordinates — the same problem as
  CNO-SQP, so both must reach the same optimum. Accuracy 1e-10 (the comparison) and OpenSim's
  default 1e-5 (what its users get unless they change it).

Timings (``time.perf_counter``; best of ``--repeat`` runs, the run with the smallest ms/frame;
the answers of every repeat are identical). Before any timing, one untimed solve of each fccgrb
method on the P0 markers: one-time start-up (numba loading its cached kernels) is left out.
fccgrb runs on its compiled engine (``engine="compiled"``, what 'auto' takes for these models):

- fccgrb ms/frame: the mean of the solver's own per-frame times (``KinematicResult.time_s``):
  one frame's warm-start prediction (frame 0: the initial guess from the markers) and iterations
  to convergence. fccgrb 'call' ms/frame: the wall time of the whole ``solve_nrm`` /
  ``solve_optimization`` call over the frames, divided by the frames: adds frame 0's set-up, the
  consistent velocities and accelerations (which OpenSim's IK does not compute) and the
  bookkeeping. Neither includes loading the YAML or ``compile_system``.
- OpenSim ms/frame: per frame, the wall time of ``state.setTime(t); solver.track(state)``
  (frame 0: ``state.setTime(t0); solver.assemble(state)`` from the default pose), as its users
  run it; the read-out of the poses and marker errors after each frame is excluded. OpenSim
  'call' ms/frame: building the ``MarkersReference`` from the in-memory marker table, the
  ``InverseKinematicsSolver``, a fresh state, then the per-frame loop, divided by the frames.
  Neither includes building the OpenSim model or the marker table (what writing a .trc file
  would be).

Columns: 'OpenSim/this': OpenSim's ms/frame at accuracy 1e-10 over the row's ms/frame; 'fit mm':
the mean over frames and markers of the distance from each model point (from the solved body
poses and the YAML's local point coordinates) to its marker; 'max|Δθ| deg': the largest
difference, over frames and angles, of the YAML's angles (acos(s1·s2), the definition of
fccgrb's mixed coordinates, Eq. 10) computed from the solved body poses, against OpenSim's at
accuracy 1e-10. iterations/frame are not available from OpenSim's Python API ('-').
biorbd (conda only) is detected and skipped when it is not importable.
"""

from __future__ import annotations

import fccgrb_cli  # noqa: F401  (first: pins BLAS to one thread before numpy loads)
import argparse
import importlib
import importlib.util
import re
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np

from fccgrb_cli.anatomy.calibrate import calibrate
from fccgrb_cli.trial.labels import match_labels
from fccgrb_cli.trial.record import read_trial
from fccgrb_cli.model import GROUND, Model, load_model, parse_model
from fccgrb_cli.signals.artefact import perturb
from fccgrb_cli.solvers.nrm.solve import NrmSettings, solve_nrm
from fccgrb_cli.solvers.optimize.solve import Settings, solve_optimization
from fccgrb_cli.pipeline.synth import Synthesis, synthesize
from fccgrb_cli.system import System, compile_system

ROOT = Path(__file__).resolve().parents[1]
LEVELS_MM = (0.0, 7.5, 30.0)
ACCURACIES = (1e-10, 1e-5)
REFERENCE_ACCURACY = 1e-10
GAIT_TEMPLATE = ROOT / "configs" / "models" / "lower_limb.yaml"
GAIT_TRIAL = ROOT.parent / "shared" / "data" / "c3d" / "Qualisys.c3d"
METHODS = ("nrm-wls", "cno-sqp")


@dataclass(frozen=True)
class Solved:
    """One solver's answer on one marker set: body poses per frame (frames × bodies × 4 × 3,
    the rows r, u, v, w of each body in the global frame, bodies in the model's order), the
    per-frame solve seconds, the whole call's seconds and iterations per frame (NaN when the
    solver does not report them)."""

    label: str
    poses: np.ndarray
    seconds: np.ndarray
    call_s: float
    iterations: float


# --- configurations compared through body poses ------------------------------------------------
def poses_from_q(system: System, q: np.ndarray) -> np.ndarray:
    """fccgrb's body poses (… × bodies × 4 × 3) from system coordinates q (… × nq): each body's
    r, u, v, w (docs/formulation.md §1; a reduced body's w = u × v, Eq. 5)."""
    q = np.asarray(q)
    x = np.array([system.layout.expand(row) for row in q.reshape(-1, q.shape[-1])])
    return x.reshape(*q.shape[:-1], len(system.layout.body_names), 4, 3)


def _frame_rows(model: Model, body: str, poses: np.ndarray) -> np.ndarray:
    """The rows r, u, v, w (… × 4 × 3) of a body, or of the ground (origin, x, y, z)."""
    if body == GROUND:
        return np.broadcast_to(np.vstack([np.zeros(3), np.eye(3)]), (*poses.shape[:-3], 4, 3))
    return poses[..., [b.name for b in model.bodies].index(body), :, :]


def angles_from_poses(model: Model, poses: np.ndarray) -> np.ndarray:
    """The model's angles (… × n_angles, rad) from body poses (… × bodies × 4 × 3) the way
    fccgrb defines its mixed coordinates (Eq. 10, docs/formulation.md §2 MCR): θ_k = acos(s1·s2)
    with s = α u + β v + γ w the YAML's body vectors. Only unsigned angles (the five-bar's)."""
    out = []
    for angle in model.angles:
        if angle.kind != "angle" or angle.full:
            raise ValueError(f"angle {angle.name}: only unsigned angles (acos(s1·s2)) are "
                             "compared with peers")
        s = []
        for body, vector in ((angle.body1, angle.vector1), (angle.body2, angle.vector2)):
            local = np.array((model.ground if body == GROUND else model.body(body))
                             .vectors[vector].local)
            s.append(np.einsum("l,...lj->...j", local, _frame_rows(model, body, poses)[..., 1:, :]))
        out.append(np.arccos(np.clip(np.einsum("...j,...j->...", s[0], s[1]), -1.0, 1.0)))
    return np.stack(out, axis=-1)


def points_from_poses(model: Model, poses: np.ndarray) -> np.ndarray:
    """The tracked points (… × n_tracked × 3, m) from body poses: r + a u + b v + c w (Eq. 2),
    in the order of the model's ``tracking.points``."""
    out = []
    for tp in model.tracked_points:
        rows = _frame_rows(model, tp.body, poses)
        a, b, c = model.body(tp.body).points[tp.point].local
        out.append(rows[..., 0, :] + a * rows[..., 1, :] + b * rows[..., 2, :]
                   + c * rows[..., 3, :])
    return np.stack(out, axis=-2)


def marker_fit(model: Model, poses: np.ndarray, markers: np.ndarray) -> np.ndarray:
    """Per frame, the mean distance (m) from each tracked model point to its marker (over the
    markers the frame has)."""
    return np.nanmean(np.linalg.norm(points_from_poses(model, poses) - markers, axis=-1),
                      axis=-1)


# --- fccgrb --------------------------------------------------------------------------------------
def run_fccgrb(method: str, system: System, time_s: np.ndarray, markers: np.ndarray) -> Solved:
    """fccgrb's NRM-WLS (weight 1e-3) or CNO-SQP (TC objective), tolerance 1e-10, through its
    public solver functions."""
    started = time.perf_counter()
    if method == "nrm-wls":
        result = solve_nrm(system, time_s, markers, NrmSettings(1e-3, 1e-10, engine="compiled"))
    elif method == "cno-sqp":
        result = solve_optimization(system, time_s, markers,
                                    Settings("cno-sqp", "tc", engine="compiled"))
    else:
        raise ValueError(f"method {method!r}: expected nrm-wls or cno-sqp")
    call = time.perf_counter() - started
    if not result.converged.all():
        raise RuntimeError(f"fccgrb {method}: frames {result.failed_frames.tolist()} failed")
    return Solved(f"fccgrb {method}", poses_from_q(system, result.q), result.time_s, call,
                  float(result.iterations.mean()))


# --- OpenSim -------------------------------------------------------------------------------------
def load_opensim() -> ModuleType | None:
    """The ``opensim`` module, or None when it cannot be imported."""
    try:
        return importlib.import_module("opensim")
    except ImportError:
        return None


def _euler_xyz(osim: ModuleType, R: np.ndarray) -> Any:
    """OpenSim's frame orientation (body-fixed X-Y-Z angles) of the rotation matrix R, by
    Simbody's own conversion (right at gimbal lock too, where the five-bar's universal joint
    frames sit: their X is the global z)."""
    return osim.Rotation(osim.Mat33(*map(float, R.ravel()))).convertRotationToBodyFixedXYZ()


def _rotation(model: Model, body: str) -> np.ndarray:
    """The body's orientation [u v w] (columns) at its YAML pose (the ground's: identity)."""
    if body == GROUND:
        return np.eye(3)
    pose = model.body(body).pose
    return np.column_stack([pose.u, pose.v, pose.w])


def _local(model: Model, body: str, table: str, name: str) -> np.ndarray:
    owner = model.ground if body == GROUND else model.body(body)
    return np.array(getattr(owner, table)[name].local, dtype=float)


def _joint_frame(model: Model, joint: Any) -> np.ndarray:
    """The joint frame's orientation in the global frame at the YAML pose: a revolute's axis
    along Z (OpenSim's PinJoint turns about Z); a universal's arms s_i, s_j along X and Y
    (OpenSim's UniversalJoint turns about the parent's X, then the child's Y: exactly the
    orientations that keep s_i ⟂ s_j); a spherical joint's: the identity."""
    if joint.type == "spherical":
        return np.eye(3)
    bi, bj = joint.bodies
    s_i = _rotation(model, bi) @ _local(model, bi, "vectors", joint.axes[0])
    if joint.type == "revolute":
        helper = np.eye(3)[np.argmin(np.abs(s_i))]
        x = np.cross(helper, s_i)
        x /= np.linalg.norm(x)
        return np.column_stack([x, np.cross(s_i, x), s_i])
    s_j = _rotation(model, bj) @ _local(model, bj, "vectors", joint.axes[1])
    return np.column_stack([s_i, s_j, np.cross(s_i, s_j)])


def _exact(frame: np.ndarray, axis: np.ndarray, k: int) -> np.ndarray:
    """The right-handed orthonormal frame (columns) nearest ``frame`` whose column ``k`` is the
    body's own joint axis: a calibrated model's pose need not satisfy its joints (the gait
    model's knee axes lie up to 3.2° apart there, its ankle arms 1.7° off perpendicular), and
    OpenSim's joint must turn about the axes fccgrb's constraints use. The five-bar's pose is
    exact: its frames stay as they are, to rounding."""
    a = axis / np.linalg.norm(axis)
    b = frame[:, (k + 1) % 3] - (frame[:, (k + 1) % 3] @ a) * a
    b /= np.linalg.norm(b)
    out = np.empty((3, 3))
    out[:, k], out[:, (k + 1) % 3], out[:, (k + 2) % 3] = a, b, np.cross(a, b)
    return out


def floating_bodies(model: Model) -> list[str]:
    """The bodies no joint makes a child of (a gait model's pelvis)."""
    children = {joint.bodies[1] for joint in model.joints}
    return [b.name for b in model.bodies if b.name not in children]


def build_opensim_model(osim: ModuleType, model: Model) -> Any:
    """The model as an ``opensim.Model`` (see the module's docstring). Each joint's parent and
    child frames get the same global orientation G at the YAML pose (R_i^T G in body i,
    R_j^T G in body j), so that zero joint coordinates leave every body at its YAML pose."""
    joint_classes = {"revolute": osim.PinJoint, "universal": osim.UniversalJoint,
                     "spherical": osim.BallJoint}
    out = osim.Model()
    out.setName(model.name)
    out.setGravity(osim.Vec3(*model.gravity))
    bodies: dict[str, Any] = {}
    for b in model.bodies:
        if b.inertia is None:
            raise ValueError(f"body {b.name}: OpenSim needs mass and inertia")
        tensor = np.array(b.inertia.tensor)
        body = osim.Body(b.name, b.inertia.mass, osim.Vec3(*b.inertia.com),
                         osim.Inertia(*np.diag(tensor), tensor[0, 1], tensor[0, 2], tensor[1, 2]))
        out.addBody(body)
        bodies[b.name] = body
    for joint in model.joints:
        if joint.type not in joint_classes:
            raise ValueError(f"joint {joint.name}: {joint.type} is not built in OpenSim here "
                             f"(expected one of {sorted(joint_classes)})")
        (bi, bj), G = joint.bodies, _joint_frame(model, joint)
        parent = out.getGround() if bi == GROUND else bodies[bi]
        in_i, in_j = _rotation(model, bi).T @ G, _rotation(model, bj).T @ G
        if joint.type != "spherical":  # each body's own axis, whatever the pose's rounding
            turning = {"revolute": (2, 2), "universal": (0, 1)}[joint.type]
            in_i = _exact(in_i, _local(model, bi, "vectors", joint.axes[0]), turning[0])
            in_j = _exact(in_j, _local(model, bj, "vectors", joint.axes[1]), turning[1])
        out.addJoint(joint_classes[joint.type](
            joint.name,
            parent, osim.Vec3(*_local(model, bi, "points", joint.points[0])),
            _euler_xyz(osim, in_i),
            bodies[bj], osim.Vec3(*_local(model, bj, "points", joint.points[1])),
            _euler_xyz(osim, in_j)))
    for name in floating_bodies(model):  # markers fix its 6 degrees of freedom: a FreeJoint
        out.addJoint(osim.FreeJoint(
            f"{name}_free", out.getGround(), osim.Vec3(*model.body(name).pose.r),
            _euler_xyz(osim, _rotation(model, name)), bodies[name], osim.Vec3(0, 0, 0),
            osim.Vec3(0, 0, 0)))
    for tp in model.tracked_points:
        out.addMarker(osim.Marker(tp.marker, bodies[tp.body],
                                  osim.Vec3(*_local(model, tp.body, "points", tp.point))))
    out.finalizeConnections()
    return out


def opensim_poses(osim: ModuleType, osim_model: Any, model: Model, state: Any) -> np.ndarray:
    """Every body's pose (bodies × 4 × 3: rows r, u, v, w) from OpenSim's ground transforms."""
    out = np.empty((len(model.bodies), 4, 3))
    bodies = osim_model.getBodySet()
    for k, b in enumerate(model.bodies):
        X = bodies.get(b.name).getTransformInGround(state)
        R, p = X.R().asMat33(), X.p()
        out[k, 0] = [p.get(i) for i in range(3)]
        out[k, 1:] = [[R.get(i, j) for i in range(3)] for j in range(3)]
    return out


def marker_table(osim: ModuleType, labels: tuple[str, ...], time_s: np.ndarray,
                 markers: np.ndarray, rate: float) -> Any:
    """The markers (frames × markers × 3, m) as OpenSim's ``TimeSeriesTableVec3`` in metres,
    what ``TRCFileAdapter`` would read from a .trc file."""
    table = osim.TimeSeriesTableVec3()
    table.setColumnLabels(list(labels))
    for t, frame in zip(time_s, markers, strict=True):
        row = osim.RowVectorVec3(len(labels))
        for k, point in enumerate(frame):
            row[k] = osim.Vec3(*map(float, point))
        table.appendRow(float(t), row)
    table.addTableMetaDataString("Units", "m")
    table.addTableMetaDataString("DataRate", f"{rate:g}")
    return table


def run_opensim(osim: ModuleType, osim_model: Any, model: Model, table: Any,
                time_s: np.ndarray, accuracy: float) -> tuple[Solved, np.ndarray]:
    """OpenSim's IK on every frame (assemble at frame 0, track after), every marker weight 1,
    infinite constraint weight; also OpenSim's own marker errors (frames × markers, m, in the
    model's ``tracking.points`` order) read after each frame."""
    started = time.perf_counter()
    state = osim_model.initSystem()
    weights = osim.SetMarkerWeights()
    for tp in model.tracked_points:
        weights.cloneAndAppend(osim.MarkerWeight(tp.marker, 1.0))
    reference = osim.MarkersReference(table, weights)
    solver = osim.InverseKinematicsSolver(osim_model, reference,
                                          osim.SimTKArrayCoordinateReference(), float("inf"))
    solver.setAccuracy(accuracy)
    seconds = np.empty(len(time_s))
    poses = np.empty((len(time_s), len(model.bodies), 4, 3))
    errors = np.empty((len(time_s), len(model.tracked_points)))
    squared = osim.SimTKArrayDouble()
    read_out = 0.0
    for f, t in enumerate(time_s):
        tick = time.perf_counter()
        state.setTime(float(t))
        if f == 0:
            solver.assemble(state)
        else:
            solver.track(state)
        tock = time.perf_counter()
        seconds[f] = tock - tick
        osim_model.realizePosition(state)
        poses[f] = opensim_poses(osim, osim_model, model, state)
        solver.computeCurrentSquaredMarkerErrors(squared)
        by_name = {solver.getMarkerNameForIndex(k): squared.getElt(k)
                   for k in range(solver.getNumMarkersInUse())}
        errors[f] = np.sqrt([by_name.get(tp.marker, np.nan) for tp in model.tracked_points])
        read_out += time.perf_counter() - tock
    call = time.perf_counter() - started - read_out
    return Solved(f"OpenSim {accuracy:.0e}", poses, seconds, call, float("nan")), errors


# --- the comparison ------------------------------------------------------------------------------
def best_of(repeat: int, run: Any) -> Any:
    """The run (of ``repeat``) with the smallest mean per-frame time; ``run`` returns a Solved
    or a (Solved, extra) pair."""
    best = None
    for _ in range(repeat):
        out = run()
        solved = out[0] if isinstance(out, tuple) else out
        if best is None or solved.seconds.mean() < best[0]:
            best = (solved.seconds.mean(), out)
    return best[1]


@dataclass(frozen=True)
class Case:
    """One trial every solver gets: a name for the table, the model, the frames' times and the
    markers (frames × tracked points × 3, m, NaN where missing), with their labels and rate;
    ``cli``: how ``fccgrb solve`` reads the same trial (model file, trial file, options)."""

    name: str
    model: Model
    time_s: np.ndarray
    markers: np.ndarray
    labels: tuple[str, ...]
    rate: float
    cli: tuple[str, ...]


def five_bar_cases(model: Model, truth: Synthesis, frames: int, trial: Path) -> list[Case]:
    """The synthesized trial's first ``frames`` frames perturbed at each level (seed 0); the
    command line reads ``trial`` (``fccgrb synth``'s file of the same motion) with
    ``--perturb``."""
    out = []
    for level in LEVELS_MM:
        markers = perturb(truth.markers, truth.labels, truth.rate, level * 1e-3, seed=0)[:frames]
        out.append(Case(f"P{level:g}", model, truth.result.time[:frames], markers, truth.labels,
                        truth.rate, (str(ROOT / "configs" / "models" / "five_bar.yaml"),
                                     str(trial), "--perturb", f"{level:g}")))
    return out


def gait_case(folder: Path) -> Case | None:
    """The gait example's trial (the lower-limb template calibrated on Qualisys.c3d, as
    benchmarks/gait.py does; its 28 markers as the file has them), or None without the shared
    data. The personalized model is written to ``folder`` for the command line."""
    if not GAIT_TRIAL.exists():
        return None
    trial = read_trial(GAIT_TRIAL)
    text = calibrate(load_model(GAIT_TEMPLATE), trial, mass=67.0).text
    path = folder / "personal.yaml"
    path.write_text(text, encoding="utf-8")
    model = parse_model(text, str(path))
    labels = match_labels(model, trial, {})
    return Case("gait", model, trial.time, trial.select(labels), tuple(labels), trial.rate,
                (str(path), str(GAIT_TRIAL)))


def warm_up(case: Case) -> None:
    """One untimed solve of each fccgrb method (see the timings above)."""
    system = compile_system(case.model, angles="coordinate", track=True)
    for method in METHODS:
        run_fccgrb(method, system, case.time_s, case.markers)


def compare(case: Case, repeat: int, osim: ModuleType | None) -> list[Solved]:
    """Every solver on the case's markers: fccgrb's first, then OpenSim at each accuracy of
    ACCURACIES (when OpenSim is importable)."""
    system = compile_system(case.model, angles="coordinate", track=True)
    solved = [best_of(repeat, lambda m=method: run_fccgrb(m, system, case.time_s, case.markers))
              for method in METHODS]
    if osim is not None:
        osim_model = build_opensim_model(osim, case.model)
        table = marker_table(osim, case.labels, case.time_s, case.markers, case.rate)
        for accuracy in ACCURACIES:
            solved.append(best_of(repeat, lambda a=accuracy: run_opensim(
                osim, osim_model, case.model, table, case.time_s, a))[0])
    return solved


def reference_ms(solved: list[Solved]) -> float | None:
    """OpenSim's ms/frame at the reference accuracy, when it ran."""
    found = [s for s in solved if s.label == f"OpenSim {REFERENCE_ACCURACY:.0e}"]
    return 1e3 * found[0].seconds.mean() if found else None


def table_rows(case: Case, solved: list[Solved]) -> list[str]:
    """The table's rows for one case."""
    reference = next((s for s in solved if s.label == f"OpenSim {REFERENCE_ACCURACY:.0e}"), None)
    rows = []
    for s in solved:
        ms = 1e3 * s.seconds.mean()
        iterations = "-" if np.isnan(s.iterations) else f"{s.iterations:.2f}"
        ratio = dtheta = "-"
        if reference is not None:
            ratio = f"{1e3 * reference.seconds.mean() / ms:.2f}"
            if s is not reference:
                diff = angles_from_poses(case.model, s.poses) - angles_from_poses(
                    case.model, reference.poses)
                dtheta = f"{np.degrees(np.abs(diff).max()):.2e}"
        fit = 1e3 * np.nanmean(marker_fit(case.model, s.poses, case.markers))
        fit_text = f"{fit:.4f}" if fit >= 0.01 else f"{fit:.1e}"
        rows.append(f"{case.name:6} {s.label:16} {ms:9.3f} "
                    f"{1e3 * s.call_s / len(case.markers):9.3f} {iterations:>10} {ratio:>12} "
                    f"{fit_text:>9} {dtheta:>11}")
    return rows


@dataclass(frozen=True)
class CliRun:
    """One ``fccgrb solve`` process: its summary's ms/frame (the per-frame position solve, which
    leaves out start-up, loading the kernels and the later stages), the process's wall time
    from start to exit, and the kernels' load it reported apart (0 on the numpy engine)."""

    ms_per_frame: float
    wall_s: float
    kernels_s: float


def run_cli(case: Case, method: str, folder: Path) -> CliRun:
    """The default ``fccgrb solve`` (every option at its default but ``--method``: the auto
    engine, per-frame rates, the inverse dynamics, the results file) on the case's
    trial, in a fresh process."""
    out = folder / "cli.h5"
    out.unlink(missing_ok=True)
    command = [shutil.which("fccgrb") or str(Path(sys.executable).with_name("fccgrb")), "solve",
               case.cli[0], case.cli[1], *case.cli[2:], "--method", method, "-o", str(out)]
    started = time.perf_counter()
    done = subprocess.run(command, capture_output=True, text=True)
    wall = time.perf_counter() - started
    if done.returncode:
        raise RuntimeError(f"{' '.join(command)}: {done.stderr.strip()}")
    lines = done.stdout.splitlines()
    header = next(k for k, line in enumerate(lines) if "ms/frame" in line.split())
    column = lines[header].split().index("ms/frame")
    loaded = re.search(r"compiled kernels loaded in ([0-9.]+) s", done.stderr)
    return CliRun(float(lines[header + 1].split()[column]), wall,
                  float(loaded.group(1)) if loaded else 0.0)


def cli_rows(case: Case, repeat: int, folder: Path, reference: float | None) -> list[str]:
    """The default command line's rows for one case: best of ``repeat`` processes by ms/frame
    (wall and load from that process)."""
    rows = []
    for method in METHODS:
        best = min((run_cli(case, method, folder) for _ in range(repeat)),
                   key=lambda r: r.ms_per_frame)
        ratio = "-" if reference is None else f"{reference / best.ms_per_frame:.2f}"
        rows.append(f"{case.name:6} {'fccgrb ' + method:16} {best.ms_per_frame:9.3f} "
                    f"{ratio:>12} {best.wall_s:9.2f} {best.kernels_s:10.2f}")
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=300)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--no-gait", action="store_true", help="leave the gait trial out")
    parser.add_argument("--no-cli", action="store_true",
                        help="leave the command line's table out")
    args = parser.parse_args()
    model = load_model(ROOT / "configs" / "models" / "five_bar.yaml")
    osim = load_opensim()
    if osim is None:
        print("opensim: not installed (pip install '.[peers]'), skipped")
    else:
        print(f"opensim {osim.__version__}: InverseKinematicsSolver, marker weights 1, "
              f"constraint weight inf, accuracy {' and '.join(f'{a:g}' for a in ACCURACIES)}")
    if importlib.util.find_spec("biorbd") is None:
        print("biorbd: not installed, skipped")
    else:
        print("biorbd: installed, but no biorbd model is built here yet, skipped")
    with tempfile.TemporaryDirectory(prefix="fccgrb-peers-") as scratch:
        folder = Path(scratch)
        trial = folder / "five_bar.c3d"
        subprocess.run([shutil.which("fccgrb") or str(Path(sys.executable).with_name("fccgrb")),
                        "synth", str(ROOT / "configs" / "models" / "five_bar.yaml"), "-o",
                        str(trial), "--duration", f"{args.frames / 100:g}"],
                       check=True, capture_output=True)
        truth = synthesize(model)
        cases = five_bar_cases(model, truth, args.frames, trial)
        gait = None if args.no_gait else gait_case(folder)
        print(f"five_bar: {args.frames} frames (P0, P7.5, P30); "
              + (f"gait: the lower limb on Qualisys.c3d, {len(gait.markers)} frames, "
                 f"{len(gait.labels)} markers" if gait is not None else
                 "gait: left out" if args.no_gait else f"gait: {GAIT_TRIAL} not found, skipped")
              + f"; best of {args.repeat}; 'OpenSim/this' = OpenSim {REFERENCE_ACCURACY:g} "
              f"ms/frame over this row's; 'max|Δθ|' against OpenSim {REFERENCE_ACCURACY:g}")
        print(f"{'case':6} {'solver':16} {'ms/frame':>9} {'call ms/f':>9} {'iter/frame':>10} "
              f"{'OpenSim/this':>12} {'fit mm':>9} {'max|Δθ| deg':>11}")
        references = {}
        for case in [*cases, *([gait] if gait is not None else [])]:
            if case is cases[0] or case is gait:
                warm_up(case)
            solved = compare(case, args.repeat, osim)
            references[case.name] = reference_ms(solved)
            print("\n".join(table_rows(case, solved)), flush=True)
        if args.no_cli:
            return
        print("\nthe default command line: 'fccgrb solve MODEL TRIAL --method M -o out.h5' in a "
              "fresh process per trial (auto engine, per-frame rates, inverse dynamics, HDF5); "
              "ms/frame from its summary (the per-frame solve: start-up, the kernels' load and "
              "the later stages are in 'wall s' only, the load also in 'kernels s')")
        print(f"{'case':6} {'solver':16} {'ms/frame':>9} {'OpenSim/this':>12} {'wall s':>9} "
              f"{'kernels s':>10}")
        for case in [*cases, *([gait] if gait is not None else [])]:
            print("\n".join(cli_rows(case, args.repeat, folder, references[case.name])),
                  flush=True)


if __name__ == "__main__":
    main()

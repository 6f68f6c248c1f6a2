"""Forward kinematics of OpenSim models: fccgrb's imported model beside OpenSim itself.

    python benchmarks/opensim_fk.py MODEL.osim [MODEL.osim ...] --opensim-python PATH
        [--poses 20] [--seed 0] [--widen 0]

For each model, OpenSim (in the Python given by ``--opensim-python``, one subprocess per model,
JSON across) draws ``--poses`` random poses: every unlocked coordinate that no enforced
CoordinateCouplerConstraint sets uniform in its range (a range wider than ±1e3 is taken as
±π rad or ±1 m; ``--widen f`` widens it by f times its width at both ends, to reach the
functions outside their points), locked ones at their default, each coupler's dependent set
by OpenSim's own coupler function of its independent value (repeated until chained couplers
settle), with
``Coordinate.setValue`` without enforcing constraints. It reports every coordinate's value,
every body's origin and rotation in the ground and every marker's position in the ground, and
how far ``Model.assemble`` moves the coordinates from there (a check that the couplers were
set as OpenSim's assembly sets them).

fccgrb reads the same file (``fccgrb_cli.model.load_model``), places the bodies at OpenSim's
values of all coordinates by ``pose_from_coordinates`` and reads the markers by
``system.point_positions``: the forward kinematics alone. Apart from it, fccgrb computes the
coordinates its couplings set (coupler functions and locked values, one pass in the model's
order, as its initial guess does) from OpenSim's values of the others, and they are compared
with OpenSim's; so are its coordinates' default values with the ones OpenSim's ``initSystem``
assembles (couplers applied).

Per model one row: the largest body-origin difference (mm), body-rotation difference (deg, the
angle of R_fccgrbᵀ R_OpenSim, from ‖ΔR‖_F so that it keeps its precision near zero) and
marker difference (mm) over the poses, the largest coordinate and default difference and the
coordinates that differ by more than 1e-9 (rad or m). A model fccgrb refuses gets its one-line
reason. Markers fixed in the ground are left out (they do not move). A model older than OpenSim 4
(Version below 40000) gets a second row: fccgrb and OpenSim both reading the 4.x file OpenSim
writes of it. OpenSim rounds such a model's joint offsets to 6 significant digits in its
conversion on reading, which fccgrb does not do; the second row tells that rounding (~1e-4 mm)
apart from a difference of fccgrb's.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from fccgrb_cli.core.errors import InputError
from fccgrb_cli.model import Model, load_model
from fccgrb_cli.system import compile_system
from fccgrb_cli.system.moving_pose import pose_from_coordinates

# Run in OpenSim's Python: argv[1] the request (JSON), argv[2] where to write the answer.
OPENSIM_SIDE = r'''
import json, math, sys
import numpy as np
import opensim as osim

request = json.load(open(sys.argv[1]))
osim.Logger.setLevelString("error")
model = osim.Model(request["model"])
state = model.initSystem()
coords = model.getCoordinateSet()
names = [coords.get(k).getName() for k in range(coords.getSize())]
defaults = [coords.get(k).getValue(state) for k in range(len(names))]  # as initSystem assembles
couplers = []
constraints = model.getConstraintSet()
for k in range(constraints.getSize()):
    c = osim.CoordinateCouplerConstraint.safeDownCast(constraints.get(k))
    if c is None or not c.isEnforced(state):
        continue
    independent = c.getIndependentCoordinateNames()
    couplers.append(([independent.get(i) for i in range(independent.getSize())],
                     c.getDependentCoordinateName(), c.getFunction()))
dependent = {d for _, d, _ in couplers}
rng = np.random.default_rng(request["seed"])
free = []
for k, name in enumerate(names):
    c = coords.get(k)
    if c.getDefaultLocked() or name in dependent:
        continue
    low, high = c.getRangeMin(), c.getRangeMax()
    if max(abs(low), abs(high)) > 1e3:
        bound = math.pi if c.getMotionType() == 1 else 1.0
        low, high = max(low, -bound), min(high, bound)
    margin = request["widen"] * (high - low)
    free.append((c, low - margin, high + margin))
bodies = model.getBodySet()
markers = model.getMarkerSet()
poses = []
for _ in range(request["poses"]):
    for c, low, high in free:
        c.setValue(state, float(rng.uniform(low, high)), False)
    for _ in range(len(couplers)):  # chained couplers settle in as many passes
        for independent, name, function in couplers:
            x = osim.Vector(len(independent), 0.0)
            for i, n in enumerate(independent):
                x.set(i, coords.get(n).getValue(state))
            coords.get(name).setValue(state, function.calcValue(x), False)
    model.realizePosition(state)
    values = [coords.get(k).getValue(state) for k in range(len(names))]
    body_out = {}
    for k in range(bodies.getSize()):
        b = bodies.get(k)
        X = b.getTransformInGround(state)
        R, p = X.R().asMat33(), X.p()
        body_out[b.getName()] = ([p.get(i) for i in range(3)],
                                 [[R.get(i, j) for j in range(3)] for i in range(3)])
    marker_out = {}
    for k in range(markers.getSize()):
        m = markers.get(k)
        g = m.getLocationInGround(state)
        marker_out[m.getName()] = [g.get(i) for i in range(3)]
    assembled = osim.State(state)
    model.assemble(assembled)
    moved = max((abs(coords.get(k).getValue(assembled) - values[k])
                 for k in range(len(names))), default=0.0)
    poses.append({"values": values, "bodies": body_out, "markers": marker_out,
                  "assembly_moved": moved})
json.dump({"names": names, "dependent": sorted(dependent), "poses": poses, "defaults": defaults},
          open(sys.argv[2], "w"))
if request["written"]:
    model.printToXML(request["written"])
'''


def opensim_poses(python: str, model: Path, poses: int, seed: int,
                  written: Path | None = None, widen: float = 0.0) -> dict:
    """OpenSim's random poses of ``model`` (see the module): names, poses with values, bodies,
    markers; with ``written``, the model as OpenSim writes it (4.x) saved there. Raises
    RuntimeError with OpenSim's error line when it fails."""
    with tempfile.TemporaryDirectory() as folder:
        request, answer = Path(folder, "request.json"), Path(folder, "answer.json")
        request.write_text(json.dumps({"model": str(model.resolve()), "poses": poses,
                                       "seed": seed, "written": str(written or ""),
                                       "widen": widen}))
        done = subprocess.run([python, "-c", OPENSIM_SIDE, str(request), str(answer)],
                              capture_output=True, text=True, cwd=folder,
                              env={**os.environ, "OPENBLAS_NUM_THREADS": "1"})
        if done.returncode != 0 or not answer.exists():
            lines = (done.stderr or done.stdout).strip().splitlines() or ["no output"]
            said = [line for line in lines if "Error" in line or "xception" in line]
            raise RuntimeError(f"OpenSim failed: {(said or lines)[-1].strip()}")
        return json.loads(answer.read_text())


def older_than_4(path: Path) -> bool:
    """Whether the document's Version is below 40000: OpenSim converts such a model on
    reading, writing its joint offsets with 6 significant digits."""
    head = path.read_text(encoding="utf-8", errors="replace")[:400]
    found = re.search(r'<OpenSimDocument\s+Version="(\d+)"', head)
    return found is not None and int(found.group(1)) < 40000


def rotation_angle_deg(A: np.ndarray, B: np.ndarray) -> float:
    """The angle (deg) of the rotation Aᵀ B, from ‖A − B‖_F = 2√2 sin(angle/2)."""
    chord = float(np.linalg.norm(A - B)) / (2.0 * np.sqrt(2.0))
    return float(np.degrees(2.0 * np.arcsin(min(chord, 1.0))))


def compare(model: Model, reference: dict) -> dict:
    """fccgrb's forward kinematics of ``model`` at OpenSim's poses: the largest differences
    (see module)."""
    system = compile_system(model, angles="coordinate")
    functions = system.functions
    assert functions is not None  # an imported model has moving joints
    names = [a.name for a in model.angles]
    their = reference["names"]
    if sorted(names) != sorted(their):
        raise RuntimeError(f"coordinates differ: fccgrb only {sorted(set(names) - set(their))}, "
                           f"OpenSim only {sorted(set(their) - set(names))}")
    order = [their.index(n) for n in names]
    points = [(tp.body, tp.point) for tp in model.tracked_points]
    bodies = [b.name for b in model.bodies]
    worst = {"origin_mm": 0.0, "rotation_deg": 0.0, "marker_mm": 0.0, "coordinate": 0.0,
             "assembly_moved": 0.0, "default": 0.0}
    differing: set[str] = set()
    ours_default = np.array([a.default for a in model.angles])
    gap = np.abs(ours_default - np.asarray(reference["defaults"], dtype=float)[order])
    worst["default"] = float(gap.max(initial=0.0))
    differing.update(f"{n} (default)" for n, g in zip(names, gap, strict=True) if g > 1e-9)
    for pose in reference["poses"]:
        values = np.asarray(pose["values"], dtype=float)[order]
        theta = values.copy()
        for _, k, independent, function in functions.couplings:
            theta[k] = function.terms(float(theta[independent]) if independent >= 0 else 0.0)[0]
        gap = np.abs(theta - values)
        worst["coordinate"] = max(worst["coordinate"], float(gap.max(initial=0.0)))
        differing.update(n for n, g in zip(names, gap, strict=True) if g > 1e-9)
        worst["assembly_moved"] = max(worst["assembly_moved"], pose["assembly_moved"])
        q = pose_from_coordinates(system, values)
        for body in bodies:
            r, axes = (np.asarray(a, dtype=float) for a in pose["bodies"][body])
            ours = q[system.layout.q_slice(body)].reshape(4, 3)
            worst["origin_mm"] = max(worst["origin_mm"], 1e3 * float(np.linalg.norm(ours[0] - r)))
            worst["rotation_deg"] = max(worst["rotation_deg"],
                                        rotation_angle_deg(ours[1:].T, axes))
        if points:
            ours = system.point_positions(q, points)
            theirs = np.array([pose["markers"][p] for _, p in points], dtype=float)
            worst["marker_mm"] = max(worst["marker_mm"],
                                     1e3 * float(np.linalg.norm(ours - theirs, axis=1).max()))
    return {**worst, "differing": sorted(differing), "bodies": len(bodies),
            "markers": len(points), "coordinates": len(names)}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("models", nargs="+", type=Path)
    parser.add_argument("--opensim-python", default=sys.executable)
    parser.add_argument("--poses", type=int, default=20)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--widen", type=float, default=0.0,
                        help="draw from each range widened by this fraction of it at both ends "
                             "(functions outside their points)")
    args = parser.parse_args(argv)
    print(f"load: {os.getloadavg()[0]:.2f} {os.getloadavg()[1]:.2f} {os.getloadavg()[2]:.2f}")
    print("| model | bodies | markers | coords | origin mm | rotation deg | marker mm | "
          "coord diff | default diff | assemble moved | differing coordinates |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    refused = []
    for path in args.models:
        started = time.perf_counter()
        try:
            model = load_model(path)
        except InputError as error:
            refused.append(f"{path}: fccgrb: {error}")
            continue
        with tempfile.TemporaryDirectory() as folder:
            written = Path(folder, path.name) if older_than_4(path) else None
            try:
                reference = opensim_poses(args.opensim_python, path, args.poses, args.seed,
                                          written, args.widen)
                rows = [(str(path), compare(model, reference))]
                if written is not None:  # both read OpenSim's 4.x conversion
                    again = opensim_poses(args.opensim_python, written, args.poses, args.seed,
                                          widen=args.widen)
                    rows.append((f"{path} as OpenSim writes it", compare(load_model(written),
                                                                         again)))
            except RuntimeError as error:
                refused.append(f"{path}: {error}")
                continue
        for name, row in rows:
            differing = ", ".join(row["differing"]) or "-"
            print(f"| {name} | {row['bodies']} | {row['markers']} | {row['coordinates']} | "
                  f"{row['origin_mm']:.2e} | {row['rotation_deg']:.2e} | "
                  f"{row['marker_mm']:.2e} | {row['coordinate']:.1e} | {row['default']:.1e} | "
                  f"{row['assembly_moved']:.1e} | {differing} |"
                  f"  ({time.perf_counter() - started:.1f} s)", flush=True)
    for line in refused:
        print(f"not compared: {line}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

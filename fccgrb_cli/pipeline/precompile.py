"""Compile the numba kernels ahead of time (``fccgrb compile``): every compiled path once, on a
few synthesized frames of a built-in model, so that the first real solve only loads them from
numba's cache (numba compiles a kernel for the types of its arguments, which do not depend on
the model)."""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from fccgrb_cli.dynamics.moving import ready_inverse
from fccgrb_cli.model import parse_model
from fccgrb_cli.pipeline.options import SolveOptions
from fccgrb_cli.pipeline.solve import solve_trial
from fccgrb_cli.pipeline.synth import synthesize
from fccgrb_cli.system import compile_system
from fccgrb_cli.trial.record import Trial

# A spatial double pendulum with inertia (configs/models/pendulum.yaml, shortened): every
# compiled path runs on it, the inverse dynamics included.
BUILT_IN = """
name: pendulum
units: {angle: deg}
gravity: [0, 0, -9.81]
form: full
ground:
  points: {O: [0, 0, 0]}
  vectors: {down: [0, 0, -1], minus_x: [-1, 0, 0]}
bodies:
  link1:
    mass: 1.5
    inertia: [0.02, 0.02, 0.0003]
    points: {A: [0, 0, 0.2], P1: [0, 0, -0.2]}
    vectors: {minus_u: [-1, 0, 0], minus_w: [0, 0, -1]}
    pose: {r: [0, 0, -0.2], u: [1, 0, 0], v: [0, 1, 0], w: [0, 0, 1]}
  link2:
    mass: 1.0
    inertia: [0.0075, 0.0075, 0.0002]
    points: {C: [0, 0, 0.15], P2: [0, 0.04, 0], P3: [0, 0, -0.15]}
    pose: {r: [0, 0, -0.55], u: [1, 0, 0], v: [0, 1, 0], w: [0, 0, 1]}
joints:
  - {name: shoulder, type: universal, bodies: [ground, link1], points: [O, A], axes: [x, v]}
  - {name: elbow, type: universal, bodies: [link1, link2], points: [P1, C], axes: [u, v]}
angles:
  - {name: shoulder_x, vectors: [ground.down, link1.v],
     motion: {mean: 90, terms: [{amplitude: 30, frequency: 0.5}]}}
  - {name: shoulder_y, vectors: [ground.minus_x, link1.w],
     motion: {mean: 90, terms: [{amplitude: 20, frequency: 0.4, phase: 30}]}}
  - {name: elbow_x, vectors: [link1.minus_w, link2.v],
     motion: {mean: 100, terms: [{amplitude: 35, frequency: 0.6, phase: 60}]}}
  - {name: elbow_y, vectors: [link1.minus_u, link2.w],
     motion: {mean: 85, terms: [{amplitude: 25, frequency: 0.7, phase: 90}]}}
tracking:
  points:
    - {marker: P1, point: link1.P1}
    - {marker: P2, point: link2.P2}
    - {marker: P3, point: link2.P3}
"""
# every compiled loop: NRM (with the rates and the classical model's drive and multipliers),
# the structured optimizers (CNO-SQP's loop holds the interior point's and goal attainment's
# kernels too), and the whole-trial smoother's (--smooth auto) after NRM
PASSES: dict[str, dict[str, Any]] = {  # pass name -> SolveOptions fields
    "nrm-wls": {"method": "nrm-wls"}, "cno-sqp": {"method": "cno-sqp"},
    "nrm-wls --smooth auto": {"method": "nrm-wls", "smooth": "auto"}}


def precompile(report: Callable[[str, float], None] | None = None,
               passes: Sequence[str] = tuple(PASSES)) -> float:
    """Run every compiled path (or those of ``passes``, names of ``PASSES``) on 12 synthesized
    frames of the built-in pendulum; ``report`` gets (pass, seconds) after each; returns the
    total seconds."""
    started = time.perf_counter()
    model = parse_model(BUILT_IN, "built-in pendulum")
    truth = synthesize(model, duration=0.12, rate=100.0)
    trial = Trial("built-in pendulum (synthesized)", truth.labels, truth.markers, truth.rate)
    for name in passes:
        begun = time.perf_counter()
        solve_trial(model, trial, SolveOptions(**PASSES[name], engine="compiled",
                                               events="none"))
        if name == "nrm-wls":  # an imported model's inverse dynamics (none in the pendulum)
            ready_inverse(compile_system(model, angles="coordinate", track=True))
        if report is not None:
            report(name, time.perf_counter() - begun)
    return time.perf_counter() - started


BACKGROUND = "FCCGRB_BACKGROUND_COMPILE"  # "0": a first run compiles in the foreground
LOCK = ".compiling"  # in the cache folder while a background compile runs
STALE = 900.0  # s: a lock older than this was left by a compile that died


def compiling(folder: Path) -> bool:
    """Whether a background compile is filling ``folder`` now (its :data:`LOCK`, younger than
    :data:`STALE`): its first kernels are already there while it compiles the rest."""
    lock = folder / LOCK
    try:
        return lock.exists() and time.time() - lock.stat().st_mtime < STALE
    except OSError:
        return False


def compile_in_background(folder: Path) -> bool:
    """Start ``fccgrb compile`` as a detached process (its own session, no terminal, output
    discarded) that fills the kernel cache ``folder`` for the next runs, unless one is running
    already (a :data:`LOCK` file younger than :data:`STALE`). Returns whether a compile is now
    under way."""
    import subprocess

    lock = folder / LOCK
    try:
        if compiling(folder):
            return True
        lock.write_text(str(os.getpid()))
    except OSError:
        return False
    code = background_code(lock)
    try:
        subprocess.Popen([sys.executable, "-c", code], stdin=subprocess.DEVNULL,
                         stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                         start_new_session=True, env={**os.environ, BACKGROUND: "0"})
    except OSError:
        lock.unlink(missing_ok=True)
        return False
    return True


def background_code(lock: Path) -> str:
    """The background compile's ``python -c`` program. It imports this very package, put first
    on its path: with ``-c`` Python puts the current folder first, and a user who runs the
    README's first command from the repository's root has the package's sources there, a
    second copy whose kernels (their cache named by their own place and digest) are not the
    installed package's: the background compile filled that copy's cache, and every later
    command found its own empty and started again."""
    home = str(Path(__file__).resolve().parents[2])  # the folder holding fccgrb_cli
    return (f"import sys; sys.path.insert(0, {home!r}); "
            "from fccgrb_cli.pipeline.precompile import background_main; "
            f"sys.exit(background_main({str(lock)!r}))")


def background_main(lock: str) -> int:
    """The background compile's process: :func:`precompile`, then the lock removed."""
    try:
        precompile()
    finally:
        Path(lock).unlink(missing_ok=True)
    return 0

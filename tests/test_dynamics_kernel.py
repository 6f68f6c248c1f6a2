"""The dynamics stage in the compiled kernels (kernels.driven_frames with the inverse dynamics):
one factorization a frame serving q̇, q̈, λ and, where Φ_q is square, the next frame's chord
steps; guesses moved by the extrapolated corrections of the frames before.

* guesses far from the solution (every body coordinate off by ~1 mm, so the chord steps must
  give way to fresh factorizations) still give the frame-by-frame reference's motion,
  multipliers, moments and load power to 1e-9, every frame inside the kernel (no frame left to
  Python's path);
* a frame with no guess in the middle (the extrapolation restarts after it) and an external
  load whose point moves over the body; the sample's steps per frame with the extrapolation;
* a taller Φ_q whose equations cannot all be met (a floating base driven by low-passed
  features) keeps Gauss–Newton: numpy's least-squares motion, not a chord's fixed point;
* the LAPACK the solvers use (fccgrb_cli.core.blas.lapack) is scipy's, without importing the
  scipy.linalg package: a solve's start-up does not pay for it (checked in a fresh process);
  nor for numba's (scipy's Cython BLAS and LAPACK modules, loaded from their files: the kernels'
  matrix products and solves give numpy's figures), nor for the rank test of a model with
  redundant equations (LAPACK's pivoted QR, scipy.linalg.qr's pivots).
"""

from __future__ import annotations

import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from test_batched_dynamics import assert_same

from fccgrb_cli.dynamics import ExternalLoad
from fccgrb_cli.dynamics.convert import classical_dynamics
from fccgrb_cli.model import load_model
from fccgrb_cli.pipeline.options import SolveOptions
from fccgrb_cli.pipeline.solve import solve_trial
from fccgrb_cli.solvers.ad import solve as ad
from fccgrb_cli.solvers.engine import numba_available
from fccgrb_cli.trial.record import read_trial

ROOT = Path(__file__).resolve().parents[1]

pytestmark = pytest.mark.skipif(not numba_available(), reason="numba is not installed")


@pytest.fixture(scope="module")
def sample():
    model = load_model(ROOT / "configs" / "models" / "five_bar.yaml")
    trial = read_trial(ROOT / "sample_data" / "five_bar.c3d")
    run = solve_trial(model, trial, SolveOptions(method="nrm-wls", perturb_mm=30.0,
                                                 dynamics=False))
    return model, run.result


def push(n: int) -> ExternalLoad:
    """A force, a free moment and a point of application that wander (N, N·m, m)."""
    rng = np.random.default_rng(11)
    return ExternalLoad("push", "B4", rng.normal(0, 15, (n, 3)), rng.normal(0, 0.2, (n, 3)),
                        rng.normal(0, 1.5, (n, 3)))


@pytest.mark.parametrize("cutoff", [None, 6.0])
def test_far_guesses_give_the_reference_inside_the_kernel(sample, cutoff) -> None:
    model, result = sample
    n = result.n_frames
    rng = np.random.default_rng(3)
    off = result.q.copy()
    off[:, :60] += rng.normal(0, 1e-3, (n, 60))
    load = push(n)
    reference = classical_dynamics(model, result, cutoff=cutoff, loads=[load], batched=False)
    compiled = classical_dynamics(model, replace(result, q=off), cutoff=cutoff, loads=[load],
                                  engine="compiled")
    assert_same(compiled, reference)
    iterations = compiled.kinematics.iterations
    assert iterations.max() <= ad.BATCH_ITER  # no frame went to Python's frame-by-frame path
    assert iterations.mean() > 3.5  # the guesses were far: more steps than the sample's ~3.4
    assert np.abs(compiled.inverse.external_power).max() > 1.0


def test_a_frame_without_a_guess_restarts_the_extrapolation(sample) -> None:
    model, result = sample
    holed = result.q.copy()
    holed[[40, 41, 150]] = np.nan
    load = push(result.n_frames)
    reference = classical_dynamics(model, result, loads=[load], batched=False)
    compiled = classical_dynamics(model, replace(result, q=holed), loads=[load],
                                  engine="compiled")
    assert_same(compiled, reference)


def test_sample_guesses_take_the_extrapolated_corrections(sample) -> None:
    """On the sample the corrections change slowly: moved by their linear extrapolation the
    guesses start ~1e-6 m off instead of ~7e-6 (the last correction alone) and the frames take
    ~3.4 steps (chord steps and one factorization at the solution) instead of ~4.0."""
    model, result = sample
    compiled = classical_dynamics(model, result, engine="compiled")
    assert compiled.kinematics.iterations.mean() < 3.6
    assert_same(compiled, classical_dynamics(model, result, batched=False))


def test_taller_system_with_unmet_equations_keeps_gauss_newton() -> None:
    """A floating base driven by its low-passed features (not exactly rigid, so Φ = 0 cannot be
    met: least squares): the kernel's Gauss–Newton reaches numpy's least-squares motion,
    which a chord matrix's fixed point would miss."""
    from test_floating_base import moving_text

    from fccgrb_cli.model import parse_model
    from fccgrb_cli.pipeline.synth import synthesize

    model = parse_model(moving_text(), "floating.yaml").with_form("full")
    truth = synthesize(model, duration=1.0).result
    numpy = classical_dynamics(model, truth, cutoff=6.0, engine="numpy")
    compiled = classical_dynamics(model, truth, cutoff=6.0, engine="compiled")
    assert np.abs(numpy.kinematics.phi_norm).max() > 1e-6  # the drivers are not all met
    assert_same(compiled, numpy)


def test_solvers_lapack_is_scipys_without_scipy_linalg() -> None:
    from scipy.linalg import lapack as scipy_lapack

    from fccgrb_cli.core.blas import lapack

    assert lapack.dposv is scipy_lapack.dposv
    A = np.array([[4.0, 1.0], [1.0, 3.0]])
    _, x, info = lapack.dposv(A, np.array([1.0, 2.0]))
    assert info == 0 and np.allclose(A @ x, [1.0, 2.0], rtol=0, atol=1e-15)
    assert lapack.dposv(np.array([[1.0, 2.0], [2.0, 1.0]]), np.ones(2))[2] > 0  # indefinite
    code = ("import sys, fccgrb_cli.cli.main, fccgrb_cli.pipeline.solve, "
            "fccgrb_cli.solvers.nrm.solve; "
            "from fccgrb_cli.core.blas import lapack; print('scipy.linalg' in sys.modules)")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=True)
    assert done.stdout.strip() == "False"


NUMBA_BLAS = """
import sys
import numpy as np
import fccgrb_cli.solvers  # noqa: F401  (configure: scipy's Cython modules for numba)
from numba import njit

@njit
def products(a, b):
    return np.dot(a, b), np.linalg.solve(a, b)

a = np.array([[4.0, 1.0, 0.5], [1.0, 3.0, 0.2], [0.5, 0.2, 2.0]])
b = np.arange(9.0).reshape(3, 3)
dot, solved = products(a, b)
print(np.abs(dot - a @ b).max() < 1e-14, np.abs(a @ solved - b).max() < 1e-13)
print("scipy.linalg" in sys.modules)
import scipy.linalg
from scipy.linalg import cython_blas, cython_lapack
print(cython_blas is sys.modules["scipy.linalg.cython_blas"], cython_lapack.__file__)
"""


def test_numba_gets_scipys_cython_blas_without_scipy_linalg() -> None:
    done = subprocess.run([sys.executable, "-c", NUMBA_BLAS], capture_output=True, text=True,
                          check=True)
    import scipy

    products, imported, same = done.stdout.splitlines()
    assert products == "True True"
    assert imported == "False"  # numba's kernels loaded without the package
    kept, path = same.split(" ", 1)
    assert kept == "True" and Path(path).parent == Path(scipy.__file__).parent / "linalg"


def test_redundant_rows_without_scipy_linalg() -> None:
    import scipy.linalg

    from fccgrb_cli.system.rank import pivoted_columns

    rng = np.random.default_rng(3)
    for shape in ((6, 4), (4, 6), (9, 9)):
        A = rng.standard_normal(shape)
        A[:, 1] = A[:, 0] + A[:, 2]  # rank-deficient: the pivots' order matters
        assert pivoted_columns(A).tolist() == \
            scipy.linalg.qr(A, pivoting=True, mode="economic")[2].tolist()
    template = ROOT / "configs" / "models" / "lower_limb.yaml"
    code = ("import sys; from fccgrb_cli.model import load_model; "
            "from fccgrb_cli.system.structure import analyse; "
            f"print(len(analyse(load_model({str(template)!r})).redundant) > 0, "
            "'scipy.linalg' in sys.modules)")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=True)
    assert done.stdout.strip() == "True False"

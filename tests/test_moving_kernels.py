"""The compiled function rows (solvers/moving_kernels.py) against the numpy reference: every
function kind's polynomial pieces against its ``terms`` (random knots and values, x inside,
at and outside the knots), and the rows' h, ∂h/∂θ, ∂²h/∂θ² against FunctionRows.terms on
generated models and on the OpenSim test models at random coordinates; then the kernels' Φ,
Φ_q, residual Hessian and γ of those models against the numpy system's."""

from __future__ import annotations

from fractions import Fraction
from math import perm
from pathlib import Path

import numpy as np
import pytest

from fccgrb_cli.model.osim.convert import load_osim
from fccgrb_cli.model.osim.functions import (
    Constant,
    LinearFunction,
    Multiplier,
    NaturalSpline,
    PiecewiseLinear,
    Polynomial,
    SimmSpline,
)
from fccgrb_cli.solvers import kernels
from fccgrb_cli.solvers.moving_kernels import function_terms, row_terms
from fccgrb_cli.system.compiled import Drive, compile_system
from fccgrb_cli.system.moving_tables import MovingRows, moving_rows
from fccgrb_cli.system.sparse import sparse_of
from tests.test_kernels import dense_jacobian, envelope_mask, in_q_order
from tests.test_moving_joints import system_of

OPENSIM = Path(__file__).resolve().parents[2] / "shared" / "data" / "opensim"


def _random_functions(rng: np.random.Generator) -> list:
    n = int(rng.integers(2, 12))
    x = np.cumsum(rng.uniform(0.1, 0.6, n)) - 1.5
    xs, ys = tuple(x), tuple(rng.normal(size=n))
    out = [Constant(float(rng.normal())), LinearFunction(*rng.normal(size=2)),
           Polynomial(tuple(rng.normal(size=int(rng.integers(1, 7))))),
           PiecewiseLinear(xs, ys), SimmSpline(xs, ys),
           Multiplier(SimmSpline(xs, ys), float(rng.normal()))]
    out += [NaturalSpline(xs, ys, d) for d in (1, 3, 5, 7) if n >= (d + 1) // 2]
    return out


def _table_of(function) -> MovingRows:
    """A one-coupling row set holding ``function`` (table index 0)."""
    from fccgrb_cli.system.moving import FunctionRows

    rows = FunctionRows(rows=np.zeros(1, dtype=int), joints=(), couplings=((0, 0, 1, function),),
                        n_coordinates=2, defaults=np.zeros(2), translational=np.zeros(2, bool))
    built = moving_rows(rows)
    assert isinstance(built, MovingRows)
    return built


def _exact_natural(f: NaturalSpline, x: float) -> np.ndarray:
    """f, f′, f″ of the truncated-power form in rational arithmetic (``terms`` rounds its sum of
    large cancelling terms: ~1e-10 for a degree-7 spline)."""
    xs = [Fraction(v) for v in f.x]
    c, p = f.coefficients
    shift, scale = (xs[0] + xs[-1]) / 2, max((xs[-1] - xs[0]) / 2, Fraction(1e-300))
    t = (Fraction(x) - shift) / scale
    k = f.degree
    out = []
    for order in range(3):
        total = Fraction(0)
        for ci, xi in zip(c, xs, strict=True):
            r = t - (xi - shift) / scale
            if k > order or (k == order and r != 0):  # d^o|r|^k = k!/(k−o)! |r|^(k−o) sgn(r)^o
                sign = 1 if r >= 0 else -1
                total += Fraction(ci) * perm(k, order) * abs(r) ** (k - order) * sign ** order
        for power, pl in enumerate(p):
            if power >= order:
                total += Fraction(pl) * perm(power, order) * t ** (power - order)
        out.append(float(total / scale ** order))
    return np.array(out)


@pytest.mark.parametrize("seed", range(40))
def test_every_function_kind_as_pieces_equals_its_terms(seed):
    rng = np.random.default_rng(seed)
    for function in _random_functions(rng):
        table = _table_of(function).table
        knots = np.asarray(getattr(getattr(function, "inner", function), "x", ()), dtype=float)
        xs = np.concatenate([rng.uniform(-4.0, 4.0, 25), knots])
        if isinstance(function, NaturalSpline) and function.degree == 1:
            xs = xs[~np.isin(xs, knots)]  # a kink: ``terms`` gives the mean of the two slopes
        for x in xs:
            got = np.array(function_terms(table, 0, float(x)))
            if isinstance(function, NaturalSpline):
                want = _exact_natural(function, float(x))
            else:
                want = np.array(function.terms(float(x)))
            assert got == pytest.approx(want, rel=1e-12, abs=1e-12), (function, x)


def _compiled_terms(m: MovingRows, theta: np.ndarray, n_theta: int):
    n, width = m.cols.shape
    h, d1, d2 = np.empty(n), np.empty((n, width)), np.empty((n, width, width))
    row_terms(m, theta, 2, h, d1, d2)
    H1, H2 = np.zeros((n, n_theta)), np.zeros((n, n_theta, n_theta))
    for r in range(n):
        for a in range(width):
            if m.cols[r, a] < 0:
                continue
            H1[r, m.cols[r, a]] += d1[r, a]
            for b in range(width):
                if m.cols[r, b] >= 0:
                    H2[r, m.cols[r, a], m.cols[r, b]] += d2[r, a, b]
    return h, H1, H2


def _agree(functions, rng, draws: int = 5) -> None:
    m = moving_rows(functions)
    assert isinstance(m, MovingRows)
    for _ in range(draws):
        theta = functions.defaults + rng.normal(scale=0.6, size=functions.n_coordinates)
        got = _compiled_terms(m, theta, functions.n_coordinates)
        want = functions.terms(theta)
        for g, w in zip(got, want, strict=True):
            assert np.abs(g - w).max() <= 1e-12 * (1.0 + np.abs(w).max())


@pytest.mark.parametrize("seed", range(8))
def test_compiled_rows_equal_the_numpy_rows_on_generated_models(seed):
    system = system_of(seed)
    _agree(system.functions, np.random.default_rng(seed))


MODELS = sorted(OPENSIM.glob("*/*.osim")) if OPENSIM.is_dir() else []


@pytest.mark.skipif(not MODELS, reason="the OpenSim test models are not here")
@pytest.mark.parametrize("path", MODELS, ids=lambda p: p.name)
def test_compiled_rows_equal_the_numpy_rows_on_the_opensim_models(path):
    model = load_osim(path)
    system = compile_system(model, angles="coordinate", track=True)
    _agree(system.functions, np.random.default_rng(0), draws=10)


def _sparse_agrees(system, rng) -> None:
    """Φ, Φ_q, Σ c ∇²Φ and the topology's γ of the compiled kernels equal the numpy system's."""
    s = sparse_of(system)
    assert len(s.moving.rows) == len(system.functions.rows)
    n_rows = system.n_rows
    inside = envelope_mask(s)
    for _ in range(3):
        q = system.pose() + 0.05 * rng.standard_normal(system.nq)
        ref = rng.standard_normal((system.n_targets, 3))
        F, phi = np.empty(len(s.f0)), np.empty(n_rows)
        kernels.residual(s, q, q[s.nb:], ref, F, phi)
        phi_dense, J_dense = system.evaluate(q, Drive(ref=ref))
        assert np.abs(phi - phi_dense).max() < 1e-12
        values = np.empty(len(s.j_col))
        kernels.jacobian(s, q, F, values)
        assert np.abs(dense_jacobian(s, values, n_rows) - J_dense).max() < 1e-12
        c = rng.standard_normal(n_rows)
        H = np.where(inside, 0.0, np.nan)
        kernels.add_hessian(s, q, c, H)
        H_dense = system.residual_hessian(q, c)
        assert np.abs(in_q_order(s, np.where(inside, H, 0.0)) - H_dense).max() \
            < 1e-12 * np.abs(H_dense).max()
        qd = rng.standard_normal(system.nq)
        gamma = np.full(n_rows, np.nan)
        kernels._gamma_top(s, q, qd, np.empty(len(s.f0)), gamma)
        want = system.gamma(q, qd, Drive(ref=ref))
        top = s.top_rows
        assert np.abs(gamma[top] - want[top]).max() < 1e-11 * (1 + np.abs(want[top]).max())


@pytest.mark.parametrize("seed", range(4))
def test_the_kernels_evaluate_a_moving_model_as_the_numpy_system(seed):
    _sparse_agrees(system_of(seed), np.random.default_rng(seed))


@pytest.mark.skipif(not MODELS, reason="the OpenSim test models are not here")
@pytest.mark.parametrize("path", MODELS, ids=lambda p: p.name)
def test_the_kernels_evaluate_the_opensim_models_as_the_numpy_system(path):
    system = compile_system(load_osim(path), angles="coordinate", track=True)
    _sparse_agrees(system, np.random.default_rng(1))

"""The compiled kernels against the numpy implementation they replace.

Piece by piece, at random configurations: Φ, Φ_q, the normal equations and the Hessian term
built from the sparse arrays equal System.residual / jacobian / residual_hessian (themselves
checked by central differences in tests/test_constraint_derivatives.py and elsewhere), and the
envelope Cholesky solves what numpy's solver solves. Whole solves: NRM through the kernels gives
the numpy path's coordinates to 1e-12 with the same iterations, flags and messages, on the
bundled mechanisms (angles, signed angles, distances), generated trees on fixed and moving
bases, gaps, unsolvable frames, every iteration matrix and warm start, the real gait trial.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from generated_models import build_case, structures
from hypothesis import given
from hypothesis import strategies as st
from test_generated import RATE, T0, reference

from fccgrb_cli.core.errors import InputError
from fccgrb_cli.model import load_model, parse_model
from fccgrb_cli.pipeline.synth import synthesize
from fccgrb_cli.signals.artefact import perturb
from fccgrb_cli.solvers import kernels
from fccgrb_cli.solvers.nrm.solve import NrmSettings, row_weights, solve_nrm
from fccgrb_cli.system import Drive, compile_system
from fccgrb_cli.system.sparse import sparse_of, supported

ROOT = Path(__file__).resolve().parents[1]
MODELS = ROOT / "configs" / "models"
BUNDLED = ("five_bar", "crank_rocker", "slider_crank", "rssr", "slider", "pendulum")
GAIT = ROOT.parent / "shared" / "data" / "c3d" / "Qualisys.c3d"


def mixed(name: str):
    model = load_model(MODELS / f"{name}.yaml")
    return model, compile_system(model, angles="coordinate", track=True)


def dense_jacobian(s, values: np.ndarray, n_rows: int) -> np.ndarray:
    """Φ_q from the CSR values, back in q's column order."""
    J = np.zeros((n_rows, s.nq))
    rows = np.repeat(np.arange(n_rows), np.diff(s.j_ptr))
    np.add.at(J, (rows, s.perm[s.j_col]), values)
    return J


def in_q_order(s, lower: np.ndarray) -> np.ndarray:
    """A symmetric matrix from its lower triangle in the factor's order, back in q's order."""
    full = np.tril(lower) + np.tril(lower, -1).T
    out = np.empty_like(full)
    out[np.ix_(s.perm, s.perm)] = full
    return out


def envelope_mask(s) -> np.ndarray:
    n = s.nq
    cols = np.arange(n)
    return (cols[None, :] >= s.first[:, None]) & (cols[None, :] <= cols[:, None])


@pytest.mark.parametrize("name", BUNDLED)
def test_pieces_equal_the_dense_system(name: str) -> None:
    _, system = mixed(name)
    s = sparse_of(system)
    rng = np.random.default_rng(abs(hash(name)) % 2**32)
    n_rows = system.n_rows
    for _ in range(3):
        q = system.pose() + 0.05 * rng.standard_normal(system.nq)
        ref = rng.standard_normal((system.n_targets, 3))
        w = rng.uniform(0.1, 2.0, n_rows)
        F, phi = np.empty(len(s.f0)), np.empty(n_rows)
        kernels.residual(s, q, q[s.nb:], ref, F, phi)
        phi_dense, J_dense = system.evaluate(q, Drive(ref=ref))
        assert np.abs(phi - phi_dense).max() < 1e-13
        values = np.empty(len(s.j_col))
        kernels.jacobian(s, q, F, values)
        assert np.abs(dense_jacobian(s, values, n_rows) - J_dense).max() < 1e-13

        N, g = np.full((s.nq, s.nq), np.nan), np.empty(s.nq)
        kernels.normal_equations(s, values, phi, w, N, g)
        inside = envelope_mask(s)
        assert np.isfinite(N[inside]).all()  # every entry of the envelope was written
        normal = J_dense.T @ (w[:, None] * J_dense)
        assert np.abs(in_q_order(s, np.where(inside, N, 0.0)) - normal).max() \
            < 1e-12 * np.abs(normal).max()
        assert np.abs(g[np.argsort(s.perm)] - J_dense.T @ (w * phi)).max() < 1e-12
        # the pattern of ΦᵀWΦ lies inside the envelope: nothing outside it is non-zero
        assert np.abs(normal[np.ix_(s.perm, s.perm)][~inside & np.tri(s.nq, dtype=bool)]).max(
            initial=0.0) == 0.0

        c = w * phi
        H = np.where(inside, 0.0, np.nan)
        kernels.add_hessian(s, q, c, H)
        H_dense = system.residual_hessian(q, c)
        assert np.abs(in_q_order(s, np.where(inside, H, 0.0)) - H_dense).max() \
            < 1e-12 * max(np.abs(H_dense).max(), 1e-300)


@given(st.integers(0, 2**32 - 1))
def test_envelope_cholesky_solves(seed: int) -> None:
    _, system = mixed("five_bar")
    s = sparse_of(system)
    rng = np.random.default_rng(seed)
    inside = envelope_mask(s)
    B = np.where(inside, rng.standard_normal((s.nq, s.nq)), 0.0)
    A = B @ B.T + s.nq * np.eye(s.nq)  # SPD; its factor B's envelope is the envelope
    A = np.where(inside, A, 0.0)
    A = np.tril(A) + np.tril(A, -1).T
    rhs = rng.standard_normal(s.nq)
    out, L = np.empty(s.nq), np.zeros((s.nq, s.nq))
    assert kernels.cholesky_solve(s.first, np.tril(A), L, rhs, out)
    assert np.abs(A @ out - rhs).max() < 1e-10 * np.abs(rhs).max()
    indefinite = np.tril(A) - 2 * np.abs(A).max() * np.eye(s.nq)
    assert not kernels.cholesky_solve(s.first, indefinite, L, rhs, out)


def both(system, time, markers, **settings):
    numpy = solve_nrm(system, time, markers, NrmSettings(**settings, engine="numpy"))
    compiled = solve_nrm(system, time, markers, NrmSettings(**settings, engine="compiled"))
    return numpy, compiled


def assert_same(a, b, tol: float = 1e-10) -> None:
    """The two engines' results: the same frames converged, failed and left unsolved, the same
    messages, and where a frame took the same iterations in both, the same coordinates to
    1e-12. Rounding (the kernels sum in another order) may flip a borderline decision — a step
    ratio at exactly the 'auto' switch, a line search at its limit — on a frame that a hard
    start (a rigid-fit guess into P30 noise) drags through tens of iterations; such frames
    (at most 5 %) must still agree to 10 × the tolerance on ‖Δq‖, and a failed frame only in
    being failed."""
    assert (a.converged == b.converged).all()
    assert np.array_equal(np.isnan(a.q), np.isnan(b.q))
    same = a.iterations == b.iterations
    assert same.mean() >= 0.95, np.flatnonzero(~same)
    ok = a.converged
    assert np.abs(a.q[ok & same] - b.q[ok & same]).max(initial=0.0) < 1e-12
    assert np.abs(a.q[ok & ~same] - b.q[ok & ~same]).max(initial=0.0) < 10 * tol
    if same.all():
        assert a.messages == b.messages
    assert np.abs(a.phi_top_max[ok] - b.phi_top_max[ok]).max(initial=0.0) < 1e-12
    assert np.abs(a.phi_norm[ok] - b.phi_norm[ok]).max(initial=0.0) < 1e-10
    if same.all():
        # the rates (kernels.rates_frames against rates.py's LU / QR) where the frame and its
        # neighbours converged (central differences reach one frame each way)
        steady = ok & np.r_[ok[1:], True] & np.r_[True, ok[:-1]]
        for x, y in ((a.qd, b.qd), (a.qdd, b.qdd)):
            assert np.array_equal(np.isnan(x), np.isnan(y))
            assert np.nanmax(np.abs(x[steady] - y[steady]), initial=0.0) \
                <= 1e-10 * np.nanmax(np.abs(x))


@pytest.mark.parametrize("name", BUNDLED)
@pytest.mark.parametrize("level", [0.0, 30e-3])
def test_engines_agree_on_bundled_models(name: str, level: float) -> None:
    model, system = mixed(name)
    truth = synthesize(model)
    markers = perturb(truth.markers, truth.labels, truth.rate, level, seed=3)[:80]
    numpy, compiled = both(system, truth.result.time[:80], markers)
    assert numpy.converged.all()
    assert_same(numpy, compiled)


@pytest.mark.parametrize(("hessian", "warm_start", "weight"), [
    ("gauss-newton", "extrapolate", 1e-3), ("exact", "extrapolate", 1e-3),
    ("auto", "previous", 1e-3), ("auto", "extrapolate", None)])
def test_engines_agree_for_every_setting(hessian: str, warm_start: str, weight) -> None:
    model, system = mixed("five_bar")
    truth = synthesize(model)
    markers = perturb(truth.markers, truth.labels, truth.rate, 15e-3, seed=1)[:60]
    assert_same(*both(system, truth.result.time[:60], markers, hessian=hessian,
                      warm_start=warm_start, tracking_weight=weight))


def test_engines_agree_on_gaps_unsolvable_frames_and_failures() -> None:
    model, system = mixed("five_bar")
    truth = synthesize(model)
    markers = perturb(truth.markers, truth.labels, truth.rate, 7.5e-3, seed=2)[:90].copy()
    time = truth.result.time[:90]
    markers[10:14, 0] = np.nan            # a gap the others can bridge
    index = {label: k for k, label in enumerate(truth.labels)}
    markers[30:33, [index["P5"], index["P6"]]] = np.nan  # nothing left on B5: unsolvable
    markers[50, :] += 0.3                 # a jump that the next frames recover from
    numpy, compiled = both(system, time, markers, skip_unsolvable=True)
    assert numpy.messages and np.isnan(numpy.q[30:33]).all()
    assert_same(numpy, compiled)
    capped = both(system, time, markers, skip_unsolvable=True, max_iter=2)
    assert (~capped[0].converged).sum() > 5  # failures, retries and fresh starts after them
    assert_same(*capped)
    for engine in ("numpy", "compiled"):
        with pytest.raises(InputError, match=r"frame index 30 .*missing: P5, P6"):
            solve_nrm(system, time, markers, NrmSettings(engine=engine),
                      labels=tuple(truth.labels))


@given(structures(floating=False) | structures(floating=True))
def test_engines_agree_on_generated_trees(structure) -> None:
    case = build_case(structure)
    t = T0 + np.arange(24) / RATE
    ref = reference(case, t)
    model = parse_model(case.text, "generated.yaml").with_form("full")
    system = compile_system(model, angles="coordinate", track=True)
    assert supported(system)
    noisy = ref.markers + 0.01 * np.sin(np.arange(24)[:, None, None] * 0.7
                                        + np.arange(ref.markers.shape[1])[None, :, None]
                                        + np.arange(3))
    for markers in (ref.markers, noisy):
        assert_same(*both(system, t, markers, tol=1e-12))


def test_reduced_bodies_stay_on_the_numpy_path() -> None:
    model = load_model(MODELS / "five_bar.yaml").with_form("reduced")
    system = compile_system(model, angles="coordinate", track=True)
    assert not supported(system)
    assert not NrmSettings(engine="auto").compiled(system)
    with pytest.raises(InputError, match="reduced"):
        NrmSettings(engine="compiled").compiled(system)


def test_weights_follow_the_settings() -> None:
    _, system = mixed("five_bar")
    w = row_weights(system, 1e-3)
    assert (w[system.masks()["tracking"]] == 1e-3).all()
    assert (w[system.masks()["topology"]] == 1.0).all()


@pytest.mark.skipif(not GAIT.exists(), reason="the shared data folder is not here")
def test_engines_agree_on_the_gait_trial() -> None:
    from fccgrb_cli.anatomy.calibrate import calibrate
    from fccgrb_cli.pipeline.options import SolveOptions
    from fccgrb_cli.pipeline.solve import solve_trial
    from fccgrb_cli.trial.record import read_trial

    trial = read_trial(GAIT)
    cal = calibrate(load_model(MODELS / "lower_limb.yaml"), trial, mass=67.0)
    model = parse_model(cal.text, "personal.yaml")
    runs = [solve_trial(model, trial, SolveOptions(engine=e, dynamics=False))
            for e in ("numpy", "compiled")]
    assert_same(runs[0].result, runs[1].result)


@given(structures(floating=True), st.integers(0, 20))
def test_compiled_rates_on_moving_bases_and_gaps(structure, gap: int) -> None:
    """rates.py's least squares (a floating base's differenced rates are not exactly rigid)
    and the kernels' normal equations with θ held: the same q̇ and q̈; NaN frames stay NaN."""
    from fccgrb_cli.solvers.rates import central_derivatives, consistent_rates
    from fccgrb_cli.system.constraints import floating_bases

    case = build_case(structure)
    t = T0 + np.arange(24) / RATE
    ref = reference(case, t)
    model = parse_model(case.text, "generated.yaml").with_form("full")
    system = compile_system(model, angles="coordinate", track=True)
    result = solve_nrm(system, t, ref.markers, NrmSettings(engine="numpy"))
    q = result.q.copy()
    q[gap] = np.nan
    layout = system.layout
    columns = np.concatenate([np.arange(layout.n_body_q)[layout.q_slice(b)]
                              for b in floating_bases(model)])
    base = (columns, *central_derivatives(q[:, columns] + 1e-4 * np.sin(t)[:, None],
                                          t[1] - t[0]))
    numpy = consistent_rates(system, q, result.theta_d, result.theta_dd, base)
    compiled = consistent_rates(system, q, result.theta_d, result.theta_dd, base, compiled=True)
    for x, y in zip(numpy, compiled, strict=True):
        assert np.array_equal(np.isnan(x), np.isnan(y)) and np.isnan(x[gap]).all()
        assert np.nanmax(np.abs(x - y)) <= 1e-10 * np.nanmax(np.abs(x))


def assert_same_dynamics(a, b) -> None:
    """The classical model's motion and inverse dynamics from the two engines (LU / QR against
    normal equations on the envelope): equal to rounding, relative to each quantity's size."""
    for name in ("q", "qd", "qdd"):
        x, y = getattr(a.kinematics, name), getattr(b.kinematics, name)
        assert np.nanmax(np.abs(x - y)) <= 1e-10 * np.nanmax(np.abs(x)), name
    assert (a.kinematics.converged == b.kinematics.converged).all()
    for name in ("lam", "joint_moments", "kinetic", "external_power"):
        x, y = getattr(a.inverse, name), getattr(b.inverse, name)
        assert np.nanmax(np.abs(x - y)) <= 1e-9 * max(np.nanmax(np.abs(x)), 1e-12), name
    assert b.inverse.residual.max() <= 1e-9 * np.abs(b.inverse.lam).max()


@pytest.mark.parametrize("name", ["five_bar", "crank_rocker", "slider", "rssr"])
def test_compiled_dynamics_equal_numpy(name: str) -> None:
    from fccgrb_cli.dynamics import ExternalLoad
    from fccgrb_cli.dynamics.convert import classical_dynamics

    model, system = mixed(name)
    truth = synthesize(model)
    markers = perturb(truth.markers, truth.labels, truth.rate, 20e-3, seed=5)[:120]
    result = solve_nrm(system, truth.result.time[:120], markers, NrmSettings())
    rng = np.random.default_rng(1)
    body = model.bodies[-1].name
    push = ExternalLoad("push", body, rng.normal(0, 20, (120, 3)), rng.normal(0, 0.3, (120, 3)),
                        rng.normal(0, 0.05, (120, 3)))
    numpy = classical_dynamics(model, result, cutoff=6.0, loads=[push], engine="numpy")
    compiled = classical_dynamics(model, result, cutoff=6.0, loads=[push], engine="compiled")
    assert compiled.kinematics.converged.all()
    assert_same_dynamics(numpy, compiled)


@given(structures(floating=True))
def test_compiled_dynamics_on_moving_bases(structure) -> None:
    """A floating base's drivers make Φ_q taller than wide: least squares in rates.py and
    min-norm multipliers, normal equations in the kernels."""
    from fccgrb_cli.dynamics.convert import classical_dynamics

    case = build_case(structure)
    t = T0 + np.arange(24) / RATE
    ref = reference(case, t)
    model = parse_model(case.text, "generated.yaml").with_form("full")
    system = compile_system(model, angles="coordinate", track=True)
    result = solve_nrm(system, t, ref.markers, NrmSettings(tol=1e-12))
    assert_same_dynamics(classical_dynamics(model, result, tol=1e-12, engine="numpy"),
                         classical_dynamics(model, result, tol=1e-12, engine="compiled"))


@pytest.mark.skipif(not GAIT.exists(), reason="the shared data folder is not here")
def test_compiled_dynamics_on_the_gait_trial() -> None:
    from fccgrb_cli.anatomy.calibrate import calibrate
    from fccgrb_cli.pipeline.options import SolveOptions
    from fccgrb_cli.pipeline.solve import solve_trial
    from fccgrb_cli.trial.record import read_trial

    trial = read_trial(GAIT)
    cal = calibrate(load_model(MODELS / "lower_limb.yaml"), trial, mass=67.0)
    model = parse_model(cal.text, "personal.yaml")
    runs = [solve_trial(model, trial, SolveOptions(engine=e)) for e in ("numpy", "compiled")]
    assert_same_dynamics(runs[0].dynamics, runs[1].dynamics)
    clinical = [r.clinical.moments for r in runs]
    assert np.nanmax(np.abs(clinical[0] - clinical[1])) <= 1e-9 * np.nanmax(np.abs(clinical[0]))


def test_frames_the_compiled_batch_leaves_take_the_frame_by_frame_path(monkeypatch) -> None:
    """One Newton iteration in the kernels (most frames unconverged) and a frame without a
    guess: they go through solve_ad's own path, and the answers are the sequential ones."""
    from dataclasses import replace

    from fccgrb_cli.dynamics.convert import classical_dynamics
    from fccgrb_cli.solvers.ad import solve as ad

    model, system = mixed("five_bar")
    truth = synthesize(model)
    markers = perturb(truth.markers, truth.labels, truth.rate, 20e-3, seed=5)[:60]
    result = solve_nrm(system, truth.result.time[:60], markers, NrmSettings())
    sequential = classical_dynamics(model, result, cutoff=6.0, batched=False)
    monkeypatch.setattr(ad, "BATCH_ITER", 1)
    holed = result.q.copy()
    holed[7] = np.nan
    compiled = classical_dynamics(model, replace(result, q=holed), cutoff=6.0,
                                  engine="compiled")
    assert (compiled.kinematics.iterations > 1).sum() > 30
    assert_same_dynamics(sequential, compiled)


@pytest.mark.parametrize("form", ["full", "reduced"])
def test_points_along_a_solution_equal_point_positions(form: str) -> None:
    """pipeline.points_along (every frame at once) against System.point_positions frame by
    frame, with a frame left unsolved (NaN)."""
    from fccgrb_cli.pipeline.solve import points_along

    model = load_model(MODELS / "five_bar.yaml").with_form(form)
    truth = synthesize(model)
    system = compile_system(model, angles="coordinate", track=True)
    q = solve_nrm(system, truth.result.time[:12], truth.markers[:12], NrmSettings()).q.copy()
    q[3] = np.nan
    which = [(b.name, p) for b in model.bodies for p in b.points]
    one_by_one = np.array([system.point_positions(qf, which) for qf in q])
    assert np.array_equal(points_along(system, q, which), one_by_one, equal_nan=True)

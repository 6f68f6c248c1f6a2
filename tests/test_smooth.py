"""The whole-trial smoother (fccgrb_cli/solvers/smooth), each part against an independent
oracle:

* the linear smoother (filter.py) against the dense least squares it solves — the state
  sequence's posterior mean, its covariance, and the covariance the noise alone gives L R Lᵀ,
  with L the dense smoother matrix — and its optimality conditions against finite differences
  of the objective; the compiled passes against the numpy ones, gaps and singular frames
  included; the noise-part covariance against a Monte-Carlo over noise draws;
* the scalar likelihood's two engines, the maximum-likelihood cutoff on a process drawn from
  the prior, the marker-noise estimate on residuals with a slow artefact;
* the rotation chart against finite differences of the exponential map;
* the measurement model's Jacobian (a fixed base and a moving floating base) against finite
  differences of the positions solved by Newton–Raphson, and its compiled twin;
* the smoothed five-bar: the constraints to 1e-10 on every frame, the estimated noise, and the
  moments' Jacobian against finite differences of the full inverse dynamics.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_floating_base import moving_text

from fccgrb_cli.dynamics.uncertainty import moment_jacobian, moments_at
from fccgrb_cli.model import parse_model
from fccgrb_cli.pipeline.synth import synthesize
from fccgrb_cli.solvers.smooth import filter as reference
from fccgrb_cli.solvers.smooth import kernels, rotation
from fccgrb_cli.solvers.smooth.coordinates import Coordinates
from fccgrb_cli.solvers.smooth.noise import marker_noise, strength
from fccgrb_cli.solvers.smooth.prior import density, noise_shape, transition
from fccgrb_cli.solvers.smooth.start import initial_state
from fccgrb_cli.solvers.smooth.trial import SmoothSettings, smooth_motion
from fccgrb_cli.system import compile_system


def _dense_problem(chains: reference.Chains, A: np.ndarray, b: np.ndarray):
    """The trial's least squares written out: the precision of every state (frames × np),
    its right-hand side, and the map from the frames' b to it."""
    F, Q, E = reference._dense(chains)
    N, n = b.shape
    m = F.shape[0]
    P0 = reference._blocks(chains.cov0)
    Lam = np.zeros((N * m, N * m))
    rhs = np.zeros(N * m)
    Lam[:m, :m] += np.linalg.inv(P0)
    rhs[:m] += np.linalg.solve(P0, chains.mean0.ravel())
    Qi = np.linalg.inv(Q)
    for f in range(1, N):
        a, c = (f - 1) * m, f * m
        Lam[a:a + m, a:a + m] += F.T @ Qi @ F
        Lam[c:c + m, c:c + m] += Qi
        Lam[a:a + m, c:c + m] -= F.T @ Qi
        Lam[c:c + m, a:a + m] -= Qi @ F
    B = np.zeros((N * m, N * n))
    for f in range(N):
        Lam[f * m:(f + 1) * m, f * m:(f + 1) * m] += E.T @ A[f] @ E
        B[f * m:(f + 1) * m, f * n:(f + 1) * n] = E.T
    return Lam, rhs, B


def _random_case(seed: int = 1, N: int = 30, n: int = 2, order: int = 3, dt: float = 0.1):
    """A small, well-conditioned problem: random information per frame, a gap, a frame that
    fixes one combination of the coordinates only."""
    rng = np.random.default_rng(seed)
    chains = reference.Chains.build(order, dt, np.array([5.0, 8.0])[:n],
                                    np.array([3.0, 50.0])[:n], rng.normal(size=(n, order)) * 0.1,
                                    np.array([np.eye(order) * 5.0] * n))
    A, b = np.zeros((N, n, n)), np.zeros((N, n))
    for f in range(N):
        if f in (7, 8, 20):
            continue
        H = rng.normal(size=(4, n))
        A[f] = H.T @ H * 100
        if f == 12:
            A[f] = np.outer([1.0, 0.5], [1.0, 0.5])[:n, :n] * 100
        b[f] = A[f] @ np.array([np.sin(3 * f * dt), np.cos(2 * f * dt)])[:n] + rng.normal(size=n)
    return chains, A, b


def test_linear_smoother_is_the_dense_least_squares() -> None:
    chains, A, b = _random_case()
    out = reference.smooth(chains, A, b, covariance=True, posterior=True)
    Lam, rhs, B = _dense_problem(chains, A, b)
    post = np.linalg.inv(Lam)
    mean = post @ (rhs + B @ b.ravel())
    L = post @ B
    noise = np.zeros((B.shape[1], B.shape[1]))
    for f in range(len(A)):
        n = b.shape[1]
        noise[f * n:(f + 1) * n, f * n:(f + 1) * n] = A[f]  # Cov(b_f) = A_f
    Xi = L @ noise @ L.T
    m = chains.n * chains.order
    out_idx, unscale = chains.outputs(), chains.unscale()
    for f in range(len(A)):
        idx = f * m + out_idx
        v = (mean[idx] * unscale).reshape(3, -1)
        np.testing.assert_allclose(out.values[f], v, rtol=1e-9, atol=1e-9 * np.abs(v).max())
        for got, want in ((out.covariance[f], Xi[np.ix_(idx, idx)]),
                          (out.posterior[f], post[np.ix_(idx, idx)])):
            want = want * np.outer(unscale, unscale)
            np.testing.assert_allclose(got, want, atol=1e-8 * np.abs(want).max())


def test_smoothed_states_solve_the_normal_equations() -> None:
    """The MAP objective's gradient, by central differences, vanishes at the smoother's state
    sequence (all p parts of every frame), and not at a perturbed one."""
    chains, A, b = _random_case(seed=3, N=12)
    F, Q, E = reference._dense(chains)
    P0, Qi = reference._blocks(chains.cov0), np.linalg.inv(Q)
    m = F.shape[0]

    def objective(X: np.ndarray) -> float:
        X = X.reshape(len(A), m)
        e0 = X[0] - chains.mean0.ravel()
        total = e0 @ np.linalg.solve(P0, e0)
        for f in range(1, len(A)):
            w = X[f] - F @ X[f - 1]
            total += w @ Qi @ w
        for f in range(len(A)):
            d = E @ X[f]
            total += d @ A[f] @ d - 2 * b[f] @ d
        return 0.5 * total

    Lam, rhs, B = _dense_problem(chains, A, b)
    X = np.linalg.solve(Lam, rhs + B @ b.ravel())
    got = reference.smooth(chains, A, b, covariance=False).values
    np.testing.assert_allclose(got.reshape(len(A), -1),
                               (X.reshape(len(A), m)[:, chains.outputs()] * chains.unscale()),
                               rtol=1e-9, atol=1e-9)

    def gradient(X: np.ndarray) -> np.ndarray:
        h = 1e-6
        g = np.empty_like(X)
        for i in range(len(X)):
            e = np.zeros_like(X)
            e[i] = h
            g[i] = (objective(X + e) - objective(X - e)) / (2 * h)
        return g

    scale = np.abs(gradient(X + 1e-3)).max()
    assert np.abs(gradient(X)).max() < 1e-6 * scale


def test_compiled_passes_equal_numpy() -> None:
    chains, A, b = _random_case(seed=5, N=40, order=5, dt=0.02)
    want = reference.smooth(chains, A, b, covariance=True)
    n = b.shape[1]
    values, cov = np.empty((len(A), 3 * n)), np.empty((len(A), 3 * n, 3 * n))
    kernels.smooth_passes(chains.arrays(), A, b, True,
                          values, cov)
    unscale = chains.unscale()
    np.testing.assert_allclose((values * unscale).reshape(want.values.shape), want.values,
                               atol=1e-9 * np.abs(want.values).max())
    np.testing.assert_allclose(cov * np.outer(unscale, unscale), want.covariance,
                               atol=1e-7 * np.abs(want.covariance).max())


def test_noise_part_covariance_matches_monte_carlo() -> None:
    """Draws of the frames' noise (Cov b_f = A_f) through the linear smoother: the outputs'
    scatter matches the covariance step 3 computes (and not the posterior, which is larger)."""
    rng = np.random.default_rng(11)
    N, n, order, dt = 60, 2, 4, 0.02
    chains = reference.Chains.build(order, dt, np.array([20.0, 30.0]), np.array([1e3, 3e3]),
                                    np.zeros((n, order)), np.array([np.eye(order) * 1e2] * n))
    A = np.array([np.diag([1e4, 2e4]) + 5e3 for _ in range(N)])
    A[25:28] = 0.0
    clean = np.zeros((N, n))
    out = reference.smooth(chains, A, clean, covariance=True, posterior=True)
    draws = []
    for _ in range(400):
        b = np.einsum("fij,fj->fi", np.linalg.cholesky(A + 1e-300 * np.eye(n)),
                      rng.normal(size=(N, n)))
        b[25:28] = 0.0
        v = np.empty((N, 3 * n))
        kernels.smooth_passes(chains.arrays(), A, b,
                              False, v, np.empty((0, 3 * n, 3 * n)))
        draws.append(v * chains.unscale())
    empirical = np.var(np.array(draws), axis=0)
    predicted = np.diagonal(out.covariance, axis1=1, axis2=2)
    ratio = np.median(empirical / predicted, axis=0)
    assert np.all(np.abs(ratio - 1) < 0.15), ratio
    posterior = np.diagonal(out.posterior, axis1=1, axis2=2)
    assert np.median(posterior[:, 2 * n:] / predicted[:, 2 * n:]) > 1.3


def test_likelihood_engines_agree_and_find_the_cutoff() -> None:
    """A process drawn from the prior with cutoff 4 Hz (at 200 Hz), observed with noise: both
    engines give the same likelihood, and its maximum lies within 25 % of 4 Hz."""
    rng = np.random.default_rng(2)
    order, dt, N, r, fc = 5, 0.005, 1500, 1e-6, 4.0
    omega = 2 * np.pi * fc
    F, C = transition(order, dt, omega), noise_shape(order, dt, omega)
    q = density(fc, r, dt, order)
    x = np.zeros(order)
    x[0] = 1.0
    L = np.linalg.cholesky(q * C + 1e-30 * np.eye(order))
    z = np.empty(N)
    for f in range(N):
        x = F @ x + L @ rng.normal(size=order)
        z[f] = x[0] + np.sqrt(r) * rng.normal()
    time = np.arange(N) * dt
    var = np.full(N, r)
    var[100:110] = np.inf
    mean0, cov0 = initial_state(time, z, var, order, omega)
    Q = q * C
    a = reference.log_likelihood(z, var, F, Q, mean0, cov0, order)
    k = kernels.log_likelihood(z, var, F, Q, mean0, cov0, order)
    assert abs(a - k) < 1e-9 * abs(a)
    found = strength(time, z, var, kernels.log_likelihood)
    assert abs(found.cutoff / fc - 1) < 0.25
    assert found.extra < 0.2 * r


def test_marker_noise_from_residuals_ignores_a_slow_artefact() -> None:
    rng = np.random.default_rng(4)
    frames, rows, sigma = 2000, 30, 7e-4
    t = np.arange(frames) / 200
    leverage = np.full((frames, rows), 0.3)
    residuals = (np.sqrt(1 - leverage) * rng.normal(size=(frames, rows)) * sigma
                 + 5e-3 * np.sin(2 * np.pi * 1.3 * t)[:, None])
    residuals[500:520, 3] = np.nan
    residuals[1000, 7] = 0.05  # a spike
    assert abs(marker_noise(residuals, leverage) / sigma - 1) < 0.05


def test_rotation_chart_derivatives() -> None:
    rng = np.random.default_rng(7)
    for scale in (1e-6, 0.3, 2.5):
        phi = rng.normal(size=3)
        phi *= scale / np.linalg.norm(phi)
        v = rng.normal(size=3)
        R = rotation.exp_map(phi)
        np.testing.assert_allclose(rotation.exp_map(rotation.log_map(R)), R, atol=1e-12)
        h = 1e-6
        dR = (rotation.exp_map(phi + h * v) - rotation.exp_map(phi - h * v)) / (2 * h)
        omega = rotation.left_jacobian(phi) @ v
        np.testing.assert_allclose(dR @ R.T, rotation.skew(omega), atol=1e-8)

        rate = (rotation.left_jacobian(phi + h * v) @ v
                - rotation.left_jacobian(phi - h * v) @ v) / (2 * h)
        np.testing.assert_allclose(rotation.jacobian_rate(phi, v), rate, atol=1e-7)


def _five_bar(rate: float = 200.0, duration: float = 0.6):
    from fccgrb_cli.model import load_model

    model = load_model("configs/models/five_bar.yaml")
    return model, synthesize(model, duration=duration, rate=rate)


@pytest.mark.parametrize("floating", [False, True])
def test_marker_jacobian_against_finite_differences(floating: bool) -> None:
    if floating:
        model = parse_model(moving_text(), "moving.yaml")
        synth = synthesize(model, duration=0.3, rate=100)
    else:
        model, synth = _five_bar(duration=0.15)
    system = compile_system(model, angles="driver")
    q = np.concatenate([synth.result.q, synth.result.theta], axis=1)
    co = Coordinates.build(system, q, np.arange(len(q)))
    d = co.from_mixed(q)
    lin = co.linearize(d, synth.result.q)
    np.testing.assert_allclose(lin.points, synth.markers, atol=1e-12)
    for k in range(co.n):
        h = 1e-6
        step = np.zeros_like(d)
        step[:, k] = h
        fd = (co.markers(co.positions(d + step, lin.q))
              - co.markers(co.positions(d - step, lin.q))) / (2 * h)
        np.testing.assert_allclose(lin.H[:, :, k], fd.reshape(len(d), -1), atol=1e-8)
    compiled = co.linearize(d, synth.result.q, compiled=True)
    for a, b in ((compiled.q, lin.q), (compiled.S, lin.S), (compiled.H, lin.H)):
        np.testing.assert_allclose(a, b, atol=1e-12)


def test_smoothed_five_bar_keeps_the_constraints_and_finds_the_noise() -> None:
    model, synth = _five_bar()
    rng = np.random.default_rng(0)
    markers = synth.markers + rng.normal(scale=1e-3, size=synth.markers.shape)
    from fccgrb_cli.solvers.nrm.solve import NrmSettings, solve_nrm

    mixed = compile_system(model, angles="coordinate", track=True)
    time = synth.result.time
    nrm = solve_nrm(mixed, time, markers, NrmSettings())
    system = compile_system(model, angles="driver")
    motion = smooth_motion(system, time, markers, np.ones(len(time), bool), nrm.q,
                           SmoothSettings())
    assert abs(motion.noise / 1e-3 - 1) < 0.1
    drives = motion.coordinates.drives(motion.d)
    for f in range(len(time)):
        phi = system.residual(motion.q[f], drives.frame(f))
        assert np.abs(phi).max() < 1e-10
    truth = synth.result.theta
    raw = np.abs(nrm.theta - truth).mean()
    assert np.abs(motion.d - truth).mean() < 0.7 * raw


def test_weighted_markers_have_their_own_noise() -> None:
    """A model that weighs its markers says a marker of weight w has noise σ/√w: markers
    drawn with exactly that noise give σ back (the weight-1 markers'), and the weighted
    smoother lands nearer the true motion than the one that takes every marker alike."""
    model, synth = _five_bar()
    weights = (1.0, 1.0, 0.04, 1.0, 0.04, 1.0, 0.04, 1.0, 0.04)
    rng = np.random.default_rng(5)
    sigma = 1e-3 / np.sqrt(np.array(weights))[None, :, None]
    markers = synth.markers + rng.normal(size=synth.markers.shape) * sigma
    from fccgrb_cli.solvers.nrm.solve import NrmSettings, solve_nrm

    time = synth.result.time
    nrm = solve_nrm(compile_system(model, angles="coordinate", track=True), time, markers,
                    NrmSettings())
    system = compile_system(model, angles="driver")
    use = np.ones(len(time), bool)
    weighted = smooth_motion(system, time, markers, use, nrm.q, SmoothSettings(weights=weights))
    alike = smooth_motion(system, time, markers, use, nrm.q, SmoothSettings())
    assert abs(weighted.noise / 1e-3 - 1) < 0.1
    truth = synth.result.theta
    error = {k: np.sqrt(np.mean((m.d - truth) ** 2)) for k, m in (("weighted", weighted),
                                                                    ("alike", alike))}
    assert error["weighted"] < 0.8 * error["alike"], error


def test_moment_jacobian_against_full_finite_differences() -> None:
    """T = ∂τ/∂(d, ḋ, d̈) against central differences of the moments with the positions
    solved afresh (Newton) at every perturbed d."""
    model, synth = _five_bar(duration=0.05)
    system = compile_system(model, angles="driver")
    q = np.concatenate([synth.result.q, synth.result.theta], axis=1)
    co = Coordinates.build(system, q, np.arange(len(q)))
    d, d_d, d_dd = synth.result.theta, synth.result.theta_d, synth.result.theta_dd
    lin = co.linearize(d, synth.result.q)
    T = moment_jacobian(co, lin.q, lin.S, d, d_d, d_dd)
    scale = np.abs(T).max(axis=(0, 1))
    for j, h in ((0, 1e-5), (1, 1e-3), (2, 1e-2)):
        for k in range(co.n):
            args = [d.copy(), d_d.copy(), d_dd.copy()]
            plus, minus = [a.copy() for a in args], [a.copy() for a in args]
            plus[j][:, k] += h
            minus[j][:, k] -= h
            fd = (moments_at(co, co.positions(plus[0], lin.q), *plus)
                  - moments_at(co, co.positions(minus[0], lin.q), *minus)) / (2 * h)
            col = j * co.n + k
            assert np.abs(T[:, :, col] - fd).max() < 1e-5 * max(scale[col], 1.0)


def test_trial_smoother_is_stationary_for_the_nonlinear_objective() -> None:
    """The whole-trial smoother's answer (Gauss–Newton on the nonlinear markers) is a
    stationary point of the MAP objective: the prior's quadratic plus ½ Σ_f ‖y_f − p(d_f)‖²/σ²,
    p the markers of the positions solved afresh by Newton–Raphson at each d. One Gauss–Newton
    step from it — the markers' Jacobian by central differences of p (not the code's H), the
    linear problem solved by the reference smoother, itself checked against the dense normal
    equations above — moves none of d, ḋ, d̈: the gradient vanishes there. (The dense normal
    equations of this trial are too stiff to evaluate the gradient itself: Q⁻¹ ~ 10¹⁸ at
    200 Hz.)"""
    from fccgrb_cli.solvers.nrm.solve import NrmSettings, solve_nrm
    from fccgrb_cli.solvers.smooth import trial

    model, synth = _five_bar(duration=0.15)
    rng = np.random.default_rng(8)
    markers = synth.markers + rng.normal(scale=1e-3, size=synth.markers.shape)
    time = synth.result.time
    nrm = solve_nrm(compile_system(model, angles="coordinate", track=True), time, markers,
                    NrmSettings())
    system = compile_system(model, angles="driver")
    use = np.ones(len(time), bool)
    motion = trial.smooth_motion(system, time, markers, use, nrm.q, SmoothSettings(noise=1e-3))
    assert not motion.extra_sd.any()  # the objective below has no coordinate noise
    co, sigma, d = motion.coordinates, motion.noise, motion.d
    # the prior the smoother built at its first linearization (the frames' own solutions)
    data = trial._Data(co, time, markers, np.ones((len(time), markers.shape[1] * 3)),
                       trial._passes("numpy"), False)
    _, A0, b0, _ = trial._linearized(data, slice(None), co.from_mixed(nrm.q),
                                     nrm.q[:, :system.layout.n_body_q], sigma)
    chains = trial._chains(time, A0, b0, motion.strengths)
    N, n = d.shape
    q = co.positions(d, motion.q)
    r = (markers - co.markers(q)).reshape(N, -1)
    H = np.empty((N, r.shape[1], n))
    h = 1e-6
    for k in range(n):
        step = np.zeros_like(d)
        step[:, k] = h
        H[:, :, k] = (co.markers(co.positions(d + step, q))
                      - co.markers(co.positions(d - step, q))).reshape(N, -1) / (2 * h)
    A = np.einsum("fri,frj->fij", H, H) / sigma**2
    b = np.einsum("fri,fr->fi", H, r) / sigma**2 + np.einsum("fij,fj->fi", A, d)
    step = reference.smooth(chains, A, b, covariance=False).values
    for j, smoothed in enumerate((d, motion.d_d, motion.d_dd)):
        moved = np.abs(step[:, j] - smoothed).max()
        assert moved < 1e-6 * np.abs(smoothed).max(), (j, moved)


def test_a_coordinates_own_noise_adds_to_its_information() -> None:
    """with_extra_noise against the covariance sum it stands for: a frame whose estimate
    z = A⁻¹ b also carries white noise Σ on the coordinates carries information (A⁻¹ + Σ)⁻¹
    and (A⁻¹ + Σ)⁻¹ z; and where A is singular, the limit of that as A's null space fills."""
    from fccgrb_cli.solvers.smooth.trial import with_extra_noise

    rng = np.random.default_rng(12)
    H = rng.normal(size=(5, 7, 3))
    A = np.einsum("fri,frj->fij", H, H)
    b = rng.normal(size=(5, 3))
    extra = np.array([0.3, 0.0, 2.0])
    A_new, b_new = with_extra_noise(A, b, extra)
    want = np.linalg.inv(np.linalg.inv(A) + np.diag(extra))
    np.testing.assert_allclose(A_new, want, rtol=1e-10)
    z = np.linalg.solve(A, b[..., None])[..., 0]
    np.testing.assert_allclose(b_new, np.einsum("fij,fj->fi", want, z), rtol=1e-10)
    H[:, :, 2] = H[:, :, 0] + H[:, :, 1]
    singular = np.einsum("fri,frj->fij", H, H)  # rank two
    got, _ = with_extra_noise(singular, b, extra)
    near = np.linalg.inv(np.linalg.inv(singular + 1e-9 * np.eye(3)) + np.diag(extra))
    np.testing.assert_allclose(got, near, atol=1e-6 * np.abs(near).max())


def test_likelihood_finds_a_coordinates_own_noise() -> None:
    """A process drawn from the prior (4 Hz at 200 Hz) whose frame estimates carry white noise
    of 10 times the variance their stated one says: the maximum likelihood keeps that extra
    noise (within 40 %) and the cutoff (within 25 %)."""
    rng = np.random.default_rng(6)
    order, dt, N, r, fc = 5, 0.005, 2000, 1e-6, 4.0
    omega = 2 * np.pi * fc
    F, C = transition(order, dt, omega), noise_shape(order, dt, omega)
    L = np.linalg.cholesky(density(fc, 11 * r, dt, order) * C + 1e-30 * np.eye(order))
    x = np.zeros(order)
    z = np.empty(N)
    for f in range(N):
        x = F @ x + L @ rng.normal(size=order)
        z[f] = x[0] + np.sqrt(11 * r) * rng.normal()
    found = strength(np.arange(N) * dt, z, np.full(N, r), kernels.log_likelihood)
    assert abs(found.extra / (10 * r) - 1) < 0.4
    assert abs(found.cutoff / fc - 1) < 0.25

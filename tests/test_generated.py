"""Generated models against independent oracles: random open trees of 2–6 bodies,
every joint type (spherical, revolute, universal, cylindrical, prismatic, parallel), fixed and
floating bases (the floating root translating and turning with non-zero acceleration), random
geometry, full inertia tensors with off-centre centres of mass, random smooth motions of every
joint variable (tests/generated_models.py writes each case as YAML, loaded like a user's file).

The truth is the test's own (tests/rne.py): forward kinematics and a recursive Newton–Euler in
its own frames and formulas, the package's coordinates θ(φ) and their rates by the chain rule,
joint forces mapped to them through (∂θ/∂φ)⁻ᵀ. The oracle is first checked on its own (rates
against central differences in time, power balance of its Newton–Euler against the rate of its
own energy). Then:

* the classical path: solve_ad driven by the exact θ, θ̇, θ̈ (and the base's exact motion),
  inverse_dynamics: coordinates, rates, joint moments, the base's residual wrench, energies and
  power balance, all ≤ 1e-8 relative;
* the mixed-coordinate path (NRM-WLS on the exact markers, then classical_dynamics): θ and
  positions exact; for a fixed base q̇, q̈ and the joint moments equal the test's own
  kinematics and Newton–Euler fed with the rates the MC path can know (central differences of
  the solved θ), ≤ 1e-8 relative: exact by construction; for a floating base, whose rates come
  from central differences of its coordinates projected on rigid motions, within the
  central-difference error bound stated at RATE below;
* every kinematic method at P0 recovers the truth: angles and positions, q̇ and q̈ within the
  central-difference bound, no failed frame, topological violation ≤ 1e-9;
* tracked vectors (TOC) through the pipeline recover the truth, and the same model with
  ``from``/``to`` swapped does not (the direction is pinned).

Cases per CI run (profile ``ci`` in tests/conftest.py, max_examples = 25): see the settings of
each test; the featured cases put every joint type on a fixed and on a floating base in every
run.
"""

from __future__ import annotations

import numpy as np
import pytest
from generated_models import Case, Structure, build_case, structures
from hypothesis import given, settings
from hypothesis import strategies as st
from rne import Reference, coordinate_jacobian, coordinates, forward, phi_motion, reference
from yaml import safe_dump

from fccgrb_cli.dynamics import ExternalLoad, inverse_dynamics
from fccgrb_cli.dynamics.convert import classical_dynamics
from fccgrb_cli.model import parse_model
from fccgrb_cli.pipeline.options import SolveOptions
from fccgrb_cli.pipeline.solve import solve_trial
from fccgrb_cli.pipeline.synth import base_trajectory
from fccgrb_cli.solvers import solve_ad
from fccgrb_cli.solvers.ad.baseline import solve_baseline
from fccgrb_cli.solvers.ad.solve import stacked_drives
from fccgrb_cli.solvers.nrm.solve import NrmSettings, solve_nrm
from fccgrb_cli.solvers.optimize.solve import Settings, solve_optimization
from fccgrb_cli.system import compile_system
from fccgrb_cli.trial.record import Trial

EXAMPLES = settings().max_examples   # the active profile's (ci: 25, long: 250)


def scaled(share: float) -> settings:
    return settings(max_examples=max(1, round(EXAMPLES * share)))


BASES = ("fixed", "floating")
# Every joint type on both bases, serial and branched, in every run.
FEATURED = (
    Structure((-1, 0, 1, 2, 3, 4),
              ("revolute", "spherical", "universal", "cylindrical", "prismatic", "parallel"),
              "full", 11),
    Structure((-1, 0, 0, 1, 1, 2),
              (None, "parallel", "prismatic", "cylindrical", "universal", "spherical"),
              "reduced", 12),
    Structure((-1, 0, 1, 0), (None, "revolute", "spherical", "universal"), "full", 13),
    Structure((-1, 0, 1, 0, 3), (None, "line", "universal", "line", "spherical"), "full", 14),
)
FEATURED_IDS = ("fixed-all-joints", "floating-branched", "floating-serial", "floating-line")

# Sampling of the mixed-coordinate runs. Every motion term is at most 1.5 Hz; the three-point
# central difference of sin(ωt) errs by (ωh)²/6 of its amplitude·ω in the first derivative and
# (ωh)²/12 of amplitude·ω² in the second; at 200 Hz, (2π·1.5/200)² = 2.2e-3.
RATE = 200.0
T0 = 0.35                            # s: not a special instant of any motion


def rel(actual: np.ndarray, expected: np.ndarray) -> float:
    """Largest error relative to the largest expected magnitude (at least 1)."""
    return float(np.abs(actual - expected).max() / max(1.0, np.abs(expected).max()))


def central(y: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Textbook central differences along axis 0: three-point stencils inside, second-order
    one-sided stencils at both ends (the rates the mixed-coordinate path can know)."""
    d1, d2 = np.empty_like(y), np.empty_like(y)
    d1[1:-1] = (y[2:] - y[:-2]) / (2 * dt)
    d2[1:-1] = (y[2:] - 2 * y[1:-1] + y[:-2]) / dt**2
    d1[0] = (-3 * y[0] + 4 * y[1] - y[2]) / (2 * dt)
    d1[-1] = (3 * y[-1] - 4 * y[-2] + y[-3]) / (2 * dt)
    d2[0] = (2 * y[0] - 5 * y[1] + 4 * y[2] - y[3]) / dt**2
    d2[-1] = (2 * y[-1] - 5 * y[-2] + 4 * y[-3] - y[-4]) / dt**2
    return d1, d2


def body_q(layout, model, x: np.ndarray) -> np.ndarray:
    """The package's body coordinates (q order) from the test's [r, u, v, w] per body."""
    q = np.zeros((len(x), layout.n_body_q))
    for i, body in enumerate(model.bodies):
        sl = layout.q_slice(body.name)
        q[:, sl] = x[:, i, : sl.stop - sl.start]
    return q


def base_drive(case: Case, ref: Reference) -> tuple[np.ndarray, ...] | None:
    """A floating root's r, u, v (, w) and their exact rates, as solve_ad takes them."""
    if not case.floating:
        return None
    n = 4 if case.structure.form == "full" else 3
    return tuple(a[:, 0, : 3 * n].reshape(len(ref.time), n, 3) for a in (ref.x, ref.xd, ref.xdd))


def load_of(case: Case, ref: Reference) -> ExternalLoad:
    force, moment = case.load(ref.time)
    return ExternalLoad("push", case.bodies[case.load_body].name, force, ref.load_point, moment)


def rates_known(case: Case, t: np.ndarray, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """φ̇, φ̈ whose θ̇, θ̈ are the central differences of θ: θ̇ = (∂θ/∂φ) φ̇ and
    θ̈ = (∂θ/∂φ) φ̈ + θ̈|φ̈=0, at the exact φ."""
    thd, thdd = central(theta, t[1] - t[0])
    phi = phi_motion(case, t)[0]
    phid, phidd = np.zeros_like(phi), np.zeros_like(phi)
    zero = np.zeros(case.n_phi)
    for f, tf in enumerate(t):
        jac = coordinate_jacobian(case, forward(case, tf, phi[f], zero, zero))
        phid[f] = np.linalg.solve(jac, thd[f])
        bias = coordinates(case, forward(case, tf, phi[f], phid[f], zero))[2]
        phidd[f] = np.linalg.solve(jac, thdd[f] - bias)
    return phid, phidd


# --- the oracle on its own ------------------------------------------------------------------

@pytest.mark.parametrize("base", BASES)
@scaled(1.0)
@given(data=st.data())
def test_oracle_is_consistent(base: str, data: st.DataObject) -> None:
    """The test's rates against 4th-order central differences of its positions in time, θ(φ)
    well posed, and its Newton–Euler against its own energy: Σ τ θ̇ + base wrench power +
    external power = d(T + V)/dt (T, V and their exact rate are independent of the backward
    pass); a floating base's wrench is Newton's law for the whole tree."""
    case = build_case(data.draw(structures(base == "floating")))
    t = np.array([0.21, 0.83, 1.67])
    ref = reference(case, t)
    h, steps, weights = 1e-3, (-2, -1, 1, 2), np.array([1, -8, 8, -1]) / 12
    shifted = [reference(case, t + k * h) for k in steps]
    assert rel(sum(w * s.x for w, s in zip(weights, shifted, strict=True)) / h, ref.xd) < 1e-7
    assert rel(sum(w * s.xd for w, s in zip(weights, shifted, strict=True)) / h, ref.xdd) < 1e-6
    theta_fd = sum(w * s.theta[:, 0] for w, s in zip(weights, shifted, strict=True)) / h
    assert rel(theta_fd, ref.theta[:, 1]) < 1e-7
    energy_fd = sum(w * (s.kinetic + s.potential)
                    for w, s in zip(weights, shifted, strict=True)) / h
    assert rel(energy_fd, ref.energy_rate) < 1e-6
    supplied = np.einsum("fk,fk->f", ref.tau, ref.theta[:, 1]) + ref.base_power + ref.ext_power
    assert rel(supplied, ref.energy_rate) < 1e-12
    angles = ref.theta[:, 0, [c.kind == "angle" for c in case.coordinates]]
    assert ((angles > 0.0) & (angles < np.pi)).all()
    assert ref.cond.max() < 1e3
    if case.floating:
        masses = np.array([b.mass for b in case.bodies])
        # Σ m (a_G − g) − F_ext from the CoM accelerations alone
        a_g = sum(masses[i] * (reference_com_acc(case, t, i) - case.gravity)
                  for i in range(len(case.bodies)))
        assert rel(ref.base_force, a_g - case.load(t)[0]) < 1e-12


def reference_com_acc(case: Case, t: np.ndarray, i: int) -> np.ndarray:
    phi, phid, phidd = phi_motion(case, t)
    return np.array([forward(case, tf, phi[f], phid[f], phidd[f])[i].point(case.bodies[i].com)[2]
                     for f, tf in enumerate(t)])


# --- the classical path ---------------------------------------------------------------------

def check_classical(structure: Structure) -> None:
    case = build_case(structure)
    t = np.linspace(0.0, 2.0, 9)
    ref = reference(case, t)
    model = parse_model(case.text, "generated.yaml")
    system = compile_system(model, angles="driver")
    layout = system.layout
    base = base_drive(case, ref)
    if base is not None:   # the model file's base motion, as the package reads it
        for mine, theirs in zip(base, base_trajectory(model, t), strict=True):
            assert rel(theirs, mine) < 1e-12
    th = ref.theta
    result = solve_ad(system, t, stacked_drives(system, th[:, 0], th[:, 1], th[:, 2], base),
                      body_q(layout, model, ref.x)[0], tol=1e-12)
    assert result.converged.all()
    assert rel(result.q, body_q(layout, model, ref.x)) < 1e-10
    assert rel(result.qd, body_q(layout, model, ref.xd)) < 1e-9
    assert rel(result.qdd, body_q(layout, model, ref.xdd)) < 1e-9
    inv = inverse_dynamics(system, result, [load_of(case, ref)])
    assert inv.angle_names == tuple(c.name for c in case.coordinates)
    assert np.abs(ref.tau).max() > 1.0
    assert rel(inv.joint_moments, ref.tau) < 1e-8, np.abs(inv.joint_moments - ref.tau).max(axis=0)
    assert rel(inv.kinetic, ref.kinetic) < 1e-10 and rel(inv.potential, ref.potential) < 1e-10
    base_power = np.zeros(len(t))
    if case.floating:
        assert inv.base_names == ("B0",)
        assert rel(inv.residual_force[:, 0], ref.base_force) < 1e-8
        assert rel(inv.residual_moment[:, 0], ref.base_moment) < 1e-8
        v, w = ref.xd[:, 0, :3], np.array([_omega(x, xd) for x, xd in zip(ref.x, ref.xd,
                                                                          strict=True)])
        base_power = (np.einsum("fi,fi->f", inv.residual_force[:, 0], v)
                      + np.einsum("fi,fi->f", inv.residual_moment[:, 0], w))
    else:
        assert inv.residual_force is None
    supplied = (np.einsum("fk,fk->f", inv.joint_moments, th[:, 1]) + base_power
                + inv.external_power)
    assert rel(inv.external_power, ref.ext_power) < 1e-10
    assert rel(supplied, ref.energy_rate) < 1e-8


def _omega(x: np.ndarray, xd: np.ndarray) -> np.ndarray:
    """ω of the root body from its u, v, w and their rates: ω = ½ Σ e × ė."""
    e, ed = x[0, 3:].reshape(3, 3), xd[0, 3:].reshape(3, 3)
    return 0.5 * np.cross(e, ed).sum(axis=0)


@pytest.mark.parametrize("structure", FEATURED, ids=FEATURED_IDS)
def test_classical_path_featured(structure: Structure) -> None:
    check_classical(structure)


@pytest.mark.parametrize("base", BASES)
@scaled(1.0)
@given(data=st.data())
def test_classical_path_matches_newton_euler(base: str, data: st.DataObject) -> None:
    """solve_ad + inverse_dynamics on the exact motion: q, q̇, q̈, joint moments (N·m, N),
    the base's residual wrench, energies and power balance against the test's oracle."""
    check_classical(data.draw(structures(base == "floating")))


# --- the mixed-coordinate path --------------------------------------------------------------

def truth_rate_errors(ref: Reference) -> tuple[float, float]:
    """The largest error of the central differences of the exact body coordinates at the
    sampling rate (first, second derivative): what differenced rates can be trusted to."""
    dt = ref.time[1] - ref.time[0]
    d1, d2 = central(ref.x, dt)
    return float(np.abs(d1 - ref.xd).max()), float(np.abs(d2 - ref.xdd).max())


def check_rates(case: Case, layout, model, result, ref: Reference, position_error: float
                ) -> None:
    """q̇, q̈ of a mixed-coordinate result against the exact ones: within three times what
    central differences of the exact coordinates miss at this rate, plus what the solver's own
    position error ε becomes once differenced (ε/h, 4ε/h²)."""
    n_body = layout.n_body_q
    dt = ref.time[1] - ref.time[0]
    e1, e2 = truth_rate_errors(ref)
    assert e1 < 3e-3 * np.abs(ref.xd).max() and e2 < 1e-2 * np.abs(ref.xdd).max()  # (ωh)² small
    err_d = np.abs(result.qd[:, :n_body] - body_q(layout, model, ref.xd)).max()
    err_dd = np.abs(result.qdd[:, :n_body] - body_q(layout, model, ref.xdd)).max()
    assert err_d <= 3 * e1 + position_error / dt, (err_d, e1)
    assert err_dd <= 3 * e2 + 4 * position_error / dt**2, (err_dd, e2)


def check_mixed(structure: Structure) -> None:
    case = build_case(structure)
    t = T0 + np.arange(24) / RATE
    ref = reference(case, t)
    model = parse_model(case.text, "generated.yaml")
    system = compile_system(model, angles="coordinate", track=True)
    layout = system.layout
    result = solve_nrm(system, t, ref.markers, NrmSettings(tol=1e-12))
    assert result.converged.all()
    assert np.abs(result.theta - ref.theta[:, 0]).max() < 1e-9
    assert np.abs(result.q[:, : layout.n_body_q] - body_q(layout, model, ref.x)).max() < 1e-9
    check_rates(case, layout, model, result, ref, 1e-9)
    dynamics = classical_dynamics(model, result, loads=[load_of(case, ref)], tol=1e-12)
    inv = dynamics.inverse
    known = reference(case, t, rates_known(case, t, result.theta))
    if not case.floating:
        # exact by construction: the test's kinematics and Newton–Euler fed with the central
        # differences of the solved θ
        n_body = layout.n_body_q
        assert rel(result.qd[:, :n_body], body_q(layout, model, known.xd)) < 1e-8
        assert rel(result.qdd[:, :n_body], body_q(layout, model, known.xdd)) < 1e-8
        assert rel(inv.joint_moments, known.tau) < 1e-8, \
            np.abs(inv.joint_moments - known.tau).max(axis=0)
        return
    # a floating base's rates are differenced from its coordinates (then made rigid): the
    # joint moments and the base's wrench within three times the relative error of the
    # differenced accelerations
    e2 = truth_rate_errors(ref)[1] / np.abs(ref.xdd).max()
    assert rel(inv.joint_moments, known.tau) < 3 * e2
    assert rel(inv.residual_force[:, 0], known.base_force) < 3 * e2
    assert rel(inv.residual_moment[:, 0], known.base_moment) < 3 * e2


@pytest.mark.parametrize("structure", FEATURED, ids=FEATURED_IDS)
def test_mixed_path_featured(structure: Structure) -> None:
    check_mixed(structure)


@pytest.mark.parametrize("base", BASES)
@scaled(0.6)
@given(data=st.data())
def test_mixed_path_matches_newton_euler(base: str, data: st.DataObject) -> None:
    """NRM-WLS on the exact markers, then the classical model it drives (classical_dynamics):
    θ, q exact; q̇, q̈ and the joint moments as the central differences of θ make them."""
    check_mixed(data.draw(structures(base == "floating")))


# --- every kinematic method at P0 -----------------------------------------------------------

METHOD_NAMES = ("nrm-ls", "nrm-wls", "cno-sqp", "cno-ip", "mo-tc", "mo-ed", "ad")
# rad and m: NRM, AD and MO-TC land within 1e-13 of the truth, CNO-SQP within ~2e-8 (its
# tolerance acts on the objective), MO-ED within ~1.2e-7 (its distances are smoothed by 1 µm)
P0_TOL = 5e-7


def check_methods(structure: Structure) -> None:
    """Every method on the exact markers of 10 frames at RATE: θ and positions to P0_TOL, rates
    within the central-difference bound, no failed frame, topology held to 1e-9."""
    case = build_case(structure)
    t = T0 + np.arange(10) / RATE
    ref = reference(case, t)
    model = parse_model(case.text, "generated.yaml")
    system = compile_system(model, angles="coordinate", track=True)
    layout = system.layout
    for method in METHOD_NAMES:
        if method.startswith("nrm"):
            weight = None if method == "nrm-ls" else 1e-3
            result = solve_nrm(system, t, ref.markers, NrmSettings(weight, tol=1e-12))
        elif method == "ad":
            result = solve_baseline(model, t, ref.markers, cutoff=None, tol=1e-12)
        else:
            result = solve_optimization(system, t, ref.markers, Settings(method))
        assert result.converged.all(), method
        assert result.phi_top_max.max() <= 1e-9, method
        assert np.abs(result.theta - ref.theta[:, 0]).max() < P0_TOL, method
        error = np.abs(result.q[:, : layout.n_body_q] - body_q(layout, model, ref.x)).max()
        assert error < P0_TOL, method
        check_rates(case, layout, model, result, ref, error)


@pytest.mark.parametrize("structure", FEATURED[1:], ids=FEATURED_IDS[1:])
def test_every_method_featured(structure: Structure) -> None:
    check_methods(structure)


@pytest.mark.parametrize("base", BASES)
@scaled(0.3)
@given(data=st.data())
def test_every_method_recovers_the_truth(base: str, data: st.DataObject) -> None:
    """nrm-ls, nrm-wls, cno-sqp, cno-ip, mo-tc, mo-ed and the AD baseline at P0 (up to four
    bodies: the optimizers' cost grows fast with the coordinates)."""
    check_methods(data.draw(structures(base == "floating", max_bodies=4)))


# --- tracked vectors through the pipeline ---------------------------------------------------

def vector_case(structure: Structure) -> tuple[Case, dict, Trial]:
    """The last body (a leaf) followed by one tracked vector, from one of its markers to
    another, instead of its points; its joint, a revolute, leaves it one turn that the vector
    fixes uniquely (not parallel to the axis). A universal joint would not do: two (φ1, φ2),
    sometimes only 0.2 rad apart, point a body vector the same way. Returns the case, the spec
    and the trial of every marker."""
    case = build_case(structure)
    leaf = case.bodies[-1]
    frame = case.joints[-1].frame
    axis = frame[:, 0]
    labels = [f"{leaf.name}_m{k}" for k in range(3)]
    pairs = [(a, b) for a in labels for b in labels if a < b]

    def direction(pair: tuple[str, str]) -> np.ndarray:
        d = leaf.R0 @ (leaf.points[pair[1]] - leaf.points[pair[0]])
        return d / np.linalg.norm(d)

    start, end = min(pairs, key=lambda p: abs(direction(p) @ axis))
    local = leaf.points[end] - leaf.points[start]
    spec = {**case.spec, "tracking": {
        "points": [tp for tp in case.spec["tracking"]["points"]
                   if not tp["point"].startswith(f"{leaf.name}.")],
        "vectors": [{"vector": f"{leaf.name}.toc", "from": start, "to": end}]}}
    spec["bodies"][leaf.name]["vectors"]["toc"] = [float(v) for v in
                                                   local / np.linalg.norm(local)]
    t = np.arange(12) / 100.0
    ref = reference(case, t)
    trial = Trial("generated_vectors.trc", tuple(label for label, _, _ in case.markers),
                  ref.markers, 100.0)
    return case, spec, trial


@pytest.mark.parametrize("base", BASES)
@scaled(0.3)
@given(data=st.data())
def test_tracked_vectors_recover_the_truth(base: str, data: st.DataObject) -> None:
    """A real solve (solve_trial, NRM-WLS at P0) with a body followed only by the unit vector
    from marker ``from`` to marker ``to`` recovers the truth; the same model with the two
    swapped asks for the opposite direction and must not."""
    structure = data.draw(structures(base == "floating"))
    structure = Structure(structure.parents, (*structure.joints[:-1], "revolute"),
                          structure.form, structure.seed)
    case, spec, trial = vector_case(structure)
    theta = reference(case, trial.time).theta[:, 0]
    options = SolveOptions(method="nrm-wls", tol=1e-12, events="none")
    run = solve_trial(parse_model(safe_dump(spec, sort_keys=False), "vectors.yaml"), trial, options)
    assert run.result.converged.all() and run.trusted.all()
    assert np.abs(run.result.theta - theta).max() < 1e-8
    (tracked,) = spec["tracking"]["vectors"]
    swapped = {**spec, "tracking": {**spec["tracking"], "vectors": [
        {**tracked, "from": tracked["to"], "to": tracked["from"]}]}}
    # kinematics only: the wrong angles may not even assemble the classical model
    wrong = solve_trial(parse_model(safe_dump(swapped, sort_keys=False), "swapped.yaml"),
                        trial, options.with_(dynamics=False))
    leaf_angles = [k for k, c in enumerate(case.coordinates) if c.joint == len(case.bodies) - 1]
    # the right direction gives the truth to 1e-8; the opposite one cannot be met (a revolute
    # turns the vector on a cone) and its compromise lies degrees away
    assert np.abs(wrong.result.theta[:, leaf_angles] - theta[:, leaf_angles]).max() > 1e-3

"""Moving joints (a child frame placed by functions of coordinates): Φ, Φ_q, ν, γ and the
residual Hessian against finite differences on generated models — random spline knots, random
rotation and translation axes, random frame offsets — at random (unassembled) poses."""

from __future__ import annotations

import numpy as np
import pytest

from fccgrb_cli.model.osim.convert import body_poses, parse_osim_model
from fccgrb_cli.model.osim.document import parse_osim
from fccgrb_cli.system.compiled import Drive, compile_system
from tests.osim_text import COORDINATE, LINEAR, axis, custom_joint, knee_model, named, simm


def random_model_text(seed: int) -> str:
    """The knee model with a third body on a CustomJoint of random axes whose six amounts are
    random splines and polynomials of two coordinates, and a coupler."""
    rng = np.random.default_rng(seed)

    def unit() -> str:
        v = rng.normal(size=3)
        return " ".join(f"{x:.6f}" for x in v / np.linalg.norm(v))

    def spline() -> str:
        x = np.sort(rng.uniform(-2.5, 2.5, 7))
        y = rng.normal(scale=0.3, size=7)
        return simm(" ".join(f"{v:.6f}" for v in x), " ".join(f"{v:.6f}" for v in y))

    def poly() -> str:
        c = " ".join(f"{v:.4f}" for v in rng.normal(size=4))
        return f"<PolynomialFunction><coefficients>{c}</coefficients></PolynomialFunction>"

    coordinates = [COORDINATE.format(name=n, motion=m, default=0.2, locked="false")
                   for n, m in (("a", "rotational"), ("b", "translational"))]
    axes = [axis("rotation1", "a", unit(), spline()), axis("rotation2", "b", unit(), poly()),
            axis("rotation3", "a", unit(), LINEAR),
            axis("translation1", "b", unit(), spline()), axis("translation2", "a", unit(), poly()),
            axis("translation3", "b", unit(), spline())]
    offsets = (" ".join(f"{v:.4f}" for v in rng.normal(scale=0.1, size=3)),
               " ".join(f"{v:.4f}" for v in rng.uniform(-1, 1, 3)))
    joint = custom_joint("extra", "/bodyset/shank", "/bodyset/foot", coordinates, axes,
                         offsets, offsets)
    foot = ('<Body name="foot"><mass>1.2</mass><mass_center>0.1 0 0</mass_center>'
            '<inertia>0.01 0.02 0.02 0 0 0</inertia></Body>')
    coupler = ('<CoordinateCouplerConstraint name="couple"><isEnforced>true</isEnforced>'
               + named(spline(), "coupled_coordinates_function")
               + '<independent_coordinate_names>knee</independent_coordinate_names>'
               '<dependent_coordinate_name>patella</dependent_coordinate_name>'
               '</CoordinateCouplerConstraint>')
    text = knee_model(extra_body=foot, coupler=coupler)
    return text.replace("</objects></JointSet>", joint + "</objects></JointSet>")


def system_of(seed: int, angles: str = "coordinate"):
    model = parse_osim_model(random_model_text(seed), "generated.osim")
    return compile_system(model, angles=angles, track=angles == "coordinate")


def random_state(system, rng):
    nq = system.nq
    return rng.normal(size=nq), rng.normal(size=nq), rng.normal(size=nq)


def drive_of(system, rng) -> Drive:
    return Drive(ref=rng.normal(size=(system.n_targets, 3)))


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_jacobian_is_the_derivative_of_the_residual(seed):
    rng = np.random.default_rng(seed)
    system = system_of(seed)
    q, _, _ = random_state(system, rng)
    drive = drive_of(system, rng)
    J = system.jacobian(q)
    h = 1e-6
    fd = np.empty_like(J)
    for k in range(system.nq):
        e = np.zeros(system.nq)
        e[k] = h
        fd[:, k] = (system.residual(q + e, drive) - system.residual(q - e, drive)) / (2 * h)
    assert np.abs(J - fd).max() < 1e-6 * (1.0 + np.abs(J).max())
    rows = system.n_linear_rows + system.functions.rows
    assert np.abs(J[rows, system.layout.n_body_q:]).max() > 1e-2  # θ columns are exercised


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_gamma_is_the_second_time_derivative_left_by_the_accelerations(seed):
    # along q(t) = q + t q̇ + ½ t² q̈:  d²Φ/dt² = Φ_q q̈ − γ  (ν = 0: no row depends on t)
    rng = np.random.default_rng(10 + seed)
    system = system_of(seed)
    q, qd, qdd = random_state(system, rng)
    drive = drive_of(system, rng)
    h = 1e-4

    def phi(t: float) -> np.ndarray:
        return system.residual(q + t * qd + 0.5 * t * t * qdd, drive)

    second = (phi(h) - 2 * phi(0.0) + phi(-h)) / h**2
    expected = system.jacobian(q) @ qdd - system.gamma(q, qd, drive)
    assert np.abs(second - expected).max() < 1e-5 * (1.0 + np.abs(expected).max())
    assert np.allclose(system.nu(q, drive)[system.kinds != 2], 0.0)


@pytest.mark.parametrize("seed", [0, 1])
def test_driven_coordinates_give_nu_and_gamma(seed):
    # θ*(t) = θ + t θ̇ + ½ t² θ̈ prescribed: Φ_q q̇ − ν = dΦ/dt and Φ_q q̈ − γ = d²Φ/dt²
    rng = np.random.default_rng(20 + seed)
    system = system_of(seed, "driver")
    n = len(system.model.angles)
    th, thd, thdd = rng.normal(size=n), rng.normal(size=n), rng.normal(size=n)
    q, qd, qdd = random_state(system, rng)
    ref = rng.normal(size=(system.n_targets, 3))

    def state(t: float) -> tuple[np.ndarray, Drive]:
        return (q + t * qd + 0.5 * t * t * qdd,
                Drive(theta=th + t * thd + 0.5 * t * t * thdd, theta_d=thd + t * thdd,
                      theta_dd=thdd, ref=ref, ref_d=np.zeros_like(ref),
                      ref_dd=np.zeros_like(ref)))

    def phi(t: float) -> np.ndarray:
        return system.residual(*state(t))

    h = 1e-4
    first = (phi(h) - phi(-h)) / (2 * h)
    second = (phi(h) - 2 * phi(0.0) + phi(-h)) / h**2
    _, drive = state(0.0)
    J = system.jacobian(q)
    assert np.abs(first - (J @ qd - system.nu(q, drive))).max() < 1e-6
    assert np.abs(second - (J @ qdd - system.gamma(q, qd, drive))).max() < 1e-4
    rows = system.n_linear_rows + system.functions.rows
    assert np.abs(system.nu(q, drive)[rows]).max() > 1e-2


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_residual_hessian_is_the_derivative_of_the_weighted_jacobian(seed):
    rng = np.random.default_rng(30 + seed)
    system = system_of(seed)
    q, _, _ = random_state(system, rng)
    c = rng.normal(size=system.n_rows)
    H = system.residual_hessian(q, c)
    h = 1e-6
    fd = np.empty_like(H)
    for k in range(system.nq):
        e = np.zeros(system.nq)
        e[k] = h
        fd[:, k] = (system.jacobian(q + e).T @ c - system.jacobian(q - e).T @ c) / (2 * h)
    assert np.abs(H - fd).max() < 1e-6 * (1.0 + np.abs(H).max())


@pytest.mark.parametrize("seed", [0, 1])
def test_the_default_pose_satisfies_every_topological_row(seed):
    system = system_of(seed)
    q = system.pose()
    phi = system.residual(q, Drive(ref=np.zeros((system.n_targets, 3))))
    assert np.abs(phi[system.kinds == 0]).max() < 1e-12
    # and the rank leaves exactly one degree of freedom per coordinate minus the coupler
    n_free = system.nq - system.topology_rank
    assert n_free == len(system.model.angles) - 1


def test_bodies_placed_by_forward_kinematics_keep_the_joint_frames_together():
    # closed form: a knee rotated by k about the joint z axis with no translation splines
    # keeps the child's frame origin on the parent's and turns its x axis by k
    text = knee_model(function="<Constant><value>0</value></Constant>")
    text = text.replace("<scale>1.1</scale>", "<scale>0</scale>")
    osim = parse_osim(text.encode(), "knee.osim")
    values = {c.name: 0.0 for c in osim.coordinates}
    values["knee"] = 0.7
    pose = body_poses(osim, values)
    joint = osim.joints[1]
    R_t, r_t = pose["thigh"]
    R_s, r_s = pose["shank"]
    o_p = r_t + R_t @ np.asarray(joint.parent.translation)
    o_c = r_s + R_s @ np.asarray(joint.child.translation)
    assert np.allclose(o_p, o_c, atol=1e-12)
    e_p = R_t @ np.asarray(joint.parent.rotation)
    e_c = R_s @ np.asarray(joint.child.rotation)
    assert e_p[:, 0] @ e_c[:, 0] == pytest.approx(np.cos(0.7))
    assert np.cross(e_p[:, 0], e_c[:, 0]) @ e_p[:, 2] == pytest.approx(np.sin(0.7))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_stacked_evaluation_equals_each_joint_on_its_own(seed):
    # the solve's batched evaluation against SpatialTransform.terms, joint by joint
    rng = np.random.default_rng(40 + seed)
    system = system_of(seed)
    functions = system.functions
    theta = rng.normal(size=functions.n_coordinates)
    h, h1, h2 = functions.terms(theta)
    for first, transform, index in functions.joints:
        value, d1, d2 = transform.terms(theta[index])
        block = slice(first, first + 12)
        assert np.allclose(h[block], value, atol=1e-14)
        assert np.allclose(h1[block][:, index], d1, atol=1e-13)
        assert np.allclose(h2[block][:, index[:, None], index[None, :]], d2, atol=1e-12)
        others = np.setdiff1d(np.arange(functions.n_coordinates), index)
        assert not h1[block][:, others].any() and not h2[block][:, others].any()


def test_a_coupled_coordinate_without_markers_follows_its_independent_one():
    """A coupler's dependent coordinate moving a body without markers (Rajagopal's patella,
    ``knee_angle_r_beta = knee_angle_r``) is set by the coupling, never held at its default:
    holding it would hold the knee through the coupling. Here the foot has no marker and its
    coordinate is coupled to the knee's; the knee is free to follow the shank's markers."""
    from fccgrb_cli.model.observed import unobserved

    text = random_model_text(3)
    foot_coordinate = text.split('<CustomJoint name="extra">')[1].split('<Coordinate name="')[1]
    name = foot_coordinate.split('"')[0]
    coupler = ('<CoordinateCouplerConstraint name="follow"><isEnforced>true</isEnforced>'
               + named("<LinearFunction><coefficients>1 0</coefficients></LinearFunction>",
                       "coupled_coordinates_function")
               + '<independent_coordinate_names>knee</independent_coordinate_names>'
               f'<dependent_coordinate_name>{name}</dependent_coordinate_name>'
               '</CoordinateCouplerConstraint>')
    text = text.replace("</objects></ConstraintSet>", coupler + "</objects></ConstraintSet>")
    model = parse_osim_model(text, "generated.osim")
    left = unobserved(model)
    assert name not in left and "knee" not in left


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_forward_kinematics_satisfies_every_joint_row_at_any_coordinates(seed):
    """pose_from_coordinates (the first frame's guess and every inverse-dynamics frame) puts
    each body where the joint rows put it, at random coordinates on generated models whose
    joint frames sit off both bodies' origins and are turned: every rigid-body and joint row
    vanishes (the couplings aside: the coordinates here are independent draws)."""
    from fccgrb_cli.system.moving_pose import pose_from_coordinates

    system = system_of(seed)
    rng = np.random.default_rng(100 + seed)
    theta = system.functions.defaults + rng.uniform(-0.6, 0.6, system.functions.n_coordinates)
    q = pose_from_coordinates(system, theta)
    phi = system.residual(q, Drive(ref=np.zeros((system.n_targets, 3))))
    rows = (system.kinds == 0) & ~np.array([label.startswith("coupling")
                                            for label in system.labels])
    assert rows.sum() > 12 * len(system.model.moving_joints)
    assert np.abs(phi[rows]).max() < 1e-12

"""Clinical sign conventions pinned by statics and anatomy, not by the code.

README ("A gait trial") and ``fccgrb_cli/anatomy/clinical.py``: the clinical angle is
φ = sign·(θ − 90°),
flexion, adduction, internal rotation, dorsiflexion and inversion positive on both sides; the
clinical moment is the internal (net muscle) moment conjugate to φ, positive towards positive φ
(OpenSim's generalized forces): an extensor moment is a negative flexion moment, a plantarflexor
moment a negative dorsiflexion moment, an abductor moment a negative adduction moment.

The case: ``configs/models/lower_limb.yaml`` as shipped, with gravity off and nominal masses (the
posture is held still, q̇ = q̈ = 0, so the masses do no work; checked), put into an asymmetric
flexed posture (the package's AD analysis from the clinical angles of POSTURE, the pelvis held)
and turned and shifted as a whole in space so that no anatomical axis lies along a global one.
Every expectation comes from the posture's landmarks (points of the YAML placed with each
body's r, u, v, w) and anatomy alone, never from the package's angle or moment definitions:

* the positive direction of each clinical angle is a rotation of the distal segments about an
  anatomical axis, oriented by what the motion does: the knee moves anteriorly (hip flexion,
  about the pelvis's left–right axis), the knee moves towards the midline (hip adduction, about
  the axis across that one and the thigh), the thigh's anterior face turns towards the midline
  (internal rotation, about the hip–knee line), the shank's distal end moves towards the back
  of the thigh (knee flexion, about the epicondylar axis), the toes move towards the shin
  (dorsiflexion, about the malleolar axis), the sole turns to face the midline (inversion, about
  the foot's long axis, the ankle's second arm);
* a free moment M on the foot about such an axis e would turn the distal segment towards
  positive φ; statics demands an internal moment opposing it, a negative clinical moment
  (extensor, abductor, external rotator, plantarflexor, evertor), and −M a positive one. Where
  φ̇ = ω·e exactly (the knee's and both ankle axes; hip adduction, the angle between the pelvis's
  left–right axis and the thigh, about the floating axis across them) virtual work gives the
  value, −M·e;
* standing on a flexed knee: a vertical ground reaction (body weight) under the metatarsal heads
  passes behind the knee and in front of the ankle (asserted from the landmarks) and needs a knee
  extensor and an ankle plantarflexor moment equal to its moment arms times the force;
* for every angle, hip included, the moment is the generalized force of virtual work:
  τ_k = −(F·∂P/∂φ_k + M·∂ω/∂φ_k) for a force F at a foot point P and a free moment M, with ∂P/∂φ_k
  and ∂ω/∂φ_k by central differences of postures solved with φ_k moved;
* the angles against the same rotations: turning the distal segments a little towards positive φ
  (done in the test, rigidly, about the anatomical axis) must raise φ (by exactly the rotation for
  the knee, the ankle and hip adduction) and leave every other joint's angles alone.

Loads are applied through ``ExternalLoad`` and solved by ``classical_dynamics`` (the pipeline's
converted model) and read through ``clinical_results``, as ``fccgrb solve`` does.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
import yaml

from fccgrb_cli.anatomy.clinical import clinical_results
from fccgrb_cli.dynamics import ExternalLoad
from fccgrb_cli.dynamics.convert import classical_dynamics
from fccgrb_cli.model import Model, parse_model
from fccgrb_cli.solvers import KinematicResult, solve_ad
from fccgrb_cli.solvers.ad.solve import stacked_drives
from fccgrb_cli.solvers.rates import MIN_FRAMES
from fccgrb_cli.system import System, compile_system

MODEL_PATH = Path(__file__).resolve().parents[1] / "configs" / "models" / "lower_limb.yaml"
SIDES = ("r", "l")
KINDS = ("hip_flexion", "hip_adduction", "hip_rotation", "knee_flexion", "ankle_dorsiflexion",
         "ankle_inversion")
# clinical angles (deg) of the held posture: a flexed stance, different on each side and with
# both signs of the secondary angles, so that no side or index mix-up cancels out
POSTURE = {
    "r": {"hip_flexion": 30.0, "hip_adduction": 5.0, "hip_rotation": 6.0, "knee_flexion": 60.0,
          "ankle_dorsiflexion": 25.0, "ankle_inversion": 4.0},
    "l": {"hip_flexion": 20.0, "hip_adduction": -4.0, "hip_rotation": -5.0, "knee_flexion": 45.0,
          "ankle_dorsiflexion": 20.0, "ankle_inversion": -3.0},
}
MOMENT = 10.0        # N·m, the test's free moments
BODY_WEIGHT = 700.0  # N, the stance case's ground reaction
STEP = 1e-5          # rad, central differences of the posture


def _rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rodrigues' rotation matrix about a unit axis."""
    k = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(angle) * K + (1.0 - np.cos(angle)) * K @ K


# the whole posture, turned and shifted so that no anatomical axis is a global one
WORLD_R = _rotation(np.array([0.3, -0.5, 0.8]), np.radians(35.0))
WORLD_T = np.array([0.4, -0.25, 0.1])
UP = WORLD_R @ np.array([0.0, 0.0, 1.0])   # the template stands along global z


def _unit(a: np.ndarray) -> np.ndarray:
    return a / np.linalg.norm(a)


def _vee(skew_part: np.ndarray) -> np.ndarray:
    return np.array([skew_part[2, 1], skew_part[0, 2], skew_part[1, 0]])


def _oriented(axis: np.ndarray, lever: np.ndarray, towards: np.ndarray) -> np.ndarray:
    """``axis`` signed so that a point at ``lever`` from it moves along ``towards`` when turned
    positively about it; the anatomical rule must be unambiguous (not near 90°)."""
    motion = np.cross(axis, lever)
    cosine = motion @ towards / (np.linalg.norm(motion) * np.linalg.norm(towards))
    assert abs(cosine) > 0.3, f"anatomical direction ambiguous (cos {cosine:.2f})"
    return np.sign(cosine) * _unit(axis)


@dataclass(frozen=True)
class Geometry:
    """Landmarks of one posture, from each body's r, u, v, w and the YAML's local coordinates."""

    doc: dict
    system: System
    q: np.ndarray

    def frame(self, body: str) -> tuple[np.ndarray, np.ndarray]:
        """Origin and rotation matrix [u v w] of a body (fully-defined form)."""
        r, u, v, w = self.q[self.system.layout.q_slice(body)].reshape(4, 3)
        return r, np.column_stack([u, v, w])

    def point(self, body: str, name: str) -> np.ndarray:
        r, R = self.frame(body)
        return r + R @ np.asarray(self.doc["bodies"][body]["points"][name], dtype=float)

    def vector(self, body: str, name: str) -> np.ndarray:
        return self.frame(body)[1] @ np.asarray(self.doc["bodies"][body]["vectors"][name], float)


@dataclass(frozen=True)
class Turn:
    """A rotation of the distal segments towards positive φ about an anatomical axis."""

    axis: np.ndarray
    pivot: np.ndarray
    distal: tuple[str, ...]
    exact: bool      # φ̇ = ω·axis exactly, so by duality a moment M·axis gives τ = −M·axis
    isolated: bool   # the joint's own axis: the joint's other angle does not move either


def anatomical_turns(g: Geometry, side: str) -> dict[str, Turn]:
    """The six positive clinical rotations of one leg, from landmarks and anatomy only."""
    S = side.upper()
    thigh, shank, foot = f"thigh_{side}", f"shank_{side}", f"foot_{side}"
    asis = {s: g.point("pelvis", f"{s}_IAS") for s in "RL"}
    psis = {s: g.point("pelvis", f"{s}_IPS") for s in "RL"}
    anterior = _unit(asis["R"] + asis["L"] - psis["R"] - psis["L"])
    to_right = _unit(asis["R"] - asis["L"])
    medial = -to_right if side == "r" else to_right
    hip, knee = g.point(thigh, "HJC"), g.point(thigh, "KJC")
    ankle = g.point(shank, "AJC")
    long_axis = _unit(knee - hip)
    thigh_front = anterior - (anterior @ long_axis) * long_axis
    epicondylar = g.point(thigh, f"{S}_FLE") - g.point(thigh, f"{S}_FME")
    malleolar = g.point(shank, f"{S}_FAL") - g.point(shank, f"{S}_TAM")
    heel, mt1, mt5 = (g.point(foot, f"{S}_{n}") for n in ("FCC", "FM1", "FM5"))
    toes = 0.5 * (mt1 + mt5)
    sole = _unit(np.cross(mt1 - heel, mt5 - heel))
    sole = -sole if sole @ (ankle - heel) > 0 else sole       # the sole's outward normal
    foot_arm = g.vector(foot, "ankle_arm")     # the ankle's second arm: the foot's long axis
    # the template's ankle arm is the heel–metatarsal line to within a degree
    assert foot_arm @ _unit(toes - heel) > np.cos(np.radians(1.0))
    leg = (thigh, shank, foot)
    # hip adduction (README: the ISB joint-coordinate-system angle) is the angle between the
    # pelvis's left–right axis and the thigh's long axis: its rate is exactly ω·(floating axis)
    floating = np.cross(to_right, long_axis)
    return {
        "hip_flexion": Turn(_oriented(to_right, knee - hip, anterior), hip, leg, False, False),
        "hip_adduction": Turn(_oriented(floating, knee - hip, medial), hip, leg, True, False),
        "hip_rotation": Turn(_oriented(long_axis, thigh_front, medial), hip, leg, False, False),
        "knee_flexion": Turn(_oriented(epicondylar, ankle - knee, -thigh_front), knee,
                             (shank, foot), True, True),
        "ankle_dorsiflexion": Turn(_oriented(malleolar, toes - ankle, knee - ankle), ankle,
                                   (foot,), True, True),
        "ankle_inversion": Turn(_oriented(foot_arm, sole, medial), ankle, (foot,), True, True),
    }


# --- the held posture and the load cases -------------------------------------------------------

def _angle_index(model: Model) -> dict[tuple[str, str], int]:
    return {(kind, side): [a.name for a in model.angles].index(f"{kind}_{side}")
            for kind in KINDS for side in SIDES}


def _posture_theta(model: Model) -> np.ndarray:
    """θ (rad) of POSTURE: θ = 90° + sign·φ, the inverse of φ = sign·(θ − 90°)."""
    theta = np.full(len(model.angles), np.pi / 2)
    for (kind, side), k in _angle_index(model).items():
        theta[k] += model.angles[k].clinical_sign * np.radians(POSTURE[side][kind])
    return theta


def _held(system: System, theta: np.ndarray, q_guess: np.ndarray, base: np.ndarray,
          n_frames: int = 1) -> KinematicResult:
    """The AD analysis of a still posture: the same θ and pelvis over frames 1 s apart."""
    thetas = np.tile(theta, (n_frames, 1))
    bases = np.tile(base, (n_frames, 1, 1))
    still = np.zeros_like(thetas)
    drives = stacked_drives(system, thetas, still, still,
                            (bases, np.zeros_like(bases), np.zeros_like(bases)))
    result = solve_ad(system, np.arange(n_frames, dtype=float), drives, q_guess)
    assert result.converged.all()
    return result


@dataclass(frozen=True)
class Case:
    """One frame's load on one foot: a force at a global point and a free moment."""

    side: str
    force: np.ndarray
    point: np.ndarray
    moment: np.ndarray


@dataclass(frozen=True)
class Posture:
    """The held posture: the test's model, its compiled classical system, the landmarks, the
    drivers θ and the pelvis's driven features, angle indices and the anatomical turns."""

    model: Model
    system: System
    geometry: Geometry
    theta: np.ndarray
    base: np.ndarray
    index: dict[tuple[str, str], int]
    turns: dict[str, dict[str, Turn]]


@pytest.fixture(scope="module")
def posture() -> Posture:
    """The shipped template without gravity, in POSTURE, turned by WORLD_R and shifted."""
    doc = yaml.safe_load(MODEL_PATH.read_text(encoding="utf-8"))
    doc["gravity"] = [0.0, 0.0, 0.0]
    for body in doc["bodies"].values():       # nominal inertia: still, so it does no work
        body.update(mass=5.0, inertia=[0.05, 0.02, 0.05])
    model = parse_model(yaml.safe_dump(doc, sort_keys=False), str(MODEL_PATH))
    system = compile_system(model, angles="driver")
    layout = system.layout
    guess = layout.pose_q(model)
    for body in layout.body_names:            # the template's pose, turned and shifted
        r, u, v, w = guess[layout.q_slice(body)].reshape(4, 3)
        guess[layout.q_slice(body)] = np.concatenate([WORLD_R @ r + WORLD_T, WORLD_R @ u,
                                                      WORLD_R @ v, WORLD_R @ w])
    base = system.base_reference(guess)
    theta = _posture_theta(model)
    q = _held(system, theta, guess, base).q[0]
    geometry = Geometry(doc, system, q)
    np.testing.assert_allclose(geometry.frame("pelvis")[1],
                               WORLD_R @ np.array([[1, 0, 0], [0, 0, 1], [0, -1, 0]]).T,
                               atol=1e-12)
    turns = {side: anatomical_turns(geometry, side) for side in SIDES}
    return Posture(model, system, geometry, theta, base, _angle_index(model), turns)


def _stance_force(p: Posture, side: str) -> Case:
    """Body weight straight up under the metatarsal heads."""
    S = side.upper()
    toes = 0.5 * (p.geometry.point(f"foot_{side}", f"{S}_FM1")
                  + p.geometry.point(f"foot_{side}", f"{S}_FM5"))
    return Case(side, BODY_WEIGHT * UP, toes, np.zeros(3))


def _cases(p: Posture) -> dict[tuple, Case]:
    """Every load case: ±MOMENT about each anatomical axis, and the stance force, per side."""
    cases: dict[tuple, Case] = {}
    for side in SIDES:
        ankle = p.geometry.point(f"shank_{side}", "AJC")
        for kind, turn in p.turns[side].items():
            for sense in (1.0, -1.0):
                cases[kind, side, sense] = Case(side, np.zeros(3), ankle,
                                                sense * MOMENT * turn.axis)
        cases["stance", side] = _stance_force(p, side)
    return cases


@dataclass(frozen=True)
class Solved:
    """Clinical moments (N·m) of every load case, and the dynamics' own checks."""

    moments: dict[tuple, np.ndarray]
    qd_max: float
    qdd_max: float
    residual_max: float


def solve_cases(p: Posture, cases: dict[tuple, Case]) -> Solved:
    """All cases in one run, one frame each, through the pipeline's converted model (at least
    three frames of the still posture: the accelerations need three)."""
    keys = list(cases)
    n = max(len(keys), MIN_FRAMES)
    result = _held(p.system, p.theta, p.geometry.q, p.base, n)
    loads = []
    for side in SIDES:
        force, point, moment = (np.zeros((n, 3)) for _ in range(3))
        point[:] = p.geometry.point(f"foot_{side}", "AJC")
        for f, key in enumerate(keys):
            if cases[key].side == side:
                force[f], point[f], moment[f] = (cases[key].force, cases[key].point,
                                                 cases[key].moment)
        loads.append(ExternalLoad(f"test_{side}", f"foot_{side}", force, point, moment))
    dynamics = classical_dynamics(p.model, result, loads=loads)
    clinical = clinical_results(p.model, dynamics.kinematics.theta,
                                dynamics.inverse.joint_moments)
    assert clinical is not None and clinical.moments is not None
    assert list(clinical.names) == [a.name for a in p.model.angles]
    return Solved({key: clinical.moments[f] for f, key in enumerate(keys)},
                  float(np.abs(dynamics.kinematics.qd).max()),
                  float(np.abs(dynamics.kinematics.qdd).max()),
                  float(dynamics.inverse.residual.max()))


@pytest.fixture(scope="module")
def solved(posture: Posture) -> Solved:
    return solve_cases(posture, _cases(posture))


def _turned(g: Geometry, turn: Turn, angle: float) -> np.ndarray:
    """q with the distal segments turned rigidly by ``angle`` (rad) about ``turn``'s axis."""
    R = _rotation(turn.axis, angle)
    q = g.q.copy()
    for body in turn.distal:
        r, u, v, w = q[g.system.layout.q_slice(body)].reshape(4, 3)
        q[g.system.layout.q_slice(body)] = np.concatenate(
            [turn.pivot + R @ (r - turn.pivot), R @ u, R @ v, R @ w])
    return q


def _clinical_angles(p: Posture, qs: list[np.ndarray]) -> np.ndarray:
    """Clinical angles (deg) of configurations, through the package's angle path."""
    theta = np.array([p.system.angles_at(q) for q in qs])
    clinical = clinical_results(p.model, theta, None)
    assert clinical is not None
    return clinical.angles


def _same_joint(kind: str, other: str) -> bool:
    return kind.split("_")[0] == other.split("_")[0]


LEG = [(kind, side) for side in SIDES for kind in KINDS]


def test_the_posture_is_held_still(posture: Posture, solved: Solved) -> None:
    """The premise of statics: no velocity, no acceleration (so the masses do no work), and the
    inverse dynamics' equations solved exactly."""
    assert solved.qd_max < 1e-12 and solved.qdd_max < 1e-12
    assert solved.residual_max < 1e-9
    angles = _clinical_angles(posture, [posture.geometry.q])[0]
    for (kind, side), k in posture.index.items():
        assert angles[k] == pytest.approx(POSTURE[side][kind], abs=1e-8), (kind, side)


@pytest.mark.parametrize(("kind", "side"), LEG)
def test_angle_rises_along_its_anatomical_turn(posture: Posture, kind: str, side: str) -> None:
    """Turning the distal segments towards flexion, adduction, internal rotation, dorsiflexion
    or inversion (as anatomy defines them, about an axis built from landmarks) raises that
    clinical angle: by exactly the turn about the knee's and the ankle's own axes and the hip's
    floating axis (adduction), at nearly that rate for hip flexion and rotation. The rotation is
    rigid, so every other joint keeps its angles; about a joint's own axis so does the joint's
    other angle."""
    turn = posture.turns[side][kind]
    delta = 1e-4
    minus, plus = _clinical_angles(posture, [_turned(posture.geometry, turn, -delta),
                                             _turned(posture.geometry, turn, delta)])
    rate = (plus - minus) / (2 * np.degrees(delta))       # deg of φ per deg of turn
    k = posture.index[kind, side]
    if turn.exact:
        assert rate[k] == pytest.approx(1.0, abs=1e-7)
    else:
        assert rate[k] > 0.8
    for (other, other_side), j in posture.index.items():
        if j != k and (turn.isolated or other_side != side or not _same_joint(kind, other)):
            assert abs(rate[j]) < 1e-9, f"{other}_{other_side} moved with {kind}_{side}"


MUSCLES = {"hip_flexion": "extensor", "hip_adduction": "abductor",
           "hip_rotation": "external rotator", "knee_flexion": "extensor",
           "ankle_dorsiflexion": "plantarflexor", "ankle_inversion": "evertor"}


@pytest.mark.parametrize(("kind", "side"), LEG)
def test_moment_opposes_a_load_towards_positive_angle(posture: Posture, solved: Solved,
                                                      kind: str, side: str) -> None:
    """A free moment on the foot that would turn the distal segments towards positive φ is held
    by an internal moment the other way (extensor, abductor, external rotator, plantarflexor,
    evertor): a negative clinical moment; the reverse load a positive one. Where φ̇ = ω·axis
    exactly (the knee's and ankle's own axes, the hip's floating axis for adduction) virtual work
    gives the value: −M·axis, here ∓MOMENT. A load on one foot leaves the other leg's moments at
    zero."""
    turn = posture.turns[side][kind]
    k = posture.index[kind, side]
    towards, away = solved.moments[kind, side, 1.0], solved.moments[kind, side, -1.0]
    assert towards[k] < 0, f"{kind}_{side}: expected an internal {MUSCLES[kind]} moment"
    assert away[k] > 0, f"{kind}_{side}: expected an internal moment towards positive φ"
    if turn.exact:
        assert towards[k] == pytest.approx(-MOMENT, rel=1e-9)
        assert away[k] == pytest.approx(MOMENT, rel=1e-9)
    else:
        assert -towards[k] > 0.8 * MOMENT and away[k] > 0.8 * MOMENT
    other = [j for (_, s), j in posture.index.items() if s != side]
    assert np.abs(towards[other]).max() < 1e-9 * MOMENT
    assert np.abs(away[other]).max() < 1e-9 * MOMENT


@pytest.mark.parametrize("side", SIDES)
def test_standing_on_a_flexed_knee(posture: Posture, solved: Solved, side: str) -> None:
    """Body weight under the metatarsal heads of a flexed leg passes in front of the hip, behind
    the knee and in front of the ankle (asserted from the landmarks): it would flex the hip and
    the knee and dorsiflex the ankle, so a hip extensor, a knee extensor and an ankle
    plantarflexor moment hold it, the last two equal to the force's moment about the joint axis
    (the epicondylar axis, the malleolar axis)."""
    g = posture.geometry
    case = _stance_force(posture, side)
    hip, knee = g.point(f"thigh_{side}", "HJC"), g.point(f"thigh_{side}", "KJC")
    ankle = g.point(f"shank_{side}", "AJC")
    knee_axis = posture.turns[side]["knee_flexion"].axis
    ankle_axis = posture.turns[side]["ankle_dorsiflexion"].axis
    hip_flexing = np.cross(case.point - hip, case.force) @ posture.turns[side]["hip_flexion"].axis
    flexing = np.cross(case.point - knee, case.force) @ knee_axis
    dorsiflexing = np.cross(case.point - ankle, case.force) @ ankle_axis
    # the premise, from geometry: lever arms of at least 2 cm about the three axes
    assert min(hip_flexing, flexing, dorsiflexing) > 0.02 * BODY_WEIGHT
    moments = solved.moments["stance", side]
    assert moments[posture.index["hip_flexion", side]] < 0, "expected a hip extensor moment"
    knee_moment = moments[posture.index["knee_flexion", side]]
    ankle_moment = moments[posture.index["ankle_dorsiflexion", side]]
    assert knee_moment < 0, "expected a knee extensor moment"
    assert ankle_moment < 0, "expected an ankle plantarflexor moment"
    assert knee_moment == pytest.approx(-flexing, rel=1e-9)
    assert ankle_moment == pytest.approx(-dorsiflexing, rel=1e-9)


@pytest.mark.parametrize("side", SIDES)
def test_moments_are_the_generalized_forces_of_virtual_work(posture: Posture, side: str) -> None:
    """Every clinical moment, the hip's included, of a generic load on one foot (an oblique
    force under the forefoot and a free moment): τ_k = −(F·∂P/∂φ_k + M·∂ω/∂φ_k), the foot's point
    P and rotation ω read from postures solved with θ_k moved by ±STEP and φ_k read back through
    ``clinical_results`` (central differences). Holds for the other leg too (τ = 0 there)."""
    g = posture.geometry
    foot = f"foot_{side}"
    origin, frame = g.frame(foot)
    local = np.array([0.12, -0.07, 0.03])               # under the forefoot
    force = WORLD_R @ np.array([40.0, -25.0, 600.0])
    moment = WORLD_R @ np.array([3.0, -4.0, 2.5])
    case = Case(side, force, origin + frame @ local, moment)
    tau = solve_cases(posture, {"generic": case}).moments["generic"]
    expected = np.empty_like(tau)
    for k in range(len(posture.theta)):
        states = []
        for sense in (-1.0, 1.0):
            theta = posture.theta.copy()
            theta[k] += sense * STEP
            q = _held(posture.system, theta, g.q, posture.base).q[0]
            moved = Geometry(g.doc, g.system, q)
            states.append((*moved.frame(foot), q))
        (r0, R0, q0), (r1, R1, q1) = states
        phi0, phi1 = np.radians(_clinical_angles(posture, [q0, q1])[:, k])
        rotation = _vee(R1 @ R0.T - R0 @ R1.T) / 2       # sin(angle) × axis: O(STEP³) off
        work = force @ (r1 + R1 @ local - r0 - R0 @ local) + moment @ rotation
        expected[k] = -work / (phi1 - phi0)
    names = [a.name for a in posture.model.angles]
    np.testing.assert_allclose(tau, expected, rtol=0, atol=1e-9 * np.abs(expected).max(),
                               err_msg=f"clinical moments of {names}")

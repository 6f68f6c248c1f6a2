"""Residual force and moment of a floating base, and the frames where they mean something.

A floating base's drivers apply the wrench the rest of the data cannot account for (the
residual; ``inverse._base_wrenches``). Under a rigid motion of its whole group of bodies every
joint equation holds (internal joint forces do no work), so that wrench follows from the
bodies' motion and the external loads alone, joints and closed chains whatever they are
(docs/formulation.md §14): with X_i = [r u v w] (3 × 4) of body i, the generalized forces on it are
Q_i = (G − Ẍ_i) K_i + (loads on i), G = [g 0 0 0], K_i its inertia coefficients, and the
residual's power over a translation δ and a rotation δθ about the base's origin o cancels
theirs:

    F = −Σ_i Q_i,0,     M = −Σ_i [(r_i − o) × Q_i,0 + u_i × Q_i,1 + v_i × Q_i,2 + w_i × Q_i,3],

Newton's second law and the rate of angular momentum of the whole group (F = Σ m a_G − m g −
Σ F_ext). The expression is linear in every K_i, which is what the residual reduction
(``dynamics.reduction``) fits.

A residual is a check of the data only where every load on the group is measured: at a frame
where a contact body touches the ground off the force plates, the unmeasured reaction is in the
residual. :func:`contact_states` tells, per contact body and frame, whether it is loaded by a
plate, in the air, or on the ground unmeasured (a point within ``CONTACT_HEIGHT`` of the lowest
height it reaches in the trial and slower than ``CONTACT_SPEED``, with ``CONTACT_MARGIN`` frames
either side of such a frame counted too); a frame is *measured* when no contact body is on the
ground unmeasured, and residual statistics are over measured frames only.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from fccgrb_cli.dynamics.loads import ExternalLoad
from fccgrb_cli.model import Model
from fccgrb_cli.solvers.batched import Stacked
from fccgrb_cli.system import System
from fccgrb_cli.system.constraints import joint_neighbours, reachable

CONTACT_HEIGHT = 0.03  # m above the lowest height a contact body's point reaches in the trial
CONTACT_SPEED = 1.0  # m/s: a point moving faster is not resting on the ground
CONTACT_MARGIN = 0.01  # s either side of a frame on the ground counted as on the ground
WEIGHT_TOLERANCE = 0.05  # the plates' body weight and the model's mass agree within 5 %
# The plates' weight estimate is taken between these multiples of the model's own weight (a
# lower-limb model holds half the body; a whole body, all of it): outside, it is not a weight.
PLAUSIBLE_WEIGHT = (0.5, 4.0)
STANDARD_GRAVITY = 9.81  # m/s²: a weight shown as a mass

AIR, PLATE, UNMEASURED = 0, 1, 2
STATES = ("air", "plate", "unmeasured")


@dataclass(frozen=True)
class BodyMotion:
    """Every body's X = [r u v w] and its first and second derivatives (frames × bodies × 3 ×
    4, columns r, u, v, w), in the system's body order."""

    names: tuple[str, ...]
    X: np.ndarray
    Xd: np.ndarray
    Xdd: np.ndarray

    @classmethod
    def of(cls, system: System, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> BodyMotion:
        """From a classical system's q, q̇, q̈ (frames × nq): x = S V q, ẋ = X_q q̇,
        ẍ = X_q q̈ + V̇ q̇ (Eq. 5, 7, 36)."""
        stacked = Stacked(system)
        n, nb = len(q), len(system.layout.body_names)
        body = system.layout.n_body_q
        q, qd, qdd = q[:, :body], qd[:, :body], qdd[:, :body]
        x, xd = stacked.expand(q), stacked.expand_rate(q, qd)
        xq = stacked.expand_jacobian(q)
        xdd = (qdd if xq is None else np.einsum("fxq,fq->fx", xq, qdd)) \
            + stacked.expand_bias(qd)

        def shaped(a: np.ndarray) -> np.ndarray:
            return a.reshape(n, nb, 4, 3).transpose(0, 1, 3, 2)

        return cls(system.layout.body_names, shaped(x), shaped(xd), shaped(xdd))

    def index(self, body: str) -> int:
        return self.names.index(body)

    def points(self, body: str, local: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Positions and velocities (frames × points × 3) of body-fixed points (points × 3)."""
        k = self.index(body)
        homogeneous = np.column_stack([np.ones(len(local)), local])  # points × 4
        return (np.einsum("fcj,pj->fpc", self.X[:, k], homogeneous),
                np.einsum("fcj,pj->fpc", self.Xd[:, k], homogeneous))


def groups(model: Model) -> dict[str, tuple[str, ...]]:
    """Each floating base → the bodies of its group (those joints tie to it)."""
    neighbours = joint_neighbours(model)
    return {base: tuple(sorted(reachable(neighbours, base, set())))
            for base in model.floating_bases}


def generalized_loads(motion: BodyMotion, loads: Sequence[ExternalLoad]) -> np.ndarray:
    """The external loads' generalized forces on every body (frames × bodies × 3 × 4)."""
    n = len(motion.X)
    out = np.zeros((n, len(motion.names), 3, 4))
    for load in loads:
        k = motion.index(load.body)
        x_body = motion.X[:, k].transpose(0, 2, 1).reshape(n, 12)
        out[:, k] += load.generalized(x_body, np.arange(n)).reshape(n, 4, 3).transpose(0, 2, 1)
    return out


def rigid_wrench(Q: np.ndarray, X: np.ndarray, origin: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
    """The force and the moment about ``origin`` (frames × 3) whose power over any rigid motion
    equals that of generalized forces Q on bodies at X (frames × bodies × 3 × 4 both):
    Σ Q_0 and Σ [(r − o) × Q_0 + u × Q_1 + v × Q_2 + w × Q_3]."""
    force = Q[:, :, :, 0].sum(axis=1)
    arm = X[:, :, :, 0] - origin[:, None, :]
    moment = np.cross(arm, Q[:, :, :, 0]).sum(axis=1)
    for k in (1, 2, 3):
        moment += np.cross(X[:, :, :, k], Q[:, :, :, k]).sum(axis=1)
    return force, moment


def gravity_matrix(model: Model, n: int) -> np.ndarray:
    """G = [g 0 0 0] for every frame (frames × 1 × 3 × 4)."""
    G = np.zeros((n, 1, 3, 4))
    G[:, 0, :, 0] = model.gravity
    return G


def whole_body_residual(model: Model, motion: BodyMotion, K: np.ndarray,
                        loads: Sequence[ExternalLoad]) -> tuple[np.ndarray, np.ndarray]:
    """Residual force and moment (frames × bases × 3, N and N·m about each base's origin) of
    the inertia coefficients K (bodies × 4 × 4, the system's body order) on the motion, by the
    rigid-motion balance of each floating group (the module's formula)."""
    n = len(motion.X)
    Q = np.einsum("fbcj,bjk->fbck", gravity_matrix(model, n) - motion.Xdd, K)
    Q += generalized_loads(motion, loads)
    bases = groups(model)
    force = np.zeros((n, len(bases), 3))
    moment = np.zeros((n, len(bases), 3))
    for g, (base, members) in enumerate(bases.items()):
        rows = [motion.index(b) for b in members]
        origin = motion.X[:, motion.index(base), :, 0]
        f, m = rigid_wrench(Q[:, rows], motion.X[:, rows], origin)
        force[:, g], moment[:, g] = -f, -m
    return force, moment


def _dilate(mask: np.ndarray, frames: int) -> np.ndarray:
    """``mask`` with every True spread ``frames`` either side."""
    if frames <= 0 or not mask.any():
        return mask
    out = mask.copy()
    for shift in range(1, frames + 1):
        out[shift:] |= mask[:-shift]
        out[:-shift] |= mask[shift:]
    return out


def contact_states(model: Model, motion: BodyMotion, stance: dict[str, np.ndarray],
                   rate: float, reach: int = 0) -> dict[str, np.ndarray]:
    """Per contact body, per frame: PLATE (a force plate loads it: ``stance``, body → frames
    whose plate force exceeds the model's threshold, before any low-pass), UNMEASURED (on the
    ground with no plate under it) or AIR. 'On the ground': some point of the body within
    CONTACT_HEIGHT of the lowest it comes in the trial (along −gravity) and slower than
    CONTACT_SPEED, spread CONTACT_MARGIN and ``reach`` frames either side (the low-pass
    filter's reach, ``filtering.settling_frames``, when the motion and loads were filtered: it
    spreads the unmeasured reaction's effect on the accelerations that far)."""
    up = -np.asarray(model.gravity, float)
    up /= np.linalg.norm(up)
    margin = round(CONTACT_MARGIN * rate) + reach
    out = {}
    for name in model.contact_bodies:
        body = model.body(name)
        local = np.array([p.local for p in body.points.values()] or [np.zeros(3)])
        where, speed = motion.points(name, local)
        height = where @ up
        low = height <= np.nanmin(height, axis=0) + CONTACT_HEIGHT
        slow = np.linalg.norm(speed, axis=2) <= CONTACT_SPEED
        ground = _dilate((low & slow).any(axis=1), margin)
        plated = stance.get(name, np.zeros(len(ground), dtype=bool))
        state = np.full(len(ground), AIR, dtype=np.int8)
        state[ground] = UNMEASURED
        state[plated] = PLATE
        out[name] = state
    return out


@dataclass(frozen=True)
class ResidualSummary:
    """The residuals over the measured frames (per base): peak and RMS of |F| (N and % of the
    body weight) and |M| (N·m); the body weight the plates measured (N) and the model's mass
    (kg); ``frames``: how many frames are measured; ``single``: how many of them have exactly
    one contact body on a plate (single support)."""

    frames: int
    single: int
    force_peak: float
    force_rms: float
    moment_peak: float
    moment_rms: float
    weight: float
    model_mass: float

    @property
    def force_peak_bw(self) -> float:
        return 100.0 * self.force_peak / self.weight

    @property
    def force_rms_bw(self) -> float:
        return 100.0 * self.force_rms / self.weight


def measured_frames(states: dict[str, np.ndarray], n: int) -> np.ndarray:
    """Frames where no contact body is on the ground unmeasured."""
    out = np.ones(n, dtype=bool)
    for state in states.values():
        out &= state != UNMEASURED
    return out


def single_support(states: dict[str, np.ndarray], n: int) -> np.ndarray:
    """Measured frames with exactly one contact body on a plate and the others in the air."""
    on = np.zeros(n, dtype=int)
    for state in states.values():
        on += state == PLATE
    return measured_frames(states, n) & (on == 1)


def plate_weight(model: Model, motion: BodyMotion, K: np.ndarray,
                 loads: Sequence[ExternalLoad], frames: np.ndarray) -> float:
    """The body weight the plates measure (N): m = Σ F·up / Σ (g + a_G)·up over the frames,
    the plates' vertical impulse over the whole body's (a_G from the motion and K's mass
    distribution, which moves the answer only by its CoM acceleration's mean)."""
    g = np.asarray(model.gravity, float)
    up = -g / np.linalg.norm(g)
    masses = K[:, 0, 0]
    first = K[:, 0, :]  # m, m c: the CoM's acceleration is Ẍ_i K_i e₁ / m_i
    a_g = np.einsum("fbcj,bj->fc", motion.Xdd, first) / masses.sum()
    force = sum((load.force for load in loads), np.zeros((len(motion.X), 3)))
    return float(np.sum(force[frames] @ up) / np.sum((a_g[frames] - g) @ up)) * float(
        np.linalg.norm(g))


def summarize(force: np.ndarray, moment: np.ndarray, frames: np.ndarray, single: np.ndarray,
              weight: float, model_mass: float) -> ResidualSummary:
    """Peak and RMS of the residual's magnitude over the measured ``frames`` (one base)."""
    f = np.linalg.norm(force[frames], axis=1)
    m = np.linalg.norm(moment[frames], axis=1)

    def stat(values: np.ndarray, kind: str) -> float:
        if not values.size:
            return float("nan")
        return float(values.max() if kind == "peak" else np.sqrt(np.mean(values ** 2)))

    return ResidualSummary(int(frames.sum()), int(single.sum()), stat(f, "peak"),
                           stat(f, "rms"), stat(m, "peak"), stat(m, "rms"), weight, model_mass)


@dataclass(frozen=True)
class ResidualReport:
    """A run's residual (its one floating base's): the contact states of every contact body
    (``contact_states``), the measured frames and the single-support ones among them, the
    residual force and moment (frames × 3; NaN outside the measured frames is left to the
    reader: the arrays hold every frame), and the statistics over each set of frames."""

    base: str
    states: dict[str, np.ndarray]
    measured: np.ndarray
    single: np.ndarray
    force: np.ndarray
    moment: np.ndarray
    over_measured: ResidualSummary
    over_single: ResidualSummary
    weighed: bool = False
    plates_estimate: float = float("nan")

    def weight_mismatch(self, tolerance: float = WEIGHT_TOLERANCE,
                        subject_mass: float | None = None) -> str | None:
        """A warning when the plates' body weight and the subject's mass disagree by more than
        ``tolerance`` (a wrong --mass, a plate's calibration), else None. The subject's mass is
        ``subject_mass`` where the model records it (a calibrated model: a lower-limb model's
        segments hold about half of it, which is no fault), else the model's segments' sum (a
        model that leaves out part of the body then shows here)."""
        s = self.over_measured
        if not self.weighed:
            return None
        plates = s.weight / STANDARD_GRAVITY
        mass, whose = ((subject_mass, "subject's") if subject_mass is not None
                       else (s.model_mass, "model's"))
        off = mass / plates - 1.0
        if abs(off) <= tolerance:
            return None
        return (f"the {whose} mass ({mass:.1f} kg) is {100 * off:+.0f} % off the body "
                f"weight the force plates measure over the {s.frames} frames where every "
                f"contact is measured ({s.weight:.0f} N, {plates:.1f} kg): check --mass, the "
                "plates' calibration" + ("" if subject_mass is not None else
                                         ", or what of the body the model leaves out"))


def residual_report(model: Model, motion: BodyMotion, K: np.ndarray,
                    loads: Sequence[ExternalLoad], states: dict[str, np.ndarray],
                    weight: float | None = None, trusted: np.ndarray | None = None
                    ) -> ResidualReport | None:
    """The residual statistics of a motion with inertia coefficients K and the given contact
    states; None unless the model has exactly one floating base (its residual is the one
    reported). The body weight (N) the percentages refer to: ``weight``, else the plates' over
    the measured frames when they load any, else the model's. Only frames the dynamics ran on
    and, given ``trusted``, whose kinematics the quality checks trust count as measured."""
    bases = model.floating_bases
    if len(bases) != 1:
        return None
    n = len(motion.X)
    force, moment = whole_body_residual(model, motion, K, loads)
    # a frame the dynamics did not run on (unsolved, outside the data) measures nothing
    ran = np.isfinite(force[:, 0]).all(axis=1) & np.isfinite(moment[:, 0]).all(axis=1)
    if trusted is not None:
        ran &= trusted
    measured = measured_frames(states, n) & ran
    single = single_support(states, n) & ran
    mass = float(K[:, 0, 0].sum())
    loaded = any(np.abs(load.force[measured]).any() for load in loads)
    estimate = float("nan")
    if weight is None:
        model_weight = mass * float(np.linalg.norm(model.gravity))
        weight = model_weight
        if loaded:
            estimate = plate_weight(model, motion, K, loads, measured)
            # a negative or absurd estimate (the measured frames' vertical accelerations as
            # large as gravity: differentiated noise, or a model far from the body) is not a
            # weight: the model's is used, and the report says why
            loaded = bool(np.isfinite(estimate)) and PLAUSIBLE_WEIGHT[0] * model_weight \
                <= estimate <= PLAUSIBLE_WEIGHT[1] * model_weight
            weight = estimate if loaded else model_weight
    over_measured, over_single = (
        summarize(force[:, 0], moment[:, 0], frames, single & frames, weight, mass)
        for frames in (measured, single))
    return ResidualReport(bases[0], states, measured, single, force[:, 0], moment[:, 0],
                          over_measured, over_single, weighed=loaded, plates_estimate=estimate)

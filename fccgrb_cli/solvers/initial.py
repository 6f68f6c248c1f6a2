"""A first-frame guess that needs no hand-given pose (docs/formulation.md §3).

Bodies are visited outward from the ground along the joints, then outward from each floating
base, which its own markers place. Each is fitted to what is known of
it: its tracked markers plus the joint points it shares with bodies already placed. Three or more
non-collinear points give a least-squares rigid fit (Söderkvist–Wedin, via the SVD); two give the
segment's direction (the smallest rotation from the model pose); one, a translation of the pose.
A two-point segment's rotation about its own axis is then chosen to satisfy its joints' axis
equations with the bodies already placed (a universal joint's perpendicular arms, a revolute's
parallel axes), the roll nearest the model pose as seen from the body it is reached from winning
ties. Mixed coordinates follow
from the fitted bodies: θ = acos(s1·s2) from their vectors, d = (r_Q − r_P)·s from their points.
Only joints whose points coincide (spherical, revolute, universal) share a point: a cylindrical,
prismatic or line joint's points only lie on one axis line, some slide apart.
"""

from __future__ import annotations

from collections import deque

import numpy as np

from fccgrb_cli.model import GROUND
from fccgrb_cli.system import System

COINCIDENT = frozenset({"spherical", "revolute", "universal"})


def rigid_fit(local: np.ndarray, world: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """R, r minimizing Σ‖r + R pᵢ − yᵢ‖² (Söderkvist & Wedin 1993)."""
    lc, wc = local.mean(axis=0), world.mean(axis=0)
    H = (local - lc).T @ (world - wc)
    U, _, Vt = np.linalg.svd(H)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
    R = Vt.T @ D @ U.T
    return R, wc - R @ lc


def rigid_fits(local: np.ndarray, world: np.ndarray) -> np.ndarray:
    """The rotations R of :func:`rigid_fit` for one set of local points (k × 3) and many
    frames of their world positions (frames × k × 3), at once (frames × 3 × 3)."""
    centred = local - local.mean(axis=0)
    H = np.matmul(centred.T, world - world.mean(axis=1, keepdims=True))
    U, _, Vt = np.linalg.svd(H)
    V, Ut = Vt.transpose(0, 2, 1), U.transpose(0, 2, 1)
    D = np.tile(np.eye(3), (len(H), 1, 1))
    D[:, 2, 2] = np.sign(np.linalg.det(V @ Ut))
    return V @ D @ Ut


def rotation_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The smallest rotation taking direction a onto direction b."""
    a, b = a / np.linalg.norm(a), b / np.linalg.norm(b)
    axis = np.cross(a, b)
    s, c = np.linalg.norm(axis), float(a @ b)
    if s < 1e-12:
        if c > 0:
            return np.eye(3)
        perp = np.cross(a, np.eye(3)[int(np.argmin(np.abs(a)))])
        perp /= np.linalg.norm(perp)
        return 2.0 * np.outer(perp, perp) - np.eye(3)
    k = axis / s
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + s * K + (1 - c) * (K @ K)


def axis_rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rotation by ``angle`` about the unit vector ``axis`` (Rodrigues)."""
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * (K @ K)


def best_roll(R: np.ndarray, axis_world: np.ndarray,
              pairs: list[tuple[np.ndarray, np.ndarray]],
              reference: np.ndarray | None = None) -> np.ndarray:
    """Rotate R about ``axis_world`` so that every (fixed world vector p, body-local vector s)
    pair is as perpendicular as possible: min Σ (p · Rot(φ) R s)²; among equally good rolls
    (a trigonometric polynomial, sampled, every local minimum refined) the one nearest the
    rotation ``reference`` when given, else the smallest |φ|; without pairs, the roll nearest
    ``reference`` (R itself when there is none)."""
    k = axis_world / np.linalg.norm(axis_world)
    if not pairs:
        if reference is None:
            return R
        # max trace(referenceᵀ Rot(φ) R) = A cos φ + B sin φ + C (Rodrigues, M = R referenceᵀ)
        M = R @ reference.T
        K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
        return axis_rotation(k, np.arctan2(np.trace(K @ M), np.trace(M) - k @ M @ k)) @ R
    P = np.array([p for p, _ in pairs])
    S = np.array([R @ s for _, s in pairs])
    # p · Rot(φ) s = A cos φ + B sin φ + C
    A = np.einsum("ij,ij->i", P, S - np.outer(S @ k, k))
    B = np.einsum("ij,ij->i", P, np.cross(k, S))
    C = (P @ k) * (S @ k)

    def residual(phi: float) -> np.ndarray:
        return A * np.cos(phi) + B * np.sin(phi) + C

    def refine(phi: float) -> float:
        for _ in range(20):
            res = residual(phi)
            d1 = -A * np.sin(phi) + B * np.cos(phi)
            d2 = -A * np.cos(phi) - B * np.sin(phi)
            grad, hess = 2 * res @ d1, 2 * (d1 @ d1 + res @ d2)
            if hess <= 0:
                break
            phi -= grad / hess
        return float(phi)

    phis = np.linspace(-np.pi, np.pi, 720, endpoint=False)
    cost = ((np.outer(np.cos(phis), A) + np.outer(np.sin(phis), B) + C) ** 2).sum(axis=1)
    # every sampled local minimum, refined: equally good rolls (a universal joint's arm and its
    # opposite) are told apart by their refined cost, not by where the samples fell
    minima = phis[(cost <= np.roll(cost, 1)) & (cost <= np.roll(cost, -1))]
    refined = [refine(phi) for phi in minima]
    costs = np.array([residual(phi) @ residual(phi) for phi in refined])
    good = [phi for phi, c in zip(refined, costs, strict=True)
            if c <= costs.min() + 1e-9 * max(1.0, costs.min())]
    if reference is None:
        phi = min(good, key=abs)
    else:
        phi = min(good, key=lambda a: np.linalg.norm(axis_rotation(k, a) @ R - reference))
    return axis_rotation(k, phi) @ R


def _place(local: np.ndarray, world: np.ndarray, R0: np.ndarray, r0: np.ndarray,
           perpendicular: list[tuple[np.ndarray, np.ndarray]],
           reference: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    if len(local) >= 3:
        spread = np.linalg.svd(local - local.mean(axis=0), compute_uv=False)
        if spread[1] > 1e-6 * max(spread[0], 1e-12):
            return rigid_fit(local, world)
    if len(local) >= 2:
        far = int(np.argmax(np.linalg.norm(local - local[0], axis=1)))
        if np.linalg.norm(local[far] - local[0]) > 1e-9:
            direction = world[far] - world[0]
            R = rotation_between(R0 @ (local[far] - local[0]), direction) @ R0
            R = best_roll(R, direction, perpendicular, reference)
            return R, world[0] - R @ local[0]
    if len(local) >= 1:
        return R0, world[0] - R0 @ local[0]
    return R0, r0


def _perpendicular_pairs(model, placed: dict, body: str) -> list[tuple[np.ndarray, np.ndarray]]:
    """(world vector of a placed body, local vector of ``body``) pairs that the joints between
    them keep perpendicular: universal arms; a revolute's axis against two perpendiculars."""
    from fccgrb_cli.system.features import perpendiculars

    out = []
    for joint in model.joints:
        if body not in joint.bodies or joint.axes is None:
            continue
        k = joint.bodies.index(body)
        other = joint.bodies[1 - k]
        if other not in placed:
            continue
        mine = np.array(_vectors(model, body)[joint.axes[k]].local)
        theirs = _world_vector(model, placed, other, joint.axes[1 - k])
        if joint.type == "universal":
            out.append((theirs, mine))
        else:
            a, b = perpendiculars(mine)
            out += [(theirs, a), (theirs, b)]
    return out


def _vectors(model, body: str):
    return model.ground.vectors if body == GROUND else model.body(body).vectors


def _world_vector(model, placed: dict, body: str, name: str) -> np.ndarray:
    R, _ = placed[body]
    return R @ np.array(_vectors(model, body)[name].local)


def initial_guess(system: System, targets: np.ndarray) -> np.ndarray:
    """q for the first frame from the tracked markers (targets: n_targets × 3, NaN in gaps)."""
    if system.functions is not None:  # bodies placed by coordinates: fitted in θ alone
        from fccgrb_cli.solvers.moving_initial import moving_initial_guess

        return moving_initial_guess(system, targets)
    model, layout = system.model, system.layout
    q = layout.pose_q(model)
    tracked: dict[str, list[tuple[tuple, np.ndarray]]] = {b.name: [] for b in model.bodies}
    for tp, target in zip(model.tracked_points, targets, strict=False):
        if np.all(np.isfinite(target)):
            tracked[tp.body].append((model.body(tp.body).points[tp.point].local, target))
    placed: dict[str, tuple[np.ndarray, np.ndarray]] = {GROUND: (np.eye(3), np.zeros(3))}

    def place(other: str, parent: str | None = None) -> None:
        pairs = list(tracked[other])
        for j in model.joints:
            if other in j.bodies and j.type in COINCIDENT:
                k = j.bodies.index(other)
                neighbour = j.bodies[1 - k]
                if neighbour in placed:
                    assert j.points is not None  # a coincident joint's two points
                    pairs.append((model.body(other).points[j.points[k]].local,
                                  _global_point(model, placed, neighbour, j.points[1 - k])))
        pose = model.body(other).pose
        R0 = np.column_stack([pose.u, pose.v, pose.w])
        reference = None
        if parent not in (None, GROUND):
            # the model pose as seen from the body it is reached from: a two-point segment
            # takes the roll nearest it, so that a trial facing another way than the model's
            # pose does not turn the segment upside down
            seen = model.body(parent).pose
            reference = placed[parent][0] @ np.column_stack([seen.u, seen.v, seen.w]).T @ R0
        local = np.array([p for p, _ in pairs]).reshape(-1, 3)
        world = np.array([w for _, w in pairs]).reshape(-1, 3)
        placed[other] = _place(local, world, R0, np.array(pose.r),
                               _perpendicular_pairs(model, placed, other), reference)

    # Outward from the ground, then from each floating base (placed by its own markers).
    for root in (GROUND, *model.floating_bases):
        if root not in placed:
            place(root)
        order = deque([root])
        while order:
            here = order.popleft()
            for joint in model.joints:
                if here in joint.bodies:
                    other = joint.bodies[1 - joint.bodies.index(here)]
                    if other not in placed:
                        place(other, here)
                        order.append(other)
    for name, (R, r) in placed.items():
        if name == GROUND:
            continue
        full = np.concatenate([r, R[:, 0], R[:, 1], R[:, 2]])
        sl = layout.q_slice(name)
        q[sl] = full[: sl.stop - sl.start]
    if system.mixed:
        q[layout.n_body_q:] = system.angles_at(q)
    return q


def _global_point(model, placed: dict, body: str, point: str) -> np.ndarray:
    R, r = placed[body]
    if body == GROUND:
        return np.array(model.ground.points[point].local, dtype=float)
    return r + R @ np.array(model.body(body).points[point].local)

"""The test's own kinematics and recursive Newton–Euler for the generated trees
(tests/generated_models.py): nothing here comes from the package.

Forward pass (textbook, its own frames): from the ground (or the floating root's prescribed
motion) outward, each joint first slides its child's joint point Q along parent-fixed axes,
then turns the child about its rotation axes through Q, one after the other:

    ω_c = ω_p + Σ z_k φ̇_k,   α_c = α_p + Σ (z_k φ̈_k + ω_{k−1} × z_k φ̇_k),
    Q = P + R_p Σ ê_k s_k,   a_Q = a_P + α_p × ρ + ω_p × (ω_p × ρ) + 2 ω_p × R_p Σ ê_k ṡ_k
                                   + R_p Σ ê_k s̈_k   (ρ = Q − P_p's point),

z_k the global direction of rotation k (after the joint's earlier rotations), ω_{k−1} the
angular velocity reached before it. A floating root's R = Rz(az) Ry(ay) Rx(ax) R₀ has
ω = ȧz e_z + ȧy Rz e_y + ȧx Rz Ry e_x and α its time derivative (written out below).

Backward pass, from the leaves in: each body's joint wrench (force f, moment n about its joint
point J, parent on child) from Newton and Euler about the centre of mass G,

    f = m (a_G − g) − F_ext + Σ_children f_c,
    n = I_G α + ω × I_G ω − (J − G) × f + Σ_children (n_c + (J_c − G) × f_c)
        − (H − G) × F_ext − N_ext,

and the force conjugate to each joint variable is its motion's share of the joint's power:
z_k · n for a rotation about z_k through J, (R_p ê_k) · f for a slide. A floating root's joint
is the 6-degree-of-freedom base itself, J = its origin: (f, n) is the wrench the base needs.
The package's coordinates θ(φ) follow (angles from their vectors, distances from their
points), and the virtual power Σ Q_φ δφ = Σ τ_θ δθ gives τ_θ = (∂θ/∂φ)⁻ᵀ Q_φ.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from generated_models import Case, rot

E = np.eye(3)


@dataclass
class BodyState:
    R: np.ndarray
    w: np.ndarray
    al: np.ndarray
    r: np.ndarray
    v: np.ndarray
    a: np.ndarray
    J: np.ndarray                        # the joint point (the origin for a floating root)
    zs: list[np.ndarray]                 # global directions of the joint's rotations
    slide_dirs: list[np.ndarray]         # global directions of the joint's slides

    def point(self, local: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Position, velocity and acceleration of a body point."""
        rho = self.R @ local
        return (self.r + rho, self.v + np.cross(self.w, rho),
                self.a + np.cross(self.al, rho) + np.cross(self.w, np.cross(self.w, rho)))

    def vector(self, local: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """A body vector and its first and second time derivatives."""
        s = self.R @ local
        return s, np.cross(self.w, s), np.cross(self.al, s) + np.cross(self.w, np.cross(self.w, s))


GROUND_STATE = BodyState(E, np.zeros(3), np.zeros(3), np.zeros(3), np.zeros(3), np.zeros(3),
                         np.zeros(3), [], [])


def phi_motion(case: Case, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every joint variable φ and its rates (frames × n_phi), joint by joint, slides first."""
    signals = [s for j in case.joints if j is not None for s in j.variables]
    values = np.array([s.at(t) for s in signals])          # n_phi × 3 × frames
    return values[:, 0].T, values[:, 1].T, values[:, 2].T


def _elementary(axis: int, angle: float) -> np.ndarray:
    return rot(E[axis], angle)


def base_motion(case: Case, t: float) -> BodyState:
    """The floating root's prescribed pose, twist and its rate (README's base motion)."""
    root = case.bodies[0]
    tr = np.array([m.at(t) for m in case.base_translation])    # 3 axes × (value, d, dd)
    an = np.array([m.at(t) for m in case.base_rotation])
    ax, ay, az = an[:, 0]
    axd, ayd, azd = an[:, 1]
    axdd, aydd, azdd = an[:, 2]
    Rz, Ry, Rx = _elementary(2, az), _elementary(1, ay), _elementary(0, ax)
    ey_, ex_ = Rz @ E[1], Rz @ Ry @ E[0]
    w_z = azd * E[2]
    w_zy = w_z + ayd * ey_
    w = w_zy + axd * ex_
    al = (azdd * E[2] + aydd * ey_ + ayd * np.cross(w_z, ey_) + axdd * ex_
          + axd * np.cross(w_zy, ex_))
    r = root.r0 + tr[:, 0]
    return BodyState(Rz @ Ry @ Rx @ root.R0, w, al, r, tr[:, 1], tr[:, 2], r, [], [])


def forward(case: Case, t: float, phi: np.ndarray, phid: np.ndarray,
            phidd: np.ndarray) -> list[BodyState]:
    """Every body's state at time t (t matters only for a floating root)."""
    states: list[BodyState] = []
    k = 0
    for joint in case.joints:
        if joint is None:
            states.append(base_motion(case, t))
            continue
        p = GROUND_STATE if joint.parent < 0 else states[joint.parent]
        R_p0 = E if joint.parent < 0 else case.bodies[joint.parent].R0
        P, vP, aP = p.point(joint.p_point)
        slide, slide_d, slide_dd, dirs = np.zeros(3), np.zeros(3), np.zeros(3), []
        for axis in joint.slides:
            e_local = R_p0.T @ joint.frame[:, axis]
            dirs.append(p.R @ e_local)
            slide += dirs[-1] * phi[k]
            slide_d += dirs[-1] * phid[k]
            slide_dd += dirs[-1] * phidd[k]
            k += 1
        J = P + slide
        vJ = vP + np.cross(p.w, slide) + slide_d
        aJ = (aP + np.cross(p.al, slide) + np.cross(p.w, np.cross(p.w, slide))
              + 2 * np.cross(p.w, slide_d) + slide_dd)
        R, w, al, zs = p.R, p.w, p.al, []
        for axis in joint.rotations:
            local = R_p0.T @ joint.frame[:, axis]         # ℓ, in the frame reached so far
            z = R @ local
            al = al + z * phidd[k] + np.cross(w, z) * phid[k]
            w = w + z * phid[k]
            R = R @ rot(local, phi[k])
            zs.append(z)
            k += 1
        R = R @ joint.rel0
        rho = -R @ joint.q_point
        states.append(BodyState(
            R, w, al, J + rho, vJ + np.cross(w, rho),
            aJ + np.cross(al, rho) + np.cross(w, np.cross(w, rho)), J, zs, dirs))
    return states


def _on(states: list[BodyState], i: int) -> BodyState:
    return GROUND_STATE if i < 0 else states[i]


def coordinates(case: Case, states: list[BodyState]) -> np.ndarray:
    """(3, n_coordinates): the package's θ, θ̇, θ̈ (rad or m) by the chain rule on their
    definitions: c = s1·s2 = cos θ, ċ = −θ̇ sin θ, c̈ = −θ̇² cos θ − θ̈ sin θ; d = (r_Q − r_P)·s."""
    out = np.zeros((3, len(case.coordinates)))
    for k, c in enumerate(case.coordinates):
        if c.kind == "angle":
            s1, s1d, s1dd = _on(states, c.a[0]).vector(c.a[1])
            s2, s2d, s2dd = _on(states, c.b[0]).vector(c.b[1])
            cs = s1 @ s2
            csd = s1d @ s2 + s1 @ s2d
            csdd = s1dd @ s2 + 2 * s1d @ s2d + s1 @ s2dd
            th = np.arccos(cs)
            thd = -csd / np.sin(th)
            out[:, k] = th, thd, -(csdd + thd**2 * cs) / np.sin(th)
        else:
            P, vP, aP = _on(states, c.a[0]).point(c.a[1])
            Q, vQ, aQ = _on(states, c.b[0]).point(c.b[1])
            s, sd, sdd = _on(states, c.a[0]).vector(c.axis)
            out[:, k] = ((Q - P) @ s, (vQ - vP) @ s + (Q - P) @ sd,
                         (aQ - aP) @ s + 2 * (vQ - vP) @ sd + (Q - P) @ sdd)
    return out


def coordinate_jacobian(case: Case, states: list[BodyState]) -> np.ndarray:
    """∂θ/∂φ (n_coordinates × n_phi), joint by joint: φ̇_k of a joint moves its child
    relative to its parent only, by a turn z_k about the joint point J (= the child's point Q) or
    a slide d_k; an angle's cosine s1·s2 then changes by s1·(z_k × s2), a distance
    (Q − P)·s by d_k·s (a turn about J leaves Q where it is)."""
    columns = {}
    k = 0
    for i, joint in enumerate(case.joints):
        if joint is None:
            continue
        for d in states[i].slide_dirs:
            columns[k] = (i, "slide", d)
            k += 1
        for z in states[i].zs:
            columns[k] = (i, "turn", z)
            k += 1
    jac = np.zeros((len(case.coordinates), k))
    for row, c in enumerate(case.coordinates):
        if c.kind == "angle":
            s1 = _on(states, c.a[0]).R @ c.a[1]
            s2 = _on(states, c.b[0]).R @ c.b[1]
            sin = np.sqrt(max(0.0, 1.0 - (s1 @ s2) ** 2))
        else:
            s = _on(states, c.a[0]).R @ c.axis
        for col, (body, kind, d) in columns.items():
            if body != c.joint:
                continue
            if c.kind == "angle":
                jac[row, col] = 0.0 if kind == "slide" else -(s1 @ np.cross(d, s2)) / sin
            elif kind == "slide":
                jac[row, col] = d @ s
    return jac


def mass_properties(case: Case, states: list[BodyState], i: int):
    """m, G, v_G, a_G and the global inertia tensor about G."""
    b, s = case.bodies[i], states[i]
    G, vG, aG = s.point(b.com)
    return b.mass, G, vG, aG, s.R @ b.tensor @ s.R.T


def backward(case: Case, states: list[BodyState], force: np.ndarray,
             moment: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """Each body's joint force and moment about its joint point J (parent on child)."""
    n = len(case.bodies)
    wrench: list = [None] * n
    for i in reversed(range(n)):
        s = states[i]
        m, G, _, aG, I_G = mass_properties(case, states, i)
        f = m * (aG - case.gravity)
        nG = I_G @ s.al + np.cross(s.w, I_G @ s.w)
        if i == case.load_body:
            H = s.point(case.load_point)[0]
            f = f - force
            nG = nG - np.cross(H - G, force) - moment
        for c in range(i + 1, n):
            if case.bodies[c].parent == i:
                fc, nc = wrench[c]
                f = f + fc
                nG = nG + nc + np.cross(states[c].J - G, fc)
        wrench[i] = (f, nG - np.cross(s.J - G, f))
    return wrench


@dataclass
class Reference:
    """The test's expectation at a set of times (frames first)."""

    time: np.ndarray
    x: np.ndarray           # every body's [r, u, v, w] (frames × bodies × 12)
    xd: np.ndarray
    xdd: np.ndarray
    theta: np.ndarray       # frames × 3 × n_coordinates (value, first, second derivative)
    tau: np.ndarray         # frames × n_coordinates, N·m or N
    base_force: np.ndarray  # frames × 3: the wrench a floating base needs, about its origin
    base_moment: np.ndarray
    kinetic: np.ndarray
    potential: np.ndarray
    energy_rate: np.ndarray  # d(T + V)/dt, exact
    ext_power: np.ndarray
    base_power: np.ndarray
    load_point: np.ndarray  # frames × 3
    markers: np.ndarray     # frames × markers × 3
    cond: np.ndarray        # cond(∂θ/∂φ) per frame


def body_coordinates(states: list[BodyState]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """[r, u, v, w] of every body and their first and second time derivatives."""
    out = np.zeros((3, len(states), 12))
    for i, s in enumerate(states):
        out[:, i, :3] = s.r, s.v, s.a
        for k in range(3):
            out[:, i, 3 + 3 * k:6 + 3 * k] = s.vector(E[k])
    return out[0], out[1], out[2]


def reference(case: Case, t: np.ndarray, rates: tuple[np.ndarray, np.ndarray] | None = None
              ) -> Reference:
    """Everything the test knows at times t. ``rates``: φ̇, φ̈ to use instead of the closed
    form's (e.g. those of central differences of θ), φ itself staying exact."""
    phi, phid, phidd = phi_motion(case, t)
    if rates is not None:
        phid, phidd = rates
    force, moment = case.load(t)
    acc: dict[str, list] = {k: [] for k in Reference.__dataclass_fields__ if k != "time"}
    for f, tf in enumerate(t):
        states = forward(case, tf, phi[f], phid[f], phidd[f])
        x, xd, xdd = body_coordinates(states)
        acc["x"].append(x)
        acc["xd"].append(xd)
        acc["xdd"].append(xdd)
        acc["theta"].append(coordinates(case, states))
        wrench = backward(case, states, force[f], moment[f])
        q_phi = []
        for i, s in enumerate(states):
            if case.joints[i] is None:
                continue
            fi, ni = wrench[i]
            q_phi += [d @ fi for d in s.slide_dirs] + [z @ ni for z in s.zs]
        jac = coordinate_jacobian(case, states)
        acc["tau"].append(np.linalg.solve(jac.T, np.array(q_phi)))
        acc["cond"].append(np.linalg.cond(jac))
        f0, n0 = wrench[0] if case.floating else (np.zeros(3), np.zeros(3))
        acc["base_force"].append(f0)
        acc["base_moment"].append(n0)
        acc["base_power"].append(f0 @ states[0].v + n0 @ states[0].w if case.floating else 0.0)
        T = V = dE = 0.0
        for i, s in enumerate(states):
            m, G, vG, aG, I_G = mass_properties(case, states, i)
            T += 0.5 * m * vG @ vG + 0.5 * s.w @ I_G @ s.w
            V -= m * case.gravity @ G
            dE += m * vG @ aG + s.w @ I_G @ s.al - m * case.gravity @ vG
        acc["kinetic"].append(T)
        acc["potential"].append(V)
        acc["energy_rate"].append(dE)
        H, vH, _ = states[case.load_body].point(case.load_point)
        acc["load_point"].append(H)
        acc["ext_power"].append(force[f] @ vH + moment[f] @ states[case.load_body].w)
        acc["markers"].append([states[i].point(local)[0] for _, i, local in case.markers])
    return Reference(np.asarray(t, dtype=float), **{k: np.array(v) for k, v in acc.items()})

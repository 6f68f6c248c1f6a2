"""Prescribed motions (used to synthesize trials): a constant plus a sum of sinusoids for each
driven coordinate, and a floating base's translation and rotation built from such sums."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Motion:
    """θ(t) = mean + rate·t + Σ A_i sin(2π f_i t + φ_i), in SI units (rad or m; rate per s),
    frequencies in Hz. A non-zero ``rate`` turns a crank (or slides a carriage) steadily."""

    mean: float
    terms: tuple[tuple[float, float, float], ...] = ()
    rate: float = 0.0

    def bounds(self) -> tuple[float, float]:
        """Guaranteed lower and upper bound of θ(t) over all t (infinite with a rate)."""
        if self.rate:
            return -np.inf, np.inf
        spread = sum(abs(a) for a, _, _ in self.terms)
        return self.mean - spread, self.mean + spread

    def evaluate(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """θ, θ̇ and θ̈ at the times t (s), each shaped like t."""
        t = np.asarray(t, dtype=float)
        theta = self.mean + self.rate * t
        theta_d = np.full_like(t, self.rate)
        theta_dd = np.zeros_like(t)
        for amplitude, frequency, phase in self.terms:
            omega = 2.0 * np.pi * frequency
            arg = omega * t + phase
            theta += amplitude * np.sin(arg)
            theta_d += amplitude * omega * np.cos(arg)
            theta_dd -= amplitude * omega**2 * np.sin(arg)
        return theta, theta_d, theta_dd


STILL = Motion(0.0)


def _axis_rotations(axis: int, angle: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """R, dR/dα and d²R/dα² (… × 3 × 3) of rotations by α about the fixed axis x, y or z."""
    c, s = np.cos(angle), np.sin(angle)
    i, j = [k for k in range(3) if k != axis]
    # R[i, i] = R[j, j] = c, R[j, i] = s, R[i, j] = −s, R[axis, axis] = 1 (right-handed: the
    # cyclic pair (i, j) follows ``axis``; y's pair is (z, x), i.e. the sign flips for (x, z)).
    sign = -1.0 if axis == 1 else 1.0
    out = [np.zeros((*np.shape(angle), 3, 3)) for _ in range(3)]
    for k, (cc, ss) in enumerate(((c, s), (-s, c), (-c, -s))):
        out[k][..., i, i] = out[k][..., j, j] = cc
        out[k][..., j, i] = sign * ss
        out[k][..., i, j] = -sign * ss
    out[0][..., axis, axis] = 1.0
    return out[0], out[1], out[2]


@dataclass(frozen=True)
class BaseMotion:
    """A floating base's prescribed motion: its origin r(t) = r₀ + [tx, ty, tz](t) (m) and its
    frame (u, v, w)(t) = Rz(az) Ry(ay) Rx(ax) (u₀, v₀, w₀), the angles (rad) about the ground's
    fixed x, y, z axes, x first."""

    translation: tuple[Motion, Motion, Motion] = (STILL, STILL, STILL)
    rotation: tuple[Motion, Motion, Motion] = (STILL, STILL, STILL)

    def rotation_matrix(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """R(t), Ṙ(t), R̈(t) (frames × 3 × 3), by the product rule on R = Rz Ry Rx."""
        t = np.asarray(t, dtype=float)
        factors = []
        for axis in (2, 1, 0):  # Rz, Ry, Rx left to right
            a, ad, add = self.rotation[axis].evaluate(t)
            R, R1, R2 = _axis_rotations(axis, a)
            factors.append((R, R1 * ad[..., None, None],
                            R2 * (ad**2)[..., None, None] + R1 * add[..., None, None]))
        (Z, Zd, Zdd), (Y, Yd, Ydd), (X, Xd, Xdd) = factors
        R = Z @ Y @ X
        Rd = Zd @ Y @ X + Z @ Yd @ X + Z @ Y @ Xd
        Rdd = (Zdd @ Y @ X + Z @ Ydd @ X + Z @ Y @ Xdd
               + 2.0 * (Zd @ Yd @ X + Zd @ Y @ Xd + Z @ Yd @ Xd))
        return R, Rd, Rdd

    def frames(self, t: np.ndarray, pose: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The base's [r, u, v, w] (frames × 4 × 3) and their first and second time
        derivatives, from its stated pose [r₀, u₀, v₀, w₀] (4 × 3)."""
        t = np.asarray(t, dtype=float)
        pose = np.asarray(pose, dtype=float).reshape(4, 3)
        R = self.rotation_matrix(t)
        shift = [np.column_stack([m.evaluate(t)[k] for m in self.translation]) for k in range(3)]
        out = []
        for k in range(3):
            axes = np.einsum("fij,aj->fai", R[k], pose[1:])
            origin = (pose[0] if k == 0 else 0.0) + shift[k]
            out.append(np.concatenate([origin[:, None, :], axes], axis=1))
        return out[0], out[1], out[2]

"""A floating base's orientation as a smoothable coordinate: the rotation vector φ of
R = exp([φ]×) R₀ about a reference orientation R₀ (Rodrigues), stacked over frames.

Its rates give the base's angular velocity and acceleration through the left Jacobian
J(φ) = I + a(θ) [φ]× + b(θ) [φ]×², a = (1 − cos θ)/θ², b = (θ − sin θ)/θ³, θ = |φ|:
ω = J(φ) φ̇ and α = J(φ) φ̈ + J̇ φ̇, where (with v = φ̇)
J̇ v = (a′(θ) φ × v + b′(θ) φ × (φ × v)) (φ·v)/θ + b(θ) v × (φ × v).
Arrays carry frames first; small angles take the series of a, b, a′/θ and b′/θ.
"""

from __future__ import annotations

import numpy as np

SMALL = 1e-4  # rad: below, the series


def skew(v: np.ndarray) -> np.ndarray:
    """[v]× of every vector (… × 3 → … × 3 × 3)."""
    out = np.zeros((*v.shape, 3))
    out[..., 0, 1], out[..., 0, 2] = -v[..., 2], v[..., 1]
    out[..., 1, 0], out[..., 1, 2] = v[..., 2], -v[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -v[..., 1], v[..., 0]
    return out


def _coefficients(theta: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """a, b, a′/θ and b′/θ of the left Jacobian (series below SMALL)."""
    t = np.where(theta < SMALL, 1.0, theta)
    t2 = theta * theta
    a = np.where(theta < SMALL, 0.5 - t2 / 24.0, (1.0 - np.cos(t)) / t**2)
    b = np.where(theta < SMALL, 1.0 / 6.0 - t2 / 120.0, (t - np.sin(t)) / t**3)
    da = np.where(theta < SMALL, -1.0 / 12.0 + t2 / 180.0,
                  (t * np.sin(t) - 2.0 * (1.0 - np.cos(t))) / t**4)
    db = np.where(theta < SMALL, -1.0 / 60.0 + t2 / 1260.0,
                  (3.0 * np.sin(t) - 2.0 * t - t * np.cos(t)) / t**5)
    return a, b, da, db


def exp_map(phi: np.ndarray) -> np.ndarray:
    """exp([φ]×) (… × 3 × 3): I + sin θ/θ [φ]× + (1 − cos θ)/θ² [φ]×²."""
    theta = np.linalg.norm(phi, axis=-1)
    t = np.where(theta < SMALL, 1.0, theta)
    s = np.where(theta < SMALL, 1.0 - theta**2 / 6.0, np.sin(t) / t)
    a = _coefficients(theta)[0]
    K = skew(phi)
    return np.eye(3) + s[..., None, None] * K + a[..., None, None] * (K @ K)


def log_map(R: np.ndarray) -> np.ndarray:
    """φ with exp([φ]×) = R, |φ| ≤ π (… × 3 × 3 → … × 3)."""
    cos = np.clip((np.trace(R, axis1=-2, axis2=-1) - 1.0) / 2.0, -1.0, 1.0)
    theta = np.arccos(cos)
    w = np.stack([R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0],
                  R[..., 1, 0] - R[..., 0, 1]], axis=-1)
    s = np.sin(theta)
    small = theta < SMALL
    near_pi = np.pi - theta < 1e-3
    scale = np.where(small, 0.5 + theta**2 / 12.0, theta / (2.0 * np.where(small, 1.0, s)))
    phi = w * scale[..., None]
    if near_pi.any():  # the axis from R + I's largest column; the sign from w
        for index in zip(*np.nonzero(near_pi), strict=False):
            B = (R[index] + np.eye(3)) / 2.0
            k = int(np.argmax(np.diag(B)))
            axis = B[:, k] / np.sqrt(max(B[k, k], 1e-300))
            if w[index] @ axis < 0:
                axis = -axis
            phi[index] = theta[index] * axis
    return phi


def unwrapped(phi: np.ndarray) -> np.ndarray:
    """A continuous rotation-vector path (frames × 3): each frame's φ or its equivalent
    φ (1 − 2π/|φ|), whichever is nearer the previous frame's (as np.unwrap does for an angle)."""
    out = phi.copy()
    for f in range(1, len(out)):
        theta = np.linalg.norm(out[f])
        if theta < SMALL:
            continue
        other = out[f] * (1.0 - 2.0 * np.pi / theta)
        if np.linalg.norm(other - out[f - 1]) < np.linalg.norm(out[f] - out[f - 1]):
            out[f] = other
    return out


def left_jacobian(phi: np.ndarray) -> np.ndarray:
    """J(φ) (… × 3 × 3): ω = J(φ) φ̇."""
    theta = np.linalg.norm(phi, axis=-1)
    a, b, _, _ = _coefficients(theta)
    K = skew(phi)
    return np.eye(3) + a[..., None, None] * K + b[..., None, None] * (K @ K)


def jacobian_rate(phi: np.ndarray, phi_d: np.ndarray) -> np.ndarray:
    """J̇ φ̇ (… × 3): the part of the angular acceleration that φ̈ = 0 leaves."""
    theta = np.linalg.norm(phi, axis=-1)
    _, b, da, db = _coefficients(theta)
    cross = np.cross(phi, phi_d)
    along = np.einsum("...i,...i->...", phi, phi_d)
    return ((da * along)[..., None] * cross + (db * along)[..., None] * np.cross(phi, cross)
            + b[..., None] * np.cross(phi_d, cross))


def mean_rotation(R: np.ndarray) -> np.ndarray:
    """The rotation nearest the mean of the given ones (frames × 3 × 3 → 3 × 3; the chordal
    mean: the polar factor of ΣR)."""
    U, _, Vt = np.linalg.svd(R.sum(axis=0))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    return U @ D @ Vt

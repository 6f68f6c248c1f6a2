"""Mass matrices and gravity of generic rigid bodies in the fully-defined coordinates x.

For a body with x_i = [r, u, v, w], a point with local (a, b, c) moves as C x_i with
C = [1, a, b, c] ⊗ I3, so T_i = ½ ẋ_iᵀ (K_i ⊗ I3) ẋ_i with K_i = ∫ [1,a,b,c]ᵀ[1,a,b,c] dm
(docs/formulation.md §4). With the centre of mass at local c̄ and the inertia tensor I_G about it
(body frame): K = [[m, m c̄ᵀ], [m c̄, m c̄ c̄ᵀ + ½ tr(I_G) I − I_G]]. Reduced bodies use the same
matrix on their fully-defined equivalent (Eq. 5); the map to q happens in the inverse dynamics.
"""

from __future__ import annotations

import numpy as np

from fccgrb_cli.core.errors import InputError
from fccgrb_cli.model import Inertia, Model


def inertia_coefficients(inertia: Inertia) -> np.ndarray:
    """K (4 × 4) of one body."""
    m = inertia.mass
    c = np.asarray(inertia.com, dtype=float)
    I_G = np.asarray(inertia.tensor, dtype=float)
    second_moment = 0.5 * np.trace(I_G) * np.eye(3) - I_G
    K = np.empty((4, 4))
    K[0, 0] = m
    K[0, 1:] = K[1:, 0] = m * c
    K[1:, 1:] = m * np.outer(c, c) + second_moment
    return K


def _inertias(model: Model) -> list[Inertia]:
    missing = [b.name for b in model.bodies if b.inertia is None]
    if missing:
        raise InputError(f"{model.source}: bodies.{missing[0]}: expected mass and inertia for "
                         f"inverse dynamics (missing for {', '.join(missing)})")
    return [b.inertia for b in model.bodies if b.inertia is not None]  # every one, as checked


def mass_blocks(model: Model) -> np.ndarray:
    """Every body's K (bodies × 4 × 4), in the order of x."""
    return np.array([inertia_coefficients(i) for i in _inertias(model)]).reshape(-1, 4, 4)


def mass_matrix(model: Model) -> np.ndarray:
    """M_x = blockdiag(K_i ⊗ I3) (nx × nx), constant."""
    blocks = [np.kron(K, np.eye(3)) for K in mass_blocks(model)]
    n = 12 * len(blocks)
    M = np.zeros((n, n))
    for k, block in enumerate(blocks):
        M[12 * k:12 * k + 12, 12 * k:12 * k + 12] = block
    return M


def gravity_forces(model: Model) -> np.ndarray:
    """g_x: gravity's generalized force, C_Gᵀ (m g) per body (nx,)."""
    g = np.asarray(model.gravity, dtype=float)
    out = []
    for inertia in _inertias(model):
        out.append(np.kron(np.array([1.0, *inertia.com]), inertia.mass * g))
    return np.concatenate(out)

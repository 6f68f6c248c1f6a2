"""Index maps between the system coordinates q (Eq. 9) and the fully-defined equivalent x (Eq. 5).

q = [q_1 … q_nb, θ_1 … θ_nd]: 12 numbers per fully-defined body [r, u, v, w], 9 per reduced body
[r, u, v], then the mixed (angular) coordinates. x holds 12 numbers per body, w = u × v for reduced
bodies, so every constraint is written once on x and reaches q through X_q = ∂x/∂q = V (Eq. 7).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fccgrb_cli.model import Model


@dataclass(frozen=True)
class Layout:
    """Where each body's coordinates live in q and in x."""

    body_names: tuple[str, ...]
    forms: tuple[str, ...]
    q_offsets: tuple[int, ...]
    n_body_q: int
    angle_names: tuple[str, ...]
    copy_x: np.ndarray
    copy_q: np.ndarray
    reduced_u: np.ndarray
    reduced_v: np.ndarray
    reduced_w: np.ndarray

    @property
    def nq(self) -> int:
        return self.n_body_q + len(self.angle_names)

    @property
    def nx(self) -> int:
        return 12 * len(self.body_names)

    def x_offset(self, body: str) -> int:
        return 12 * self.body_names.index(body)

    def q_slice(self, body: str) -> slice:
        k = self.body_names.index(body)
        return slice(self.q_offsets[k], self.q_offsets[k] + (12 if self.forms[k] == "full" else 9))

    def expand(self, q: np.ndarray) -> np.ndarray:
        """x = S V q (Eq. 5): the fully-defined equivalent of q's body coordinates."""
        x = np.empty(self.nx)
        x[self.copy_x] = q[self.copy_q]
        if len(self.reduced_w):
            x[self.reduced_w] = np.cross(q[self.reduced_u], q[self.reduced_v])
        return x

    def expand_rate(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """ẋ = X_q q̇."""
        xd = np.empty(self.nx)
        xd[self.copy_x] = qd[self.copy_q]
        if len(self.reduced_w):
            u, v = q[self.reduced_u], q[self.reduced_v]
            ud, vd = qd[self.reduced_u], qd[self.reduced_v]
            xd[self.reduced_w] = np.cross(ud, v) + np.cross(u, vd)
        return xd

    def expand_jacobian(self, q: np.ndarray) -> np.ndarray | None:
        """X_q = ∂x/∂q over the body coordinates (nx × n_body_q); None when it is the identity."""
        if not len(self.reduced_w) and self.n_body_q == self.nx:
            return None
        xq = np.zeros((self.nx, self.n_body_q))
        xq[self.copy_x, self.copy_q] = 1.0
        if len(self.reduced_w):
            rows = self.reduced_w[:, :, None]
            xq[rows, self.reduced_u[:, None, :]] = -skew(q[self.reduced_v])
            xq[rows, self.reduced_v[:, None, :]] = skew(q[self.reduced_u])
        return xq

    def expand_bias(self, qd: np.ndarray) -> np.ndarray:
        """ẍ − X_q q̈ = V̇ q̇: zero except 2 u̇ × v̇ in the w block of each reduced body (Eq. 36)."""
        bias = np.zeros(self.nx)
        if len(self.reduced_w):
            bias[self.reduced_w] = 2.0 * np.cross(qd[self.reduced_u], qd[self.reduced_v])
        return bias

    def pose_q(self, model: Model, theta: np.ndarray | None = None) -> np.ndarray:
        """q at the model's stated initial pose (θ entries from ``theta`` or zero)."""
        q = np.zeros(self.nq)
        for name, form, offset in zip(self.body_names, self.forms, self.q_offsets, strict=True):
            full = model.body(name).pose.as_array()
            q[offset:offset + (12 if form == "full" else 9)] = full[: 12 if form == "full" else 9]
        if theta is not None:
            q[self.n_body_q:] = theta
        return q


def skew(a: np.ndarray) -> np.ndarray:
    """Cross-product matrices ã (…, 3, 3) with ã b = a × b."""
    out = np.zeros((*a.shape[:-1], 3, 3))
    out[..., 0, 1], out[..., 0, 2] = -a[..., 2], a[..., 1]
    out[..., 1, 0], out[..., 1, 2] = a[..., 2], -a[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -a[..., 1], a[..., 0]
    return out


def build_layout(model: Model, angle_names: tuple[str, ...]) -> Layout:
    """Index maps for the model's bodies followed by the given mixed coordinates."""
    offsets: list[int] = []
    copy_x: list[int] = []
    copy_q: list[int] = []
    red_u: list[range] = []
    red_v: list[range] = []
    red_w: list[range] = []
    q = 0
    for k, body in enumerate(model.bodies):
        offsets.append(q)
        n = body.ncoord
        copy_x.extend(range(12 * k, 12 * k + n))
        copy_q.extend(range(q, q + n))
        if body.form == "reduced":
            red_u.append(range(q + 3, q + 6))
            red_v.append(range(q + 6, q + 9))
            red_w.append(range(12 * k + 9, 12 * k + 12))
        q += n

    def block(rows: list) -> np.ndarray:
        return np.array([list(r) for r in rows], dtype=int).reshape(-1, 3)

    return Layout(
        body_names=tuple(b.name for b in model.bodies),
        forms=tuple(b.form for b in model.bodies),
        q_offsets=tuple(offsets),
        n_body_q=q,
        angle_names=angle_names,
        copy_x=np.array(copy_x, dtype=int),
        copy_q=np.array(copy_q, dtype=int),
        reduced_u=block(red_u),
        reduced_v=block(red_v),
        reduced_w=block(red_w),
    )

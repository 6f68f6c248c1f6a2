"""All moving joints' transforms evaluated together (the per-iteration work of a solve).

The same mathematics as :meth:`fccgrb_cli.model.spatial.SpatialTransform.terms`, stacked over
joints: every joint padded to three rotations and three translations (a missing one turns or
slides by zero), the rotation factors R_k = I + sin a ñ + (1 − cos a) ñ², their derivatives
ñ R_k and ñ² R_k, and the products through prefixes and suffixes, as batched 3 × 3 matrix
products instead of a Python loop per joint. The amounts' functions are still called one by one
(each is its own kind of function).
"""

from __future__ import annotations

from functools import cached_property

import numpy as np

from fccgrb_cli.model.spatial import Pieces, skew3

__all__ = ["StackedTransforms"]


class _Zero:
    """f = 0: a padding axis."""

    def terms(self, x: float) -> tuple[float, float, float]:
        return 0.0, 0.0, 0.0

    def pieces(self) -> Pieces:
        return Pieces.polynomial([0.0])


class StackedTransforms:
    """The transforms of ``joints`` ((first row, transform, θ indices) each) over n_θ
    coordinates."""

    def __init__(self, joints: tuple, n_theta: int):
        self.n_theta = n_theta
        J = len(joints)
        self.first = np.array([first for first, _, _ in joints], dtype=int)
        self.K = np.zeros((J, 3, 3, 3))
        self.t = np.zeros((J, 3, 3))
        self.rot_slot = np.full((J, 3), -1, dtype=int)
        self.tr_slot = np.full((J, 3), -1, dtype=int)
        self.rot_fn: list = []
        self.tr_fn: list = []
        for j, (_, transform, index) in enumerate(joints):
            local = dict(zip(transform.coordinates, index, strict=True))
            rotations = [a for a in transform.axes if a.kind == "rotation"]
            translations = [a for a in transform.axes if a.kind == "translation"]
            for k in range(3):
                if k < len(rotations):
                    a = rotations[k]
                    self.K[j, k] = skew3(np.asarray(a.axis, dtype=float))
                    self.rot_slot[j, k] = local.get(a.coordinate, -1) if a.coordinate else -1
                    self.rot_fn.append(a.function)
                else:
                    self.rot_fn.append(_Zero())
                if k < len(translations):
                    a = translations[k]
                    self.t[j, k] = np.asarray(a.axis, dtype=float)
                    self.tr_slot[j, k] = local.get(a.coordinate, -1) if a.coordinate else -1
                    self.tr_fn.append(a.function)
                else:
                    self.tr_fn.append(_Zero())
        self.KK = self.K @ self.K
        self.rot_rows = self.first[:, None] + np.arange(9)
        self.tr_rows = self.first[:, None] + 9 + np.arange(3)

    @staticmethod
    def _amounts(functions: list, slots: np.ndarray, theta: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        x = np.where(slots >= 0, theta[np.maximum(slots, 0)], 0.0).ravel()
        values = np.array([f.terms(float(v)) for f, v in zip(functions, x, strict=True)])
        value, first, second = (values[:, i].reshape(slots.shape) for i in range(3))
        return value, first, second

    def transforms(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """R_PC (frames × joints × 3 × 3) and p_PC (frames × joints × 3) of every joint at
        every frame of θ (frames × n_θ): the values of :meth:`add`'s rows, all frames at once."""
        theta = np.asarray(theta, dtype=float)
        rotations, translations = self._pieces
        a = self._frame_amounts(self.rot_fn, rotations, self.rot_slot, theta)  # frames × J × 3
        s, c = np.sin(a)[..., None, None], (1.0 - np.cos(a))[..., None, None]
        R = np.eye(3) + s * self.K + c * self.KK                     # frames × J × 3 × 3 × 3
        b = self._frame_amounts(self.tr_fn, translations, self.tr_slot, theta)
        return R[:, :, 0] @ R[:, :, 1] @ R[:, :, 2], np.einsum("fjm,jmi->fji", b, self.t)

    @cached_property
    def _pieces(self) -> tuple[list, list]:
        """Every rotation's and translation's function as polynomial pieces (None: it has
        none), found once for :meth:`transforms`."""
        return [f.pieces() for f in self.rot_fn], [f.pieces() for f in self.tr_fn]

    @staticmethod
    def _frame_amounts(functions: list, pieces: list, slots: np.ndarray, theta: np.ndarray
                       ) -> np.ndarray:
        """Every axis's amount at every frame (frames × J × 3): by its function's pieces, or
        one x at a time where it has none."""
        x = np.where(slots >= 0, theta[:, np.maximum(slots, 0)], 0.0)  # frames × J × 3
        out = np.empty_like(x)
        for k, (function, form) in enumerate(zip(functions, pieces, strict=True)):
            j, axis = divmod(k, 3)
            out[:, j, axis] = form.values(x[:, j, axis]) if form is not None else \
                [function.terms(float(v))[0] for v in x[:, j, axis]]
        return out

    def add(self, theta: np.ndarray, second: bool, h: np.ndarray, h1: np.ndarray,
            h2: np.ndarray) -> None:
        """Write h and add ∂h/∂θ (and ∂²h/∂θ² when ``second``) of every joint's 12 rows."""
        f, d1, d2 = self._amounts(self.rot_fn, self.rot_slot, theta)
        s, c = np.sin(f)[..., None, None], (1.0 - np.cos(f))[..., None, None]
        R = np.eye(3) + s * self.K + c * self.KK          # (J, 3 axes, 3, 3)
        G1, G2 = self.K @ R, self.KK @ R
        eye = np.broadcast_to(np.eye(3), R[:, 0].shape)
        prefix = [eye, R[:, 0], R[:, 0] @ R[:, 1]]
        suffix = [R[:, 0] @ R[:, 1] @ R[:, 2], R[:, 1] @ R[:, 2], R[:, 2], eye]
        h[self.rot_rows] = (prefix[2] @ R[:, 2]).reshape(-1, 9)
        first = [prefix[a] @ G1[:, a] @ suffix[a + 1] for a in range(3)]
        for a in range(3):
            on = self.rot_slot[:, a] >= 0
            rows, col = self.rot_rows[on], self.rot_slot[on, a][:, None]
            np.add.at(h1, (rows, col), d1[on, a][:, None] * first[a][on].reshape(-1, 9))
            if second:
                diagonal = d2[on, a][:, None, None] * first[a][on] + \
                    (d1[on, a] ** 2)[:, None, None] * (prefix[a] @ G2[:, a] @ suffix[a + 1])[on]
                np.add.at(h2, (rows, col, col), diagonal.reshape(-1, 9))
        if second:
            pairs = {(0, 1): G1[:, 0] @ G1[:, 1] @ R[:, 2],
                     (0, 2): G1[:, 0] @ R[:, 1] @ G1[:, 2],
                     (1, 2): R[:, 0] @ G1[:, 1] @ G1[:, 2]}
            for (a, b), product in pairs.items():
                on = (self.rot_slot[:, a] >= 0) & (self.rot_slot[:, b] >= 0)
                rows = self.rot_rows[on]
                ca, cb = self.rot_slot[on, a][:, None], self.rot_slot[on, b][:, None]
                both = ((d1[on, a] * d1[on, b])[:, None, None] * product[on]).reshape(-1, 9)
                np.add.at(h2, (rows, ca, cb), both)
                np.add.at(h2, (rows, cb, ca), both)
        g, e1, e2 = self._amounts(self.tr_fn, self.tr_slot, theta)
        h[self.tr_rows] = np.einsum("jm,jmi->ji", g, self.t)
        for m in range(3):
            on = self.tr_slot[:, m] >= 0
            rows, col = self.tr_rows[on], self.tr_slot[on, m][:, None]
            np.add.at(h1, (rows, col), e1[on, m][:, None] * self.t[on, m])
            if second:
                np.add.at(h2, (rows, col, col), e2[on, m][:, None] * self.t[on, m])

"""Compiled h, ∂h/∂θ and ∂²h/∂θ² of the function rows (moving joints and couplings of an
imported OpenSim model) on the arrays of :class:`~fccgrb_cli.system.moving_tables.MovingRows`:
the mathematics of :class:`~fccgrb_cli.system.moving.FunctionRows` (joints as
system/moving_batch.py stacks them), one joint at a time in machine code, each function of one
coordinate from its polynomial pieces.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from fccgrb_cli.system.moving_tables import FunctionTable, MovingRows


@njit(cache=True)
def function_terms(table: FunctionTable, f: int, x: float) -> tuple[float, float, float]:
    """f(x), f′(x), f″(x) of the table's function ``f`` (the piece that holds x, Horner's
    rule with its two derivatives)."""
    k0, k1 = table.kptr[f], table.kptr[f + 1]
    m = k1 - k0
    piece = 0
    if m > 0:
        if x < table.knots[k0]:
            piece = 0
        elif x > table.knots[k1 - 1]:
            piece = m
        else:  # the last knot ≤ x among the first m − 1 (the last interval is closed)
            lo, hi = 0, m - 2
            while lo < hi:
                mid = (lo + hi + 1) // 2
                if table.knots[k0 + mid] <= x:
                    lo = mid
                else:
                    hi = mid - 1
            piece = lo + 1
    p = table.pptr[f] + piece
    dx = x - table.origin[p]
    value = d1 = d2 = 0.0
    for c in range(table.cptr[p + 1] - 1, table.cptr[p] - 1, -1):
        d2 = d2 * dx + 2.0 * d1
        d1 = d1 * dx + value
        value = value * dx + table.coef[c]
    return value, d1, d2


@njit(cache=True)
def _product(A: np.ndarray, B: np.ndarray, out: np.ndarray) -> None:
    """out = A B (3 × 3; out distinct from A and B)."""
    for i in range(3):
        for j in range(3):
            out[i, j] = A[i, 0] * B[0, j] + A[i, 1] * B[1, j] + A[i, 2] * B[2, j]


@njit(cache=True)
def _triple(A: np.ndarray, B: np.ndarray, C: np.ndarray, work: np.ndarray,
            out: np.ndarray) -> None:
    """out = A B C (``work`` 3 × 3 scratch)."""
    _product(A, B, work)
    _product(work, C, out)


@njit(cache=True)
def _amount(m: MovingRows, fn: int, slot: int, row: int, theta: np.ndarray
            ) -> tuple[float, float, float]:
    """An axis's amount and its derivatives: 0 without a function, f(0) without a coordinate."""
    if fn < 0:
        return 0.0, 0.0, 0.0
    x = theta[m.cols[row, slot]] if slot >= 0 else 0.0
    return function_terms(m.table, fn, x)


@njit(cache=True)
def row_terms(m: MovingRows, theta: np.ndarray, order: int, h: np.ndarray, d1: np.ndarray,
              d2: np.ndarray) -> None:
    """h (rows), and with ``order`` ≥ 1 ∂h/∂θ (rows × width, local columns ``m.cols``), with
    ``order`` 2 ∂²h/∂θ² (rows × width × width) of every function row at θ: a joint's
    R_PC = R_1 R_2 R_3 row by row then p_PC, a coupling's f(θ_i) − θ_d."""
    if order >= 1:
        d1[:] = 0.0
    if order >= 2:
        d2[:] = 0.0
    R, G1, G2 = np.empty((3, 3, 3)), np.empty((3, 3, 3)), np.empty((3, 3, 3))
    prefix, suffix = np.empty((3, 3, 3)), np.empty((4, 3, 3))
    work, out, eye = np.empty((3, 3)), np.empty((3, 3)), np.eye(3)
    f, e1, e2 = np.empty(3), np.empty(3), np.empty(3)
    for j in range(len(m.first)):
        r0 = m.first[j]
        for a in range(3):
            f[a], e1[a], e2[a] = _amount(m, m.rot_fn[j, a], m.rot_slot[j, a], r0, theta)
            s, c = np.sin(f[a]), 1.0 - np.cos(f[a])
            for i in range(3):
                for k in range(3):
                    R[a, i, k] = eye[i, k] + s * m.K[j, a, i, k] + c * m.KK[j, a, i, k]
        prefix[0] = eye
        prefix[1] = R[0]
        _product(R[0], R[1], prefix[2])
        suffix[3] = eye
        suffix[2] = R[2]
        _product(R[1], R[2], suffix[1])
        _product(prefix[2], R[2], out)
        for i in range(3):
            for k in range(3):
                h[r0 + 3 * i + k] = out[i, k]
        if order >= 1:
            for a in range(3):
                _product(m.K[j, a], R[a], G1[a])
                _product(m.KK[j, a], R[a], G2[a])
            for a in range(3):
                slot = m.rot_slot[j, a]
                if slot < 0 or m.rot_fn[j, a] < 0:
                    continue
                _triple(prefix[a], G1[a], suffix[a + 1], work, out)
                for i in range(9):
                    d1[r0 + i, slot] += e1[a] * out[i // 3, i % 3]
                if order >= 2:
                    for i in range(9):
                        d2[r0 + i, slot, slot] += e2[a] * out[i // 3, i % 3]
                    _triple(prefix[a], G2[a], suffix[a + 1], work, out)
                    for i in range(9):
                        d2[r0 + i, slot, slot] += e1[a] ** 2 * out[i // 3, i % 3]
            if order >= 2:
                for a in range(3):
                    for b in range(a + 1, 3):
                        sa, sb = m.rot_slot[j, a], m.rot_slot[j, b]
                        if sa < 0 or sb < 0 or m.rot_fn[j, a] < 0 or m.rot_fn[j, b] < 0:
                            continue
                        # ∂²/∂a∂b: G1 in slots a and b, R elsewhere
                        _triple(G1[0] if a == 0 else R[0], G1[1] if a == 1 or b == 1 else R[1],
                                G1[2] if b == 2 else R[2], work, out)
                        both = e1[a] * e1[b]
                        for i in range(9):
                            d2[r0 + i, sa, sb] += both * out[i // 3, i % 3]
                            d2[r0 + i, sb, sa] += both * out[i // 3, i % 3]
        for i in range(3):
            h[r0 + 9 + i] = 0.0
        for a in range(3):
            slot = m.tr_slot[j, a]
            g, g1, g2 = _amount(m, m.tr_fn[j, a], slot, r0, theta)
            for i in range(3):
                h[r0 + 9 + i] += g * m.t[j, a, i]
                if slot >= 0 and order >= 1:
                    d1[r0 + 9 + i, slot] += g1 * m.t[j, a, i]
                    if order >= 2:
                        d2[r0 + 9 + i, slot, slot] += g2 * m.t[j, a, i]
    for c in range(len(m.coupled)):
        r = m.coupled[c]
        dependent, independent = m.cols[r, 0], m.cols[r, 1]
        x = theta[independent] if independent >= 0 else 0.0
        g, g1, g2 = function_terms(m.table, m.coupled_fn[c], x)
        h[r] = g - theta[dependent]  # θ_d − f(θ_i) = −h
        if order >= 1:
            d1[r, 0] -= 1.0
            if independent >= 0:
                d1[r, 1] += g1
                if order >= 2:
                    d2[r, 1, 1] += g2

"""The function rows of moving joints and couplings (system/moving.py) as constant arrays the
compiled kernels read (fccgrb_cli/solvers/moving_kernels.py): every function of one coordinate
as its polynomial pieces (``Function.pieces``, model/osim/functions.py), every joint as its
axes and the functions and coordinates that move them, every coupling as its function. The
rows' ∂h/∂θ columns are local: ``cols[i]`` lists the coordinates (θ indices, −1 unused) a row
depends on, the joint's (or the coupling's: dependent, independent) in the order of
``FunctionRows``.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from fccgrb_cli.model.spatial import skew3
from fccgrb_cli.system.moving import FunctionRows

__all__ = ["FunctionTable", "MovingRows", "moving_rows", "no_moving_rows"]


class FunctionTable(NamedTuple):
    """Functions of one coordinate as polynomial pieces (``Pieces``): function f has the
    knots ``knots[kptr[f]:kptr[f+1]]`` and the pieces ``pptr[f]`` … ``pptr[f+1] − 1``; piece p
    is Σ_j coef[cptr[p] + j] (x − origin[p])^j."""

    kptr: np.ndarray
    knots: np.ndarray
    pptr: np.ndarray
    origin: np.ndarray
    cptr: np.ndarray
    coef: np.ndarray


class MovingRows(NamedTuple):
    """The function rows of a system: ``rows`` their dot rows; ``cols`` (rows × width) each
    row's local θ columns, ``pos`` the CSR positions of −∂h/∂θ in Φ_q (−1: none; set by
    sparse_system). Joint j: its first function row ``first[j]``, its rotations' ñ and ñ²
    (``K``, ``KK``: 3 axes × 3 × 3, zero when absent), its translations' axes ``t`` (3 × 3),
    the functions (``rot_fn``, ``tr_fn``: index into ``table``, −1 none) and their local
    columns (``rot_slot``, ``tr_slot``: −1 constant, evaluated at 0). Coupling c: its function
    row ``coupled[c]`` (local columns: dependent, independent or −1) and function
    ``coupled_fn[c]``."""

    rows: np.ndarray
    cols: np.ndarray
    pos: np.ndarray
    first: np.ndarray
    K: np.ndarray
    KK: np.ndarray
    t: np.ndarray
    rot_fn: np.ndarray
    rot_slot: np.ndarray
    tr_fn: np.ndarray
    tr_slot: np.ndarray
    coupled: np.ndarray
    coupled_fn: np.ndarray
    table: FunctionTable


def no_moving_rows() -> MovingRows:
    """The empty arrays of a system without function rows (the kernels' types stay the same)."""
    return _assembled([], np.zeros((0, 2), dtype=np.int64), [], [], [], [])


def moving_rows(functions: FunctionRows) -> MovingRows | str:
    """The arrays of ``functions``; where a function has no polynomial pieces, the name of its
    kind (such a model stays with the numpy reference engine)."""
    joints = functions.joints
    width = max([2, *(len(index) for _, _, index in joints)])
    cols = np.full((len(functions.rows), width), -1, dtype=np.int64)
    pieces: list = []
    known: dict[int, int] = {}

    def register(function) -> int | str:
        if id(function) not in known:
            form = function.pieces()
            if form is None:
                return type(function).__name__
            known[id(function)] = len(pieces)
            pieces.append(form)
        return known[id(function)]

    joint_rows = []
    for first, transform, index in joints:
        cols[first:first + 12, :len(index)] = index
        local = {name: k for k, name in enumerate(transform.coordinates)}
        K, t = np.zeros((3, 3, 3)), np.zeros((3, 3))
        fns, slots = np.full((2, 3), -1, dtype=np.int64), np.full((2, 3), -1, dtype=np.int64)
        for kind, side in (("rotation", 0), ("translation", 1)):
            axes = [a for a in transform.axes if a.kind == kind]
            for k, a in enumerate(axes):
                f = register(a.function)
                if isinstance(f, str):
                    return f
                fns[side, k] = f
                slots[side, k] = local[a.coordinate] if a.coordinate is not None else -1
                axis = np.asarray(a.axis, dtype=float)
                if side == 0:
                    K[k] = skew3(axis)
                else:
                    t[k] = axis
        joint_rows.append((first, K, t, fns, slots))
    coupled, coupled_fn = [], []
    for row, dependent, independent, function in functions.couplings:
        f = register(function)
        if isinstance(f, str):
            return f
        cols[row, :2] = dependent, independent
        coupled.append(row)
        coupled_fn.append(f)
    return _assembled(joint_rows, cols, coupled, coupled_fn, pieces, functions.rows)


def _assembled(joint_rows: list, cols: np.ndarray, coupled: list, coupled_fn: list,
               pieces: list, rows=()) -> MovingRows:
    J = len(joint_rows)
    K = np.array([j[1] for j in joint_rows]).reshape(J, 3, 3, 3)
    fns = np.array([j[3] for j in joint_rows], dtype=np.int64).reshape(J, 2, 3)
    slots = np.array([j[4] for j in joint_rows], dtype=np.int64).reshape(J, 2, 3)
    counts = [len(p.coefficients) for p in pieces]
    flat = [c for p in pieces for c in p.coefficients]
    table = FunctionTable(
        kptr=np.concatenate([[0], np.cumsum([len(p.knots) for p in pieces])]).astype(np.int64),
        knots=np.concatenate([np.zeros(0), *(p.knots for p in pieces)]).astype(float),
        pptr=np.concatenate([[0], np.cumsum(counts)]).astype(np.int64),
        origin=np.concatenate([np.zeros(0), *(p.origins for p in pieces)]).astype(float),
        cptr=np.concatenate([[0], np.cumsum([len(c) for c in flat])]).astype(np.int64),
        coef=np.concatenate([np.zeros(0), *flat]).astype(float),
    )
    return MovingRows(
        rows=np.asarray(rows, dtype=np.int64), cols=cols, pos=np.full(cols.shape, -1, np.int64),
        first=np.array([j[0] for j in joint_rows], dtype=np.int64), K=K, KK=K @ K,
        t=np.array([j[2] for j in joint_rows]).reshape(J, 3, 3),
        rot_fn=np.ascontiguousarray(fns[:, 0]), rot_slot=np.ascontiguousarray(slots[:, 0]),
        tr_fn=np.ascontiguousarray(fns[:, 1]), tr_slot=np.ascontiguousarray(slots[:, 1]),
        coupled=np.array(coupled, dtype=np.int64), coupled_fn=np.array(coupled_fn, np.int64),
        table=table)

"""Numerical rank of a Jacobian, and which of its rows depend on the others."""

from __future__ import annotations

import numpy as np


def rank_of(J: np.ndarray) -> int:
    """Numerical rank (singular values above the largest × max(shape) × 1e-10)."""
    if J.size == 0:
        return 0
    s = np.linalg.svd(J, compute_uv=False)
    return int((s > s[0] * max(J.shape) * 1e-10).sum()) if s[0] > 0 else 0


def dependent_rows(J: np.ndarray, labels: tuple[str, ...]) -> tuple[str, ...]:
    """Rows of J that are linear combinations of earlier-pivoted rows (QR with pivoting of Jᵀ)."""
    rank = rank_of(J)
    if rank == J.shape[0]:
        return ()
    return tuple(labels[k] for k in sorted(pivoted_columns(J.T)[rank:]))


def pivoted_columns(A: np.ndarray) -> np.ndarray:
    """The column order (from 0) of A's QR factorization with column pivoting: LAPACK's dgeqp3
    with its optimal workspace, the same call and pivots as ``scipy.linalg.qr(A,
    pivoting=True)``, through ``core.blas.lapack`` (importing ``scipy.linalg`` for it would
    cost ~0.3 s of a solve's start-up)."""
    from fccgrb_cli.core.blas import lapack

    A = np.array(A, dtype=float, order="F")
    work, info = lapack.dgeqp3(A, lwork=-1)[3:]
    if info == 0:
        _, pivots, _, _, info = lapack.dgeqp3(A, lwork=int(work[0]), overwrite_a=True)
    if info != 0:
        raise ValueError(f"dgeqp3: LAPACK info {info}")
    return pivots - 1

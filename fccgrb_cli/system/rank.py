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
    import scipy.linalg  # 0.1 s to import: only for a model with redundant equations

    _, _, pivots = scipy.linalg.qr(J.T, pivoting=True, mode="economic")
    return tuple(labels[k] for k in sorted(pivots[rank:]))

"""The compiled system's sparsity, fixed for a model: Φ_q's non-zero pattern row by row, where
each dot row's values come from the features, the order that keeps the normal matrix's
Cholesky factor inside a narrow envelope, and the Hessian's terms in that order. The arrays feed
the compiled per-frame kernels (fccgrb_cli/solvers/kernels.py); nothing here runs per frame.

A row of Φ_q touches at most two bodies' coordinates (plus its mixed coordinates), and of a
body's 12 only those whose coefficient in the feature is not zero (a vector has no r term; an
axis along a body axis is one of u, v, w): on the five-bar 87 rows × 69 columns hold 339
non-zeros (6 %), so ΦᵀWΦ costs Σ nnz_r² instead of a dense product, and ordered by reverse
Cuthill–McKee its factor fills an envelope of a third of the lower triangle.
"""

from __future__ import annotations

import weakref
from typing import NamedTuple

import numpy as np

from fccgrb_cli.system.compiled import System
from fccgrb_cli.system.moving_tables import MovingRows, moving_rows, no_moving_rows


class SparseSystem(NamedTuple):
    """Constant arrays of a mixed-coordinate system with fully-defined bodies (x = q's body
    part). ``j_ptr``/``j_col``: CSR pattern of Φ_q (columns already in the factor's order;
    entries whose feature coefficient is zero left out);
    ``j_const``: the constant values (linear and tracking rows, zero elsewhere); ``scat_pos``,
    ``scat_coef``, ``scat_feat``: each dot row's value += coef · F_flat[feat] (Eq. 2–3);
    ``ang_pos``/``sin_pos``: where the mixed coordinates' entries −g′(θ) and −cos θ sit;
    ``first``: each row's first column in the factor's envelope; ``inverse``: each column of q
    at its place in that order (perm's inverse); ``h_*``: the Hessian's
    lower-triangle terms (row, column, coefficient, dot row); ``moving``: the function rows of
    moving joints and couplings (system/moving_tables.py; empty without them)."""

    nq: int
    nb: int
    n_lin: int
    trk_start: int
    a_ptr: np.ndarray
    a_col: np.ndarray
    a_val: np.ndarray
    f0: np.ndarray
    c_const: np.ndarray
    trk_slot: np.ndarray
    dot_a: np.ndarray
    dot_b: np.ndarray
    dot_c: np.ndarray
    angle_rows: np.ndarray
    distance: np.ndarray
    sine_rows: np.ndarray
    sine_of: np.ndarray
    j_ptr: np.ndarray
    j_col: np.ndarray
    j_const: np.ndarray
    scat_pos: np.ndarray
    scat_coef: np.ndarray
    scat_feat: np.ndarray
    ang_pos: np.ndarray
    sin_pos: np.ndarray
    perm: np.ndarray
    first: np.ndarray
    inverse: np.ndarray
    h_row: np.ndarray
    h_col: np.ndarray
    h_coef: np.ndarray
    h_dot: np.ndarray
    top_rows: np.ndarray
    moving: MovingRows


def supported(system: System) -> bool:
    """The mixed-coordinate kernels (NRM, the structured optimizers, the rates of their
    solution) take mixed coordinates with tracking and fully-defined bodies (a reduced body's
    w = u × v makes Φ_q depend on q through X_q: those systems keep the numpy path), moving
    joints and couplings included where every function has polynomial pieces (else a line on
    stderr, once per process, says that the numpy reference engine solves the model)."""
    if not (system.mixed and system.n_targets > 0 and _fully_defined(system)):
        return False
    if system.functions is None:
        return True
    rows = _moving_of(system)
    if isinstance(rows, str):
        _tell_once(f"the compiled kernels do not take {rows} functions: the numpy reference "
                   "engine solves this model")
        return False
    return True


def compilable(system: System) -> bool:
    """Every kernel, the classical model's too (driven frames, the multipliers, the smoother's
    linearization): fully-defined bodies (x is q's body part) and no moving joint. A model
    with moving joints (an imported OpenSim model) has its smoothing in the numpy reference
    engine, which a line on stderr says once per process (its inverse dynamics, along its
    coordinates, runs in the mixed system's kernels: dynamics/moving.py)."""
    if system.functions is not None:
        _tell_once("the compiled kernels take moving joints (an imported OpenSim model) in "
                   "the mixed-coordinate solves and the inverse dynamics: the numpy "
                   "reference engine runs its smoothing")
        return False
    return _fully_defined(system)


def _fully_defined(system: System) -> bool:
    layout = system.layout
    return not len(layout.reduced_w) and layout.n_body_q == layout.nx


_TOLD: set[str] = set()


def _tell_once(note: str) -> None:
    import sys

    if note not in _TOLD:
        _TOLD.add(note)
        sys.stderr.write(f"fccgrb: note: {note}\n")


_MOVING: weakref.WeakKeyDictionary[System, MovingRows | str] = weakref.WeakKeyDictionary()


def _moving_of(system: System) -> MovingRows | str:
    """The system's function rows as arrays (moving_tables.moving_rows), built once."""
    if system not in _MOVING:
        _MOVING[system] = (no_moving_rows() if system.functions is None
                           else moving_rows(system.functions))
    return _MOVING[system]


def sparse_system(system: System) -> SparseSystem:
    """The arrays of :class:`SparseSystem` for ``system``: mixed (see :func:`supported`) or
    classical, angles as drivers (no θ columns; θ* comes with each frame)."""
    if not (supported(system) or (not system.mixed and compilable(system))):
        raise ValueError("sparse_system needs fully-defined bodies (and tracking when mixed; "
                         "moving joints only when mixed)")
    moving = _moving_of(system)
    assert isinstance(moving, MovingRows)  # supported() has checked
    nq, nb, n_rows = system.nq, system.layout.n_body_q, system.n_rows
    n_lin = system.n_linear_rows
    n_ang = len(system.angle_rows) if system.mixed else 0
    sine_rows = system.sine_rows if system.mixed else np.zeros(0, dtype=int)
    sine_of = system.sine_of if system.mixed else np.zeros(0, dtype=int)

    mixed_rows = n_lin + np.concatenate([system.angle_rows[:n_ang], sine_rows]).astype(int)
    mixed_cols = nb + np.concatenate([np.arange(n_ang), sine_of]).astype(int)
    # a feature's block of 12 columns holds [c0 I, c1 I, c2 I, c3 I]: where c_k = 0 (a vector
    # has no r term; a frame axis along a body axis has one u, v or w) the entry is always zero
    kept = system.scatter_coef != 0.0
    pattern = np.zeros((n_rows, nq), dtype=bool)
    pattern.flat[system.scatter_index[kept]] = True
    pattern[:n_lin, :nb] |= system.J_const != 0.0
    pattern[mixed_rows, mixed_cols] = True
    moved = moving.cols >= 0  # a function row's θ columns
    moving_rows_all = np.broadcast_to(n_lin + moving.rows[:, None], moving.cols.shape)
    pattern[moving_rows_all[moved], nb + moving.cols[moved]] = True
    # degree-aware order of the normal matrix's graph (entries where two columns share a row)
    graph = (pattern.T.astype(float) @ pattern.astype(float)) != 0.0
    # and each tracked point's three rows together: goal attainment's distance curvature
    # couples them (goal/kernels.py's ed_fits)
    start = 3 * len(system.lin_a)
    for t in range(system.n_targets):
        together = np.flatnonzero(pattern[start + 3 * t:start + 3 * t + 3].any(axis=0))
        graph[np.ix_(together, together)] = True
    perm = _reverse_cuthill_mckee(graph)
    inverse = np.empty(nq, dtype=int)
    inverse[perm] = np.arange(nq)

    # CSR, each row's entries in the factor's column order (the normal matrix's lower triangle
    # is then the pairs m ≤ k of a row)
    rows, cols = np.nonzero(pattern)
    order = np.lexsort((inverse[cols], rows))
    rows, cols = rows[order], cols[order]
    position = np.full((n_rows, nq), -1, dtype=int)
    position[rows, cols] = np.arange(len(rows))
    j_const = np.zeros(len(rows))
    lin = rows < n_lin
    j_const[lin] = system.J_const[rows[lin], cols[lin]]
    scat_rows, scat_cols = np.divmod(system.scatter_index[kept], nq)

    A = system.A_flat
    a_rows, a_cols = np.nonzero(A)
    hess_rows, hess_cols, hess_coef, hess_dot = _hessian_terms(system, inverse)
    first = _envelope(graph[np.ix_(perm, perm)])
    pos = np.full(moving.cols.shape, -1, dtype=np.int64)
    pos[moved] = position[moving_rows_all[moved], nb + moving.cols[moved]]
    return SparseSystem(
        nq=nq, nb=nb, n_lin=n_lin, trk_start=3 * len(system.lin_a),
        a_ptr=_pointers(a_rows, len(A)), a_col=a_cols, a_val=A[a_rows, a_cols],
        f0=system.f0.ravel().copy(), c_const=system.c_const.copy(),
        trk_slot=system.trk_slot.astype(np.int64),
        dot_a=system.dot_a.astype(np.int64), dot_b=system.dot_b.astype(np.int64),
        dot_c=system.dot_c.copy(), angle_rows=system.angle_rows.astype(np.int64),
        distance=system.distance_rows.copy(), sine_rows=system.sine_rows.astype(np.int64),
        sine_of=system.sine_of.astype(np.int64),
        j_ptr=_pointers(rows, n_rows), j_col=inverse[cols], j_const=j_const,
        scat_pos=position[scat_rows, scat_cols],
        scat_coef=system.scatter_coef[kept], scat_feat=system.scatter_gather[kept].astype(np.int64),
        ang_pos=position[n_lin + system.angle_rows[:n_ang], nb + np.arange(n_ang)],
        sin_pos=position[n_lin + sine_rows, nb + sine_of],
        perm=perm, first=first,
        inverse=inverse.astype(np.int64),
        h_row=hess_rows, h_col=hess_cols, h_coef=hess_coef, h_dot=hess_dot,
        top_rows=np.flatnonzero(system.masks()["topology"]),
        moving=moving._replace(pos=pos),
    )


def _pointers(rows: np.ndarray, n: int) -> np.ndarray:
    return np.concatenate([[0], np.cumsum(np.bincount(rows, minlength=n))]).astype(np.int64)


def _hessian_terms(system: System, inverse: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The dot rows' constant Hessian kron(K, I3) (System.residual_hessian) as terms of the
    lower triangle in the factor's order: H[row, col] += coef · c[dot]."""
    side = 4 * len(system.layout.body_names)
    ka, kb = np.divmod(system.hess_index, side)
    d = np.arange(3)
    rows = inverse[(3 * ka[:, None] + d).ravel()]
    cols = inverse[(3 * kb[:, None] + d).ravel()]
    coef = np.repeat(system.hess_coef, 3)
    dot = np.repeat(system.hess_row, 3)
    lower = (rows >= cols) & (coef != 0.0)  # a zero coefficient's term is no term
    return rows[lower], cols[lower], coef[lower], dot[lower].astype(np.int64)


def _reverse_cuthill_mckee(graph: np.ndarray) -> np.ndarray:
    """The reverse Cuthill–McKee order of a symmetric pattern (dense booleans), as
    scipy.sparse.csgraph.reverse_cuthill_mckee gives it (tests/test_structure.py compares them):
    each connected part searched breadth first from its node of least degree (the diagonal
    counted twice; ties in numpy's argsort order), the neighbours each node adds taken by
    increasing degree (in their column order on ties), the whole order reversed. Written out
    because scipy.sparse and its csgraph took 0.2–0.7 s to import for a graph of ~100 nodes."""
    n = len(graph)
    neighbours = [np.flatnonzero(row) for row in graph]
    degree = (graph.sum(axis=1) + np.diagonal(graph).astype(bool)).astype(np.int32)
    seeds = np.argsort(degree).astype(np.int32)
    seen = np.zeros(n, dtype=bool)
    order: list[int] = []
    for seed in seeds:
        if seen[seed]:
            continue
        seen[seed] = True
        order.append(int(seed))
        head = len(order) - 1
        while head < len(order):
            added = [int(j) for j in neighbours[order[head]] if not seen[j]]
            seen[added] = True
            order.extend(sorted(added, key=lambda j: degree[j]))  # stable: ties keep columns
            head += 1
        if len(order) == n:
            break
    return np.array(order[::-1], dtype=np.int64)


def _envelope(graph: np.ndarray) -> np.ndarray:
    """Each row's first column with a non-zero in the lower triangle: the Cholesky factor stays
    inside this envelope (fill-in never reaches left of a row's first entry)."""
    lower = np.tril(graph)
    return np.argmax(lower, axis=1).astype(np.int64)


_BUILT: weakref.WeakKeyDictionary[System, SparseSystem] = weakref.WeakKeyDictionary()


def sparse_of(system: System) -> SparseSystem:
    """The system's sparse arrays, built once per System."""
    if system not in _BUILT:
        _BUILT[system] = sparse_system(system)
    return _BUILT[system]

"""Sparse-matrix operations repeated on one sparsity pattern, done once as index work.

Newton assembles a tangent of the same sparsity pattern at every iteration, and the solvers
cut it up the same way each time: the free DOFs, the displacement / pressure blocks of the
Krylov preconditioner, the AMG's padded displacement matrix, the contact curvature and the
nodal elimination added in. SciPy redoes the index work of such slicing and sums for every
matrix: at 1.54M tets (68.7M non-zeros) that was ~35 s per Newton iteration (cProfile of
seven iterations: 166 s of fancy indexing, 59 s of CSR subtractions, 60 s of padding), a
third of an iteration. Here the index work is done once per pattern, and each new matrix
costs a gather of its values (``K.data[take]``) or an in-place addition.

Written by hand: SciPy has no pattern-reusing slicing or addition.
"""

from __future__ import annotations

import weakref
from collections.abc import Callable

import numpy as np
import scipy.sparse as sp


def canonical(K: sp.spmatrix) -> sp.csr_matrix:
    """``K`` as CSR with sorted column indices (in place where it already is CSR)."""
    K = K.tocsr()
    if not K.has_sorted_indices:
        K.sort_indices()
    return K


def _frozen(a: np.ndarray) -> np.ndarray:
    """``a`` made read-only: a plan's index arrays are shared by the matrices it returns."""
    a.flags.writeable = False
    return a


def _same_array(a: np.ndarray, ref: np.ndarray) -> bool:
    """Whether ``a`` is the read-only array ``ref`` or a view of all of it (SciPy's
    constructors re-view the index arrays they are given). ``ref`` is held by the caller, so
    its memory is not reused, and read-only, so its contents do not change."""
    if a is ref:
        return True
    return (not a.flags.writeable and a.dtype == ref.dtype and a.shape == ref.shape
            and a.strides == ref.strides
            and a.__array_interface__["data"][0] == ref.__array_interface__["data"][0])


class _Pattern:
    """The sparsity pattern a cached plan was made for.

    Matrices returned by a :class:`PatternGather` share its read-only index arrays, and so do
    the matrices later made from them: those are recognised in O(1); any other matrix is
    compared entry by entry (~0.1 s at 69M non-zeros)."""

    def __init__(self) -> None:
        self.shape: tuple[int, int] | None = None
        self.indptr = _frozen(np.zeros(0, dtype=np.int64))
        self.indices = _frozen(np.zeros(0, dtype=np.int64))
        self.comparisons = 0  # matrices compared entry by entry (not recognised in O(1))

    def matches(self, K: sp.csr_matrix) -> bool:
        if K.shape != self.shape:
            return False
        if _same_array(K.indices, self.indices) and _same_array(K.indptr, self.indptr):
            return True
        self.comparisons += 1
        same = (len(K.indices) == len(self.indices) and np.array_equal(K.indptr, self.indptr)
                and np.array_equal(K.indices, self.indices))
        if same and not (K.indices.flags.writeable or K.indptr.flags.writeable):
            self.indptr, self.indices = K.indptr, K.indices  # recognised by identity next time
        return same

    def remember(self, K: sp.csr_matrix) -> None:
        self.shape = K.shape
        self.indptr, self.indices = (a if not a.flags.writeable else _frozen(a.copy())
                                     for a in (K.indptr, K.indices))


class PatternGather:
    """``transform(K)`` for a sequence of matrices ``K`` of (mostly) one pattern.

    ``transform`` may only move entries (slicing, permuting, padding with new entries); it is
    applied once per pattern to a matrix that holds each entry's position, which gives the
    result's pattern and ``take``, the entry of ``K`` behind each of its values. Later
    matrices of the same pattern cost ``K.data[take]``. Entries the transform adds (no entry of
    ``K`` behind them) take ``fill(K)``.
    """

    def __init__(self, transform: Callable[[sp.csr_matrix], sp.spmatrix],
                 fill: Callable[[sp.csr_matrix], float] | None = None) -> None:
        self.transform = transform
        self.fill = fill
        self._pattern = _Pattern()
        self._take = np.zeros(0, dtype=np.int64)
        self._indptr = self._indices = np.zeros(0, dtype=np.int64)
        self._shape: tuple[int, int] = (0, 0)
        self.plans = 0  # how many patterns were analysed

    @property
    def comparisons(self) -> int:
        """How many matrices were compared with the plan's pattern entry by entry."""
        return self._pattern.comparisons

    def __call__(self, K: sp.spmatrix) -> sp.csr_matrix:
        K = canonical(K)
        if not self._pattern.matches(K):
            # positions + 1, so that entries the transform creates (0) stand out; as int32
            # where they fit: a plan of the 1.54M-tet tangent holds 69M of them, and the
            # transform's copies of them cost half of float64's (at 495k tets the first
            # tangent's free-part plan peaked 0.2 GB lower)
            itype = np.int32 if K.nnz < 2**31 - 1 else np.int64
            index = sp.csr_matrix((np.arange(1, K.nnz + 1, dtype=itype), K.indices,
                                   K.indptr), shape=K.shape)
            T = canonical(sp.csr_matrix(self.transform(index)))
            self._take = T.data.astype(itype) - 1
            self._indptr, self._indices = _frozen(T.indptr), _frozen(T.indices)
            self._shape = T.shape
            self._pattern.remember(K)
            self.plans += 1
        data = K.data[self._take]
        added = self._take < 0
        if added.any():
            data[added] = self.fill(K) if self.fill is not None else 0.0
        # the plan's read-only index arrays, not copies (0.3 GB at 69M non-zeros, ~1 s)
        out = sp.csr_matrix((data, self._indices, self._indptr), shape=self._shape)
        out.has_sorted_indices = True
        return out


class PatternAdd:
    """``K + M`` on ``K``'s pattern, in place on ``K.data``, for a sequence of ``K`` of
    (mostly) one pattern and ``M`` of (mostly) one pattern; a SciPy sum where ``M`` has an
    entry outside ``K``'s pattern.

    The position in ``K.data`` of each entry of ``M`` is searched once per pair of patterns
    (by one SciPy sum over ``M``'s rows, :func:`_positions`), then reused: the contact
    curvature keeps its pattern while the active set does not change. (A search over all of
    ``K`` for each call took 6-15 s at 1.54M tets when the nodal elimination's 6M-entry
    ``dK`` was added this way; that now goes through :class:`PatternProject`.)
    """

    def __init__(self) -> None:
        self._pattern = _Pattern()  # of K
        self._m_pattern = _Pattern()  # of M, for which _pos holds
        self._pos = np.zeros(0, dtype=np.int64)
        self.plans = 0  # how many position searches were made (a test's handle)

    def __call__(self, K: sp.spmatrix, M: sp.spmatrix) -> sp.csr_matrix:
        K = canonical(K)
        if not self._pattern.matches(K):
            self._pattern.remember(K)
            self._m_pattern = _Pattern()
        M = canonical(M)
        M.sum_duplicates()  # one entry per position: a plain fancy-index addition is exact
        if not self._m_pattern.matches(M):
            pos = _positions(K, M)
            if pos is None:
                return canonical(K + M)
            self._pos = pos
            self._m_pattern.remember(M)
            self.plans += 1
        K.data[self._pos] += M.data
        return K


def _positions(K: sp.csr_matrix, M: sp.csr_matrix) -> np.ndarray | None:
    """Position in ``K.data`` of each entry of ``M`` (both CSR with sorted indices, ``M``
    without duplicates), or ``None`` if an entry of ``M`` is not in ``K``'s pattern.

    By one SciPy sum over the rows ``M`` has entries in: those rows of ``K`` with each entry
    valued its position + 1, plus ``M``'s entries valued ``2^40``; where the sum exceeds
    ``2^40``, ``M`` has an entry at position ``sum - 2^40 - 1``, in ``M``'s (row-major)
    order. Exact in float64 up to ``2^40`` entries. Restricted to ``M``'s rows, the cost
    follows ``M`` (the contact curvature touches a few tens of thousands of rows of 1.2M),
    not all of ``K``.
    """
    rows = np.flatnonzero(np.diff(M.indptr))
    if not len(rows):
        return np.zeros(0, dtype=np.int64)
    start = K.indptr[rows].astype(np.int64)
    lens = K.indptr[rows + 1].astype(np.int64) - start
    sub_ptr = np.zeros(len(rows) + 1, dtype=np.int64)
    np.cumsum(lens, out=sub_ptr[1:])
    src = np.arange(sub_ptr[-1], dtype=np.int64) - np.repeat(sub_ptr[:-1] - start, lens)
    mark = float(2**40)
    shape = (len(rows), K.shape[1])
    numbered = sp.csr_matrix((src + 1.0, K.indices[src], sub_ptr), shape=shape)
    m_ptr = np.zeros(len(rows) + 1, dtype=np.int64)
    np.cumsum(np.diff(M.indptr)[rows], out=m_ptr[1:])
    S = numbered + sp.csr_matrix((np.full(M.nnz, mark), M.indices, m_ptr), shape=shape)
    if S.nnz != numbered.nnz:  # entries of M outside K's pattern
        return None
    hit = S.data[S.data > mark]
    return (hit - (mark + 1)).astype(np.int64)



class PatternProject:
    """``Pi K Pi + d P`` on ``K``'s pattern, with ``P = N N^T`` and ``Pi = I - P``, for ``N``
    whose orthonormal columns each live on the DOFs of one node (the nodal elimination of
    contact constraints: column ``j`` of ``N`` is the unit normal at contact point ``j``).

    Written on the values, in place: where the rows of a node's DOFs share one column pattern
    (a vector P1 space) and that pattern is symmetric around them, ``Pi K`` mixes the rows of
    each constrained node, ``(Pi K) Pi`` its columns (at the transposed positions), and
    ``d P`` lands in the node's diagonal block. Those positions are planned once per pattern
    of ``K`` and set of constrained DOFs (the active set); a call then costs a few gathers
    over the constrained rows and columns.

    The projected matrix shares ``K``'s values: ``K.data`` holds ``Pi K Pi + d P`` at the
    constrained rows and columns until :meth:`restore` (or the next call) puts the saved
    values back. So the Newton step keeps one copy of the tangent's values, not two (0.5 GB
    at 1.40M tets). Any other case falls back to SciPy products added by
    :class:`PatternAdd` on a copy (~2.5 s per call at 1.54M tets), ``K`` left alone.
    """

    def __init__(self) -> None:
        self._pattern = _Pattern()
        self._dofs = np.zeros(0, dtype=np.int64)  # N's pattern the plan was made for
        self._dofs_ptr = np.zeros(0, dtype=np.int64)
        self._plan: list[tuple[np.ndarray, ...]] | None = None
        self._touched = np.zeros(0, dtype=np.int64)  # the positions the plan changes
        self._column_counts = np.zeros(0, dtype=np.int64)  # entries per column of K
        self._saved: tuple[weakref.ref, np.ndarray, np.ndarray] | None = None
        self._add = PatternAdd()
        self.plans = 0  # how many active-set plans were made (0: SciPy's products)

    def __call__(self, K: sp.spmatrix, N: sp.spmatrix, d: float) -> sp.csr_matrix:
        self.restore()
        K = canonical(K)
        if not self._pattern.matches(K):
            self._pattern.remember(K)
            self._column_counts = np.bincount(K.indices, minlength=K.shape[1])
            self._dofs_ptr = np.zeros(0, dtype=np.int64)  # a new plan
        Nc = sp.csc_matrix(N)
        Nc.sort_indices()
        if not (np.array_equal(Nc.indptr, self._dofs_ptr)
                and np.array_equal(Nc.indices, self._dofs)):
            self._plan = _projection_plan(K, Nc, self._column_counts)
            self._dofs, self._dofs_ptr = Nc.indices.copy(), Nc.indptr.copy()
            self._touched = (np.unique(np.concatenate([a.ravel() for g in self._plan
                                                       for a in g[2:]]))
                             if self._plan is not None else np.zeros(0, dtype=np.int64))
            self.plans += self._plan is not None
        if self._plan is None:
            return self._scipy(K, Nc, d)
        data = K.data
        self._saved = (weakref.ref(data), self._touched, data[self._touched])
        for cols, seg, pos, trans, diag in self._plan:
            k = pos.shape[0]
            nhat = Nc.data[Nc.indptr[cols][:, None] + np.arange(k)]  # (m, k) unit normals
            w = nhat[seg]  # (T, k): the normal of each entry's node
            for at in (pos, trans):  # Pi K (rows of the node), then (Pi K) Pi (its columns)
                V = data[at]  # (k, T)
                s = np.einsum("kt,tk->t", V, w)
                data[at] = V - w.T * s
            for a in range(k):
                for b in range(k):
                    data[diag[a, b]] += d * nhat[:, a] * nhat[:, b]
        out = sp.csr_matrix((data, K.indices, K.indptr), shape=K.shape)
        out.has_sorted_indices = True
        return out

    def restore(self) -> None:
        """Put back the values of the last projected ``K`` (if it still exists)."""
        if self._saved is not None:
            ref, at, values = self._saved
            data = ref()
            if data is not None:
                data[at] = values
            self._saved = None

    def _scipy(self, K: sp.csr_matrix, N: sp.spmatrix, d: float) -> sp.csr_matrix:
        """``K + dK``, ``dK = -P K - K P + N (N^T K N + d I) N^T``, by SciPy products."""
        N = sp.csc_matrix(N)
        NtK = (N.T @ K).tocsr()
        core = NtK @ N + d * sp.identity(N.shape[1])
        dK = -(N @ NtK) - (K @ N) @ N.T + N @ core @ N.T
        return self._add(sp.csr_matrix((K.data.copy(), K.indices, K.indptr), shape=K.shape), dK)


def _transposes(K: sp.csr_matrix, rows: np.ndarray, pos: np.ndarray) -> np.ndarray | None:
    """Position in ``K.data`` of the transpose of each entry at ``pos`` (in rows ``rows``,
    same shape), or None if one has none. Searched among the entries of the rows the
    entries' columns name, so the cost follows the constrained rows, not all of ``K``."""
    cols = K.indices[pos].astype(np.int64)
    J = np.unique(cols)
    start = K.indptr[J].astype(np.int64)
    lens = K.indptr[J + 1].astype(np.int64) - start
    ptr = np.zeros(len(J) + 1, dtype=np.int64)
    np.cumsum(lens, out=ptr[1:])
    src = np.arange(ptr[-1], dtype=np.int64) - np.repeat(ptr[:-1] - start, lens)
    n = np.int64(K.shape[1])
    keys = np.repeat(J, lens) * n + K.indices[src]  # ascending: rows J, sorted columns
    want = cols * n + rows
    at = np.minimum(np.searchsorted(keys, want), len(keys) - 1)
    if not np.array_equal(keys[at], want):
        return None
    return src[at]


def _projection_plan(K: sp.csr_matrix, Nc: sp.csc_matrix, column_counts: np.ndarray
                     ) -> list[tuple[np.ndarray, ...]] | None:
    """Per group of constraints on ``k`` DOFs: the constraints ``cols``, and over the
    concatenated rows of their DOFs the constraint of each entry ``seg`` (T,), the entries'
    positions ``pos`` (k, T) (row ``a`` of the node), their transposes ``trans`` (k, T) and
    the node's diagonal block ``diag`` (k, k, m). None if a node's rows differ in pattern,
    lack a diagonal-block entry, or a constrained DOF's column is not the transpose of its
    row (``column_counts``: the entries of each column of ``K``)."""
    if K.shape[0] != K.shape[1]:
        return None
    counts = np.diff(Nc.indptr)
    plan = []
    for k in np.unique(counts[counts > 0]):
        cols = np.flatnonzero(counts == k)
        R = Nc.indices[Nc.indptr[cols][:, None] + np.arange(k)]  # (m, k) DOFs of each node
        start = K.indptr[R].astype(np.int64)
        lens = K.indptr[R + 1].astype(np.int64) - start
        if not (np.all(lens == lens[:, :1]) and np.array_equal(column_counts[R], lens)):
            return None
        L = lens[:, 0]
        ptr = np.zeros(len(cols) + 1, dtype=np.int64)
        np.cumsum(L, out=ptr[1:])
        seg = np.repeat(np.arange(len(cols)), L)
        pos = start[seg].T + (np.arange(ptr[-1], dtype=np.int64) - ptr[seg])  # (k, T)
        col_of = K.indices[pos]
        if not np.all(col_of == col_of[0]):
            return None
        diag = np.empty((k, k, len(cols)), dtype=np.int64)
        for b in range(k):
            hit = np.flatnonzero(col_of[0] == R[seg, b])
            if len(hit) != len(cols):
                return None
            for a in range(k):
                diag[a, b] = pos[a, hit]
        trans = _transposes(K, R[seg].T.astype(np.int64), pos)
        if trans is None:
            return None
        plan.append((cols, seg, pos, trans, diag))
    return plan

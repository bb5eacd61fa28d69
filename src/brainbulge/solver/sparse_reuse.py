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

    def matches(self, K: sp.csr_matrix) -> bool:
        if K.shape != self.shape:
            return False
        if _same_array(K.indices, self.indices) and _same_array(K.indptr, self.indptr):
            return True
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
        self.plans = 0  # how many patterns were analysed (a test's handle)

    def __call__(self, K: sp.spmatrix) -> sp.csr_matrix:
        K = canonical(K)
        if not self._pattern.matches(K):
            # positions + 1, so that entries the transform creates (0) stand out; exact in
            # float64 up to 2^53 entries
            index = sp.csr_matrix((np.arange(1, K.nnz + 1, dtype=np.float64), K.indices,
                                   K.indptr), shape=K.shape)
            T = canonical(sp.csr_matrix(self.transform(index)))
            # int32 where it fits: a plan of the 1.54M-tet tangent holds 69M of them
            itype = np.int32 if K.nnz < 2**31 - 1 else np.int64
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
    (by one SciPy sum, :func:`_positions`), then reused: Newton's contact terms keep their
    pattern while the active set does not change. At 1.54M tets (69M non-zeros in ``K``, 6M
    in the nodal elimination's ``M``) the search over all of ``K`` took 6-15 s per call.
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

    By one SciPy sum: ``K``'s entries numbered 1, 2, ... plus ``M``'s entries set to
    ``2^40``; where the sum exceeds ``2^40``, ``M`` has an entry at ``K``'s position ``sum -
    2^40 - 1``, in ``M``'s (row-major) order. Exact in float64 up to ``2^40`` entries."""
    mark = float(2**40)
    numbered = sp.csr_matrix((np.arange(1, K.nnz + 1, dtype=np.float64), K.indices, K.indptr),
                             shape=K.shape)
    S = numbered + sp.csr_matrix((np.full(M.nnz, mark), M.indices, M.indptr), shape=M.shape)
    if S.nnz != K.nnz:  # entries of M outside K's pattern
        return None
    hit = S.data[S.data > mark]
    return (hit - (mark + 1)).astype(np.int64)

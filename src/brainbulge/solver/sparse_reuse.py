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


class _Pattern:
    """The sparsity pattern a cached plan was made for."""

    def __init__(self) -> None:
        self.shape: tuple[int, int] | None = None
        self.indptr = np.zeros(0, dtype=np.int64)
        self.indices = np.zeros(0, dtype=np.int64)

    def matches(self, K: sp.csr_matrix) -> bool:
        return (K.shape == self.shape and len(K.indices) == len(self.indices)
                and np.array_equal(K.indptr, self.indptr)
                and np.array_equal(K.indices, self.indices))

    def remember(self, K: sp.csr_matrix) -> None:
        self.shape = K.shape
        self.indptr = K.indptr.copy()
        self.indices = K.indices.copy()


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
            self._indptr, self._indices, self._shape = T.indptr, T.indices, T.shape
            self._pattern.remember(K)
            self.plans += 1
        data = K.data[self._take]
        added = self._take < 0
        if added.any():
            data[added] = self.fill(K) if self.fill is not None else 0.0
        return sp.csr_matrix((data, self._indices.copy(), self._indptr.copy()),
                             shape=self._shape)


class PatternAdd:
    """``K + M`` on ``K``'s pattern, in place on ``K.data``, for a sequence of ``K`` of
    (mostly) one pattern; a SciPy sum where ``M`` has an entry outside that pattern."""

    def __init__(self) -> None:
        self._pattern = _Pattern()
        self._keys = np.zeros(0, dtype=np.int64)

    def __call__(self, K: sp.spmatrix, M: sp.spmatrix) -> sp.csr_matrix:
        K = canonical(K)
        if not self._pattern.matches(K):
            rows = np.repeat(np.arange(K.shape[0], dtype=np.int64), np.diff(K.indptr))
            self._keys = rows * K.shape[1] + K.indices  # increasing: sorted indices
            self._pattern.remember(K)
        coo = M.tocoo()
        keys = coo.row.astype(np.int64) * K.shape[1] + coo.col
        pos = np.minimum(np.searchsorted(self._keys, keys), len(self._keys) - 1)
        if len(keys) and not np.array_equal(self._keys[pos], keys):
            return canonical(K + M)
        np.add.at(K.data, pos, coo.data)
        return K

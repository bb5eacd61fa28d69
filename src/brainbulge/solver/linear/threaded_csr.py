"""Sparse matrix-vector products ``y = A x`` on all cores.

A :class:`ThreadedCSR` is a SciPy CSR matrix whose product with a vector splits the rows
into blocks of about equal non-zeros and hands each block to SciPy's own kernel
(``csr_matvec``, which releases the GIL) in a thread of its own::

    y[r_k : r_k+1] = A[r_k : r_k+1, :] x,      k = 0 .. threads - 1

Each row's sum is computed exactly as the serial kernel computes it, so the result is the
same bit for bit. Written here because neither SciPy nor pyamg threads the product (MKL's
sparse BLAS would, as a further dependency); the Krylov solver's products (GMRES, the AMG
cycle's residuals, restrictions and prolongations) are a third of its time and ran on one
of the two cores. pyamg's Gauss-Seidel holds the GIL, so its sweeps stay serial.
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import scipy.sparse as sp
from scipy.sparse import _sparsetools

#: below this many non-zeros a product stays on one thread (the threads' start-up, ~50 us,
#: is then a noticeable part of it)
MIN_NNZ = 200_000

_pool: tuple[int, ThreadPoolExecutor] | None = None  # (the process it belongs to, pool)


def threads() -> int:
    """Threads for the products: the cores this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not on Linux
        return max(1, os.cpu_count() or 1)


def _executor() -> ThreadPoolExecutor:
    """The pool of this process: a forked child (a study's worker) gets one of its own, as
    the parent's threads do not exist in it and work handed to them would never run."""
    global _pool
    if _pool is None or _pool[0] != os.getpid():
        _pool = (os.getpid(),
                 ThreadPoolExecutor(max_workers=threads(), thread_name_prefix="csr-matvec"))
    return _pool[1]


def row_blocks(indptr: np.ndarray, parts: int) -> np.ndarray:
    """Row bounds ``r_0 = 0 < ... < r_parts = n`` of blocks with about equal non-zeros."""
    n = len(indptr) - 1
    bounds = np.searchsorted(indptr, np.linspace(0, indptr[-1], parts + 1), side="left")
    bounds[0], bounds[-1] = 0, n
    return np.unique(np.clip(bounds, 0, n))


class ThreadedCSR(sp.csr_matrix):
    """A CSR matrix whose matrix-vector product runs on :func:`threads` threads."""

    def _matmul_vector(self, other: np.ndarray) -> np.ndarray:
        parts = threads()
        if parts == 1 or self.nnz < MIN_NNZ or other.dtype != self.dtype or self.ndim != 2:
            return super()._matmul_vector(other)
        m, n = self.shape
        y = np.zeros(m, dtype=np.result_type(self.dtype, other.dtype))
        indptr, indices, data = self.indptr, self.indices, self.data
        x = np.ascontiguousarray(other)

        def block(a: int, b: int) -> None:
            p0, p1 = indptr[a], indptr[b]
            _sparsetools.csr_matvec(b - a, n, indptr[a : b + 1] - p0, indices[p0:p1],
                                    data[p0:p1], x, y[a:b])

        bounds = row_blocks(indptr, parts)
        pending = [_executor().submit(block, a, b)
                   for a, b in zip(bounds[:-1], bounds[1:], strict=True)]
        for f in pending:
            f.result()
        return y


def threaded(A: sp.spmatrix) -> sp.spmatrix:
    """``A`` as a :class:`ThreadedCSR` sharing its arrays (a CSR matrix), else ``A``."""
    if not sp.isspmatrix_csr(A) or isinstance(A, ThreadedCSR):
        return A
    T = ThreadedCSR((A.data, A.indices, A.indptr), shape=A.shape, copy=False)
    T.has_sorted_indices = A.has_sorted_indices
    return T

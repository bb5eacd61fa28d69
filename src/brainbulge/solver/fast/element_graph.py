"""Element graphs for hand-written assembly: the sparsity pattern of all pairs of each
element's DOFs, and a colouring of the elements in which no two of one colour share a
vertex (so that elements of one colour can be assembled in parallel).

Written by hand (Numba): SciPy builds such a pattern only through a COO matrix of all
pairs (256 per tet: hundreds of millions at 1.4M tets), and no library we use colours the
elements of a mesh.
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np
import scipy.sparse as sp


@numba.njit(cache=True)
def colour_elements(verts, nv):  # noqa: ANN001, ANN202
    """Greedy colouring of the elements: no two of one colour share a vertex (at most 128
    colours; -1 for an element that found none free)."""
    ne = verts.shape[0]
    used = np.zeros((nv, 2), dtype=np.uint64)
    colour = np.empty(ne, dtype=np.int64)
    for e in range(ne):
        m0 = np.uint64(0)
        m1 = np.uint64(0)
        for a in range(verts.shape[1]):
            m0 |= used[verts[e, a], 0]
            m1 |= used[verts[e, a], 1]
        c = -1
        for k in range(128):
            word = m0 if k < 64 else m1
            if (word >> np.uint64(k % 64)) & np.uint64(1) == 0:
                c = k
                break
        colour[e] = c
        if c >= 0:
            for a in range(verts.shape[1]):
                used[verts[e, a], c // 64] |= np.uint64(1) << np.uint64(c % 64)
    return colour


class Pattern(NamedTuple):
    """A CSR sparsity pattern without values: every tangent assembled on it shares its
    read-only index arrays (a zero-valued CSR of the pattern would hold a tangent-sized
    float64 array for nothing: 0.5 GB at 1.40M tets)."""

    indptr: np.ndarray
    indices: np.ndarray
    shape: tuple[int, int]

    @property
    def nnz(self) -> int:
        return len(self.indices)

    def matrix(self, data: np.ndarray) -> sp.csr_matrix:
        """The CSR matrix of ``data`` on this pattern (sorted columns, shared indices)."""
        K = sp.csr_matrix((data, self.indices, self.indptr), shape=self.shape)
        K.has_sorted_indices = True
        return K


def numbering(ndof: int, kept: np.ndarray | None) -> np.ndarray:
    """The new number of each of ``ndof`` DOFs when only ``kept`` (ascending) are kept, -1
    for a dropped one (all kept, in their order, when ``kept`` is None)."""
    if kept is None:
        return np.arange(ndof, dtype=np.int64)
    new = np.full(ndof, -1, dtype=np.int64)
    new[kept] = np.arange(len(kept))
    return new


@numba.njit(cache=True, parallel=True)
def _pattern_rows(ext, ndof, ptr, adj, maxlen, nthreads, count_only, indptr, indices):  # noqa: ANN001, ANN202
    """Row lengths (``count_only``) or sorted column indices of the pattern of all DOF pairs
    of every element (dropped DOFs, -1, left out); ``ptr``/``adj``: the elements of each
    DOF. A marker per thread and DOF marks the columns found for the current row."""
    lengths = np.zeros(ndof, dtype=np.int64)
    marker = np.full((nthreads, ndof), -1, dtype=np.int64)
    for t in numba.prange(nthreads):
        buf = np.empty(maxlen, dtype=np.int64)
        for d in range(t * ndof // nthreads, (t + 1) * ndof // nthreads):
            n = 0
            for k in range(ptr[d], ptr[d + 1]):
                e = adj[k]
                for m in range(ext.shape[1]):
                    c = ext[e, m]
                    if c >= 0 and marker[t, c] != d:
                        marker[t, c] = d
                        buf[n] = c
                        n += 1
            lengths[d] = n
            if not count_only:
                cols = np.sort(buf[:n])
                for k in range(n):
                    indices[indptr[d] + k] = cols[k]
    return lengths


def element_pattern(ext: np.ndarray, ndof: int) -> Pattern:
    """The sparsity pattern of the condensed tangent: every pair of an element's external
    DOFs ``ext`` (ne x 16; -1 for a DOF left out, such as a fixed one), as NGSolve's matrix
    graph has it (sorted columns, int32, read-only index arrays)."""
    ne, m = ext.shape
    flat = ext.ravel()
    kept = flat >= 0
    ptr = np.zeros(ndof + 1, dtype=np.int64)
    np.cumsum(np.bincount(flat[kept], minlength=ndof), out=ptr[1:])
    # the elements of each DOF (the dropped entries sort first, before ptr[0] = 0's DOF)
    adj = np.argsort(flat, kind="stable")[len(flat) - int(kept.sum()):] // m
    del kept
    dummy = np.zeros(1, dtype=np.int64)
    maxlen = int(np.diff(ptr).max(initial=0)) * m  # a row's candidates, duplicates included
    nt = numba.get_num_threads()
    lengths = _pattern_rows(ext, ndof, ptr, adj, maxlen, nt, True, dummy, dummy)
    nnz = int(lengths.sum())
    itype = np.int32 if nnz < 2**31 - 1 else np.int64
    indptr = np.zeros(ndof + 1, dtype=itype)
    np.cumsum(lengths, out=indptr[1:])
    indices = np.empty(nnz, dtype=itype)  # written in place: no int64 copy (0.5 GB at 1.40M)
    _pattern_rows(ext, ndof, ptr, adj, maxlen, nt, False, indptr, indices)
    # read-only: every tangent shares them, and so can the plans that slice the tangents
    # (brainbulge.solver.linear.sparse_reuse keeps a writeable pattern as a copy)
    indices.flags.writeable = indptr.flags.writeable = False
    return Pattern(indptr, indices, (ndof, ndof))

"""Element graphs for hand-written assembly: the sparsity pattern of all pairs of each
element's DOFs, and a colouring of the elements in which no two of one colour share a
vertex (so that elements of one colour can be assembled in parallel).

Written by hand (Numba): SciPy builds such a pattern only through a COO matrix of all
pairs (256 per tet: hundreds of millions at 1.4M tets), and no library we use colours the
elements of a mesh.
"""

from __future__ import annotations

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


@numba.njit(cache=True, parallel=True)
def _pattern_rows(ext, ndof, ptr, adj, maxlen, nthreads, count_only, indptr, indices):  # noqa: ANN001, ANN202
    """Row lengths (``count_only``) or sorted column indices of the pattern of all DOF pairs
    of every element; ``ptr``/``adj``: the elements of each DOF. A marker per thread and
    DOF marks the columns found for the current row."""
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
                    if marker[t, c] != d:
                        marker[t, c] = d
                        buf[n] = c
                        n += 1
            lengths[d] = n
            if not count_only:
                cols = np.sort(buf[:n])
                for k in range(n):
                    indices[indptr[d] + k] = cols[k]
    return lengths


def element_pattern(ext: np.ndarray, ndof: int) -> sp.csr_matrix:
    """The sparsity pattern of the condensed tangent: every pair of an element's external
    DOFs ``ext`` (ne x 16), as NGSolve's matrix graph has it (sorted columns, int32,
    read-only index arrays)."""
    ne, m = ext.shape
    flat = ext.ravel()
    ptr = np.zeros(ndof + 1, dtype=np.int64)
    np.cumsum(np.bincount(flat, minlength=ndof), out=ptr[1:])
    adj = (np.argsort(flat, kind="stable") // m).astype(np.int64)  # the elements of each DOF
    dummy = np.zeros(1, dtype=np.int64)
    maxlen = int(np.diff(ptr).max()) * m  # a row's candidate columns, duplicates included
    nt = numba.get_num_threads()
    lengths = _pattern_rows(ext, ndof, ptr, adj, maxlen, nt, True, dummy, dummy)
    indptr = np.zeros(ndof + 1, dtype=np.int64)
    np.cumsum(lengths, out=indptr[1:])
    indices = np.empty(indptr[-1], dtype=np.int64)
    _pattern_rows(ext, ndof, ptr, adj, maxlen, nt, False, indptr, indices)
    indices, indptr = indices.astype(np.int32), indptr.astype(np.int32)
    # read-only: every tangent shares them, and so can the plans that slice the tangents
    # (brainbulge.solver.linear.sparse_reuse keeps a writeable pattern as a copy)
    indices.flags.writeable = indptr.flags.writeable = False
    return sp.csr_matrix((np.zeros(len(indices)), indices, indptr), shape=(ndof, ndof))

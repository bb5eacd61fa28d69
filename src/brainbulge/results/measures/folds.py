"""Where a deformed 2D boundary crosses itself: a fold that only tissue self-contact, which
the model does not have, would prevent.

The outer boundary of a triangle mesh is the set of edges that belong to one triangle each.
Deformed, each is the chord ``[x_a, x_b]`` between its vertices ``x = X + u``; two chords
that share no vertex cross when each one's endpoints lie strictly on opposite sides of the
other (the signs of the orientations ``orient(p, q, r) = (q - p) x (r - p)`` differ). The
chords are the P1 trace of the boundary: a P2 edge's bow is not seen, so the count flags a
fold of at least an element's size.
"""

from __future__ import annotations

import numpy as np

#: boundary chords tested against all others at a time (bounds the pair arrays' memory)
BLOCK = 256


def outer_edges(cells: np.ndarray) -> np.ndarray:
    """The edges ``(n, 2)`` (vertex numbers) that belong to exactly one of the triangles
    ``cells`` ``(m, 3)``: the mesh's outer boundary."""
    edges = np.sort(np.concatenate([cells[:, [0, 1]], cells[:, [1, 2]], cells[:, [2, 0]]]),
                    axis=1)
    unique, count = np.unique(edges, axis=0, return_counts=True)
    return unique[count == 1]


def boundary_self_crossings(points: np.ndarray, cells: np.ndarray, u: np.ndarray) -> int:
    """The number of pairs of deformed outer boundary chords that cross, chords with a common
    vertex apart [-]: 0 unless the deformed boundary folds onto itself. ``points`` ``(nv,
    2)`` the reference vertices, ``cells`` ``(m, 3)`` the triangles, ``u`` ``(nv, 2)`` the
    displacement at the vertices."""
    x = np.asarray(points, dtype=float)[:, :2] + np.asarray(u, dtype=float)[:, :2]
    e = outer_edges(np.asarray(cells))
    p, q = x[e[:, 0]], x[e[:, 1]]

    def orient(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
        """``(b - a) x (c - a)`` for every chord ``[a, b]`` (rows) and point ``c`` (columns)."""
        d, f = b - a, c[None, :, :] - a[:, None, :]
        return d[:, None, 0] * f[..., 1] - d[:, None, 1] * f[..., 0]

    count = 0
    for i0 in range(0, len(e), BLOCK):  # rows in blocks: (BLOCK, n) arrays on fine meshes
        rows = slice(i0, i0 + BLOCK)
        # [i, j]: j's ends on opposite sides of i, and i's ends on opposite sides of j
        apart = np.sign(orient(p[rows], q[rows], p)) * np.sign(orient(p[rows], q[rows], q))
        across = np.sign(orient(p, q, p[rows])) * np.sign(orient(p, q, q[rows]))
        crosses = (apart < 0) & (across.T < 0)
        for a in range(2):  # chords with a common vertex do not count
            for b in range(2):
                crosses &= e[rows, a, None] != e[None, :, b]
        later = np.arange(len(e))[None, :] > np.arange(i0, i0 + crosses.shape[0])[:, None]
        count += int(np.count_nonzero(crosses & later))
    return count

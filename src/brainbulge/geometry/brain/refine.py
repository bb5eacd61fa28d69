"""Uniform ("red") refinement of a tetrahedral mesh, new surface nodes on the envelope.

Each tet is cut into eight: four corner tets at its vertices and four around the shortest
diagonal of the inner octahedron (Bey's rule with the shortest diagonal; the children's
shapes stay within a bounded number of classes, so the quality does not decay with repeated
refinement). A refined mesh is nested in the one it came from: every coarse P1 function is
exactly a fine P1 function (a coarse solution carries over without interpolation error and
over the same boundary).

New nodes on the outer surface (midpoints of surface edges) are moved onto the envelope, the
zero level of its signed distance, as Netgen places its own surface nodes: the refined
surface then samples the skull's inner surface as finely as a mesh built at that size. A
node is left at its midpoint where the move would flatten an adjacent tet below a quarter of
its volume.

Written by hand (NumPy, vectorised): Netgen's ``Refine`` works on its own mesh objects,
without our tissue tags and the envelope's distance, and meshio / pyvista have no 1:8
tetrahedral refinement (pyvista's ``subdivide_tetra`` makes 12 tets around added centroids).
"""

from __future__ import annotations

import numpy as np

from brainbulge.geometry.brain.quality import tet_volumes_mm3

#: The six edges of a tet as pairs of local vertex numbers.
TET_EDGES = np.array([[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]])

# Children in local numbering: 0-3 the tet's vertices, 4-9 the midpoints of TET_EDGES
# (4: 01, 5: 02, 6: 03, 7: 12, 8: 13, 9: 23).
_CORNERS = np.array([[0, 4, 5, 6], [4, 1, 7, 8], [5, 7, 2, 9], [6, 8, 9, 3]])
#: For each inner diagonal (two opposite midpoints) the four others in cyclic order.
_OCTAHEDRON = {
    (4, 9): (5, 7, 8, 6),
    (5, 8): (4, 7, 9, 6),
    (6, 7): (4, 5, 9, 8),
}


def unique_edges(tets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sorted vertex pairs (n_edges, 2) of the mesh and each tet's edge numbers (n_tets, 6)
    in the order of :data:`TET_EDGES`."""
    pairs = np.sort(tets[:, TET_EDGES], axis=2).reshape(-1, 2)
    edges, inverse = np.unique(pairs, axis=0, return_inverse=True)
    return edges, inverse.reshape(len(tets), 6)


def refine_uniformly(nodes: np.ndarray, tets: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """One uniform refinement: ``(nodes, tets, parent, edges)``.

    ``nodes`` (n + n_edges, 3): the old nodes first, in their order, then the midpoint of
    each edge of ``edges`` (n_edges, 2); ``tets`` (8 m, 4), positively oriented; ``parent``
    (8 m,): the old tet each new one lies in.
    """
    nodes = np.asarray(nodes, dtype=float)
    tets = np.asarray(tets, dtype=np.int64)
    edges, tet_edges = unique_edges(tets)
    new_nodes = np.concatenate([nodes, nodes[edges].mean(axis=1)])
    local = np.concatenate([tets, len(nodes) + tet_edges], axis=1)  # (m, 10)
    children = [local[:, c] for c in _CORNERS]
    # the octahedron is cut along its shortest diagonal, chosen per tet
    diagonals = list(_OCTAHEDRON)
    length = np.stack([np.linalg.norm(new_nodes[local[:, a]] - new_nodes[local[:, b]], axis=1)
                       for a, b in diagonals], axis=1)
    choice = np.argmin(length, axis=1)
    inner = np.empty((4, len(tets), 4), dtype=np.int64)
    for k, (a, b) in enumerate(diagonals):
        sel = choice == k
        ring = _OCTAHEDRON[(a, b)]
        for i in range(4):
            inner[i, sel] = local[sel][:, [a, b, ring[i], ring[(i + 1) % 4]]]
    new_tets = np.concatenate([np.stack(children), inner]).transpose(1, 0, 2).reshape(-1, 4)
    flip = tet_volumes_mm3(new_nodes, new_tets) < 0
    new_tets[flip] = new_tets[flip][:, [0, 2, 1, 3]]
    parent = np.repeat(np.arange(len(tets)), 8)
    return new_nodes, new_tets, parent, edges


def move_onto_surface(nodes: np.ndarray, tets: np.ndarray, movable: np.ndarray,
                      distance, iterations: int = 3, min_volume_ratio: float = 0.25
                      ) -> tuple[np.ndarray, int]:
    """Move the nodes ``movable`` (indices) onto the zero level of ``distance``.

    ``distance(x) -> (phi, grad)``: signed distance (mm, positive outside) and its gradient
    at points (k, 3). Each node takes ``iterations`` steps ``x <- x - phi grad / |grad|^2``;
    a node whose move leaves an adjacent tet with less than ``min_volume_ratio`` of its
    volume stays where it was. Returns the new nodes and how many nodes stayed.
    """
    x = np.asarray(nodes, dtype=float).copy()
    movable = np.asarray(movable, dtype=np.int64)
    if not len(movable):
        return x, 0
    target = x[movable].copy()
    for _ in range(iterations):
        phi, grad = distance(target)
        g2 = np.maximum(np.einsum("ij,ij->i", grad, grad), 1e-12)
        target -= (phi / g2)[:, None] * grad
    vol0 = tet_volumes_mm3(x, tets)
    is_movable = np.zeros(len(x), dtype=bool)
    is_movable[movable] = True
    touched = np.flatnonzero(is_movable[tets].any(axis=1))
    stayed = np.zeros(len(x), dtype=bool)
    x[movable] = target
    for _ in range(10):  # undo the moves next to flattened tets until none is left
        bad = touched[tet_volumes_mm3(x, tets[touched]) < min_volume_ratio * vol0[touched]]
        if not len(bad):
            break
        back = np.unique(tets[bad].ravel())
        back = back[is_movable[back] & ~stayed[back]]
        if not len(back):
            break
        x[back] = nodes[back]
        stayed[back] = True
    return x, int(stayed.sum())

"""An NGSolve mesh and its vertex DOFs as NumPy arrays, without a Python loop per entity.

``[v.point for v in mesh.vertices]``, ``mesh.Elements(VOL)`` and ``GetDofNrs`` per vertex
cost seconds per million entities: at 1.4M tets a carry-over of a coarse state spent
~17 s in such loops and the vertex fields ~8 s. Netgen's own arrays
(``Coordinates()``, ``Elements3D().NumPy()``) give the same numbers at once.
"""

from __future__ import annotations

import ngsolve as ngs
import numpy as np


def vertex_coordinates(mesh: ngs.Mesh) -> np.ndarray:
    """Vertex coordinates ``(nv, dim)`` in NGSolve's vertex numbering."""
    return np.array(mesh.ngmesh.Coordinates(), dtype=float)[:, : mesh.dim]


def element_vertices(mesh: ngs.Mesh) -> tuple[np.ndarray, np.ndarray]:
    """Vertex numbers ``(ne, dim + 1)`` (0-based) and region index ``(ne,)`` (0-based, as
    ``el.index``) of the volume simplices, in NGSolve's element numbering."""
    els = (mesh.ngmesh.Elements3D() if mesh.dim == 3 else mesh.ngmesh.Elements2D()).NumPy()
    return (els["nodes"][:, : mesh.dim + 1].astype(np.int64) - 1,
            els["index"].astype(np.int64) - 1)


def element_corners(mesh: ngs.Mesh):
    """Mapped points at every element's vertices, element by element, in the order of
    :func:`element_vertices` (NGSolve's reference simplex: ``e_1, ..., e_dim, 0``), for
    evaluating CoefficientFunctions per element corner."""
    corners = np.vstack([np.eye(mesh.dim), np.zeros(mesh.dim)])
    ir = ngs.IntegrationRule([tuple(c) + (0.0,) * (3 - mesh.dim) for c in corners],
                             [1.0] * len(corners))
    return mesh.MapToAllElements(ir, ngs.VOL)


def vertex_dofs(space: ngs.FESpace, mesh: ngs.Mesh,
                elements: np.ndarray | None = None) -> np.ndarray:
    """DOF numbers ``(nv, ncomp)`` of the vertex basis functions of an H1-type ``space``
    (scalar: ``ncomp = 1``; ``VectorH1``: one per component), as ``space.GetDofNrs(
    NodeId(VERTEX, v))`` gives them; -1 at vertices of no element of ``elements`` (a mask
    over the elements; default all: a space ``definedon`` some regions needs theirs).

    A hierarchical H1 basis is 1 at its vertex and every other basis function vanishes
    there, so a GridFunction holding its own DOF numbers takes the value ``dof(v)`` at
    vertex ``v``: evaluated at every element's corners, all vertices at once.
    """
    gf = ngs.GridFunction(space)
    gf.vec.FV().NumPy()[:] = np.arange(space.ndof, dtype=float)
    vals = np.asarray(gf(element_corners(mesh)))
    els, _ = element_vertices(mesh)
    vals = vals.reshape(len(els), mesh.dim + 1, gf.dim)
    if elements is not None:
        els, vals = els[elements], vals[elements]
    dofs = np.full((mesh.nv, gf.dim), -1, dtype=np.int64)
    dofs[els.ravel()] = np.rint(vals.reshape(-1, gf.dim)).astype(np.int64)
    return dofs

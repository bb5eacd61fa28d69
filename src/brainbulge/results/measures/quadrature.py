"""Fields sampled at integration points: the raw material for extremes and checks.

NGSolve evaluates a coefficient function at all integration points of all elements in one
vectorised call (``mesh.MapToAllElements``), so summaries are taken where the solver sees the
fields, not at interpolated nodes.
"""

from __future__ import annotations

from dataclasses import dataclass

import ngsolve as ngs
import numpy as np

_VOLUME_SHAPE = {2: ngs.TRIG, 3: ngs.TET}
_FACET_SHAPE = {2: ngs.SEGM, 3: ngs.TRIG}


@dataclass
class QuadraturePoints:
    """Integration points of a mesh (volume or boundary) with coordinates and weights."""

    mesh: ngs.Mesh
    points: object  # NGSolve MeshPoint array
    X: np.ndarray  # reference coordinates, shape (n, dim)
    weights: np.ndarray  # quadrature weight times Jacobian, i.e. dV or dA per point

    def __call__(self, cf: ngs.CoefficientFunction) -> np.ndarray:
        """Values of ``cf`` at the points, shape ``(n,)`` or ``(n, ncomp)``."""
        vals = np.asarray(cf(self.points))
        return vals[:, 0] if vals.ndim == 2 and vals.shape[1] == 1 else vals


def quadrature_points(mesh: ngs.Mesh, order: int = 4, boundary: bool = False) -> QuadraturePoints:
    """All integration points (volume, or boundary facets) of a rule of the given order."""
    dim = mesh.dim
    shape = (_FACET_SHAPE if boundary else _VOLUME_SHAPE)[dim]
    ir = ngs.IntegrationRule(shape, order)
    pts = mesh.MapToAllElements(ir, ngs.BND if boundary else ngs.VOL)
    coords = ngs.CF((ngs.x, ngs.y, ngs.z)[:dim])
    X = np.asarray(coords(pts)).reshape(-1, dim)
    # weight = reference weight x measure ratio of the element map at the point
    n_el = X.shape[0] // len(ir)
    ref_w = np.tile(np.asarray(ir.weights), n_el)
    det = np.abs(np.asarray(_jacobian_det(dim, boundary)(pts))).reshape(-1)
    return QuadraturePoints(mesh, pts, X, ref_w * det)


def _jacobian_det(dim: int, boundary: bool) -> ngs.CoefficientFunction:
    if not boundary:
        return ngs.Det(ngs.specialcf.JacobianMatrix(dim))
    # on a facet, the measure ratio is the norm of the tangential Jacobian
    Jac = ngs.specialcf.JacobianMatrix(dim, dim - 1)
    if dim == 2:
        return ngs.Norm(Jac)
    return ngs.sqrt(ngs.Det(Jac.trans * Jac))

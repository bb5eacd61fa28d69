"""Frictionless contact with a rigid body by a penalty in the energy, at integration points.

The rigid body is known by its signed distance ``g(x)`` [length] as an NGSolve coefficient
function of the deformed position ``x = X + u`` (positive outside the body). The energy gains

    Pi_c(u) = int_Gamma kappa/2 max(-g(X + u), 0)^2 dA,

over the contact boundary ``Gamma`` at :data:`POINTS` Gauss points per boundary segment, so
NGSolve's ``Variation`` gives the contact force ``-kappa max(-g, 0) grad g`` and its tangent
(the gap's curvature included). The contact pressure is ``kappa max(-g, 0)`` [stress]; a
point enters and leaves contact continuously (no active set to cycle), and the body is
entered by ``pressure / kappa``. A point that slides past a rounded edge is released
smoothly, and tissue that bulges out is held off the body's end face by the same term.
"""

from __future__ import annotations

import re

import ngsolve as ngs
import numpy as np

from brainbulge.errors import InputError
from brainbulge.geometry.ngsolve_arrays import vertex_coordinates, vertex_dofs

#: Gauss points per boundary segment (2D): the penalty's integration rule, exact for the
#: quadratic displacement of a Taylor-Hood boundary segment through ``g``'s curvature
POINTS = 5


class PenaltyContact:
    """The contact of the boundary ``boundary`` (regex) of ``form``'s mesh with ``obstacle``
    (its ``gap(x)`` on a coefficient function ``x``) by a penalty of stiffness ``kappa``
    [stress/length]."""

    def __init__(self, form, boundary: str, obstacle, kappa: float) -> None:
        mesh = form.mesh
        if mesh.dim != 2:
            raise InputError("penalty contact is implemented for 2D meshes only; use the "
                             "exact multipliers (no penalty) in 3D")
        if not hasattr(obstacle, "gap"):
            raise InputError(f"the obstacle of contact boundary {boundary!r} has no gap(x) "
                             "on coefficient functions; the penalty needs one")
        if not kappa > 0:
            raise InputError(f"penalty stiffness {kappa} must be positive")
        self.form, self.boundary, self.obstacle, self.kappa = form, boundary, obstacle, kappa
        self.region = mesh.Boundaries(boundary)
        if not any(self.region.Mask()):
            raise InputError(f"contact boundary {boundary!r} matches no mesh boundary")
        rule = ngs.IntegrationRule(ngs.SEGM, 2 * POINTS - 1)
        self.ds = ngs.ds(definedon=self.region, intrules={ngs.SEGM: rule})
        self._points = mesh.MapToAllElements(rule, self.region)
        u = form.gfu.components[0]
        self._depth = -obstacle.gap(_position(u))  # at the state: > 0 inside the body
        names = mesh.GetBoundaries()
        rx = re.compile(f"^(?:{boundary})$")
        #: the boundary's vertices (mesh numbers) and their displacement DOFs (vertex values)
        self.vertices = np.unique([v.nr for el in mesh.Elements(ngs.BND)
                                   if rx.match(names[el.index]) for v in el.vertices])
        dofs = vertex_dofs(form.fes.components[0], mesh)[self.vertices]
        self._vertex_dofs = dofs + form.fes.Range(0).start
        self._X = vertex_coordinates(mesh)[self.vertices]

    def energy(self, u: ngs.CoefficientFunction) -> ngs.CoefficientFunction:
        """``kappa/2 max(-g(X + u), 0)^2`` [energy/area] for the trial function ``u``."""
        depth = -self.obstacle.gap(_position(u))
        return 0.5 * self.kappa * ngs.IfPos(depth, depth * depth, 0.0)

    def max_penetration(self) -> float:
        """Largest ``max(-g, 0)`` at the Gauss points of the current state [length]."""
        depth = np.asarray(self._depth(self._points)).ravel()
        if not np.all(np.isfinite(depth)):
            return float("nan")
        return float(max(depth.max(initial=0.0), 0.0)) + 0.0  # no -0.0 in reports

    def free_measure(self, tol: float) -> float:
        """Length of the boundary away from the obstacle by more than ``tol`` at rest."""
        g = self.obstacle.gap(ngs.CF((ngs.x, ngs.y)))
        return float(ngs.Integrate(ngs.IfPos(g - tol, 1.0, 0.0), self.form.mesh,
                                   definedon=self.region))

    def at_vertices(self) -> tuple[np.ndarray, np.ndarray]:
        """The gap ``g`` [length] and the contact pressure ``kappa max(-g, 0)`` [stress] at
        the boundary's :attr:`vertices` in the current state."""
        x = self.form.gfu.vec.FV().NumPy()
        g = self.obstacle.gap_numpy(self._X + x[self._vertex_dofs])
        return g, self.kappa * np.maximum(-g, 0.0)

    def gap(self) -> ngs.CoefficientFunction:
        """The gap ``g(X + u)`` of the current state [length]."""
        return -self._depth

    def pressure(self) -> ngs.CoefficientFunction:
        """The contact pressure ``kappa max(-g, 0)`` at the current state [stress]."""
        return self.kappa * ngs.IfPos(self._depth, self._depth, 0.0)


def _position(u: ngs.CoefficientFunction) -> ngs.CoefficientFunction:
    """The deformed position ``X + u`` (2D) [length]."""
    return ngs.CF((ngs.x + u[0], ngs.y + u[1]))

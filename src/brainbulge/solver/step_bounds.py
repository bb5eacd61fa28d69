"""How far a Newton update and a load step may move the mesh's vertices, in element sizes.

Both bounds measure a displacement increment ``du_v`` of a vertex ``v`` in units of its
smallest incident edge ``h_v`` [length]:

- :class:`StepCap`, a trust region on Newton's update: the update ``dx`` is scaled by
  ``f = min(1, cap / max_v |du_v| / h_v)`` so that no vertex moves more than ``cap`` of its
  smallest edge (options ``newton.step_cap``);
- :class:`Slide`, the motion of a load step: the largest ``|du_v| / h_v`` from its start to
  its end, which sizes the next step (options ``ramp.slide``): where the tissue wraps a
  rounded skull edge, the finest elements move farthest, and Newton's capped updates cost
  about ``motion / cap`` iterations.
"""

from __future__ import annotations

import ngsolve as ngs
import numpy as np

from brainbulge.geometry.ngsolve_arrays import element_vertices, vertex_coordinates, vertex_dofs


def vertex_scales(form) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The displacement DOFs ``(nv, dim)`` of each vertex in ``form.fes``'s numbering (-1 on
    none), its smallest incident edge ``h_v`` (nv,) and its position ``X`` (nv, dim) [length]."""
    mesh = form.mesh
    X = vertex_coordinates(mesh)
    els, _ = element_vertices(mesh)
    h = np.full(len(X), np.inf)
    for a in range(els.shape[1]):
        for b in range(a + 1, els.shape[1]):
            length = np.linalg.norm(X[els[:, a]] - X[els[:, b]], axis=1)
            np.minimum.at(h, els[:, a], length)
            np.minimum.at(h, els[:, b], length)
    dofs = vertex_dofs(form.fes.components[0], mesh)
    dofs = np.where(dofs >= 0, dofs + form.fes.Range(0).start, -1)
    return dofs, h, X


def _moves(dofs: np.ndarray, h: np.ndarray, d: np.ndarray) -> np.ndarray:
    """``|du_v| / h_v`` of the vertices for the increment ``d`` (full numbering) [-]."""
    du = np.where(dofs >= 0, d[np.maximum(dofs, 0)], 0.0)
    return np.linalg.norm(du, axis=1) / h


class StepCap:
    """``limit_step(x, dx) -> f``: the factor that keeps every vertex's move within ``cap``
    of its smallest incident edge (:data:`~brainbulge.solver.newton.StepLimit`)."""

    def __init__(self, form, cap: float) -> None:
        self.dofs, self.h, _ = vertex_scales(form)
        self.cap = cap

    def __call__(self, x: ngs.BaseVector, dx: ngs.BaseVector) -> float:
        largest = float(np.max(_moves(self.dofs, self.h, dx.FV().NumPy()), initial=0.0))
        return 1.0 if largest <= self.cap else self.cap / largest


class Slide:
    """The motion of a load step: the largest ``|du_v| / h_v`` over the vertices [edge
    elements], the measure :class:`StepCap` bounds per Newton update."""

    def __init__(self, form) -> None:
        self.dofs, self.h, _ = vertex_scales(form)

    def __call__(self, x_start: np.ndarray, x_end: np.ndarray) -> float:
        """The motion from the state ``x_start`` to ``x_end`` (full numbering) [-]."""
        return float(np.max(_moves(self.dofs, self.h, x_end - x_start), initial=0.0))

"""Where the free DOFs of a mixed form sit: each displacement DOF's mesh vertex and
component, and the rigid-body motions in those DOFs (the near-nullspace of the displacement
block, for the AMG of :mod:`.amg`).

A rigid motion ``u(X) = t + w x (X - X_c)`` has, at the DOF of vertex ``v`` and component
``c``, the value ``t_c + (w x (X_v - X_c))_c``; hierarchical higher-order basis functions
(Taylor-Hood's P2 edge functions) vanish at every vertex and carry none of it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from brainbulge.errors import InputError


@dataclass
class DisplacementLayout:
    """Where each free displacement DOF sits: its mesh vertex and its component.

    Attributes:
        coords: (n_vertices, dim) vertex coordinates.
        vertex: (n_free_u,) vertex of each free displacement DOF, in the order of the free
            DOFs; -1 at the DOFs of higher-order hierarchical basis functions (Taylor-Hood's
            P2 edge functions), which vanish at every vertex and carry no part of a rigid
            motion.
        component: (n_free_u,) component (0 = x, 1 = y, 2 = z) of each.
    """

    coords: np.ndarray
    vertex: np.ndarray
    component: np.ndarray

    @property
    def dim(self) -> int:
        return int(self.coords.shape[1])

    @property
    def linear(self) -> np.ndarray:
        """(n_free_u,) True at the DOFs of vertex (P1 hat) basis functions."""
        return self.vertex >= 0

    def rigid_body_modes(self) -> np.ndarray:
        """(n_free_u, 3 or 6) translations and linearised rotations about the centroid
        (zero at hierarchical higher-order DOFs: a linear field is their P1 part alone)."""
        dim = self.dim
        X = np.where(self.linear[:, None], self.coords[self.vertex] - self.coords.mean(axis=0),
                     0.0)
        c = np.where(self.linear, self.component, -1)
        n = len(c)
        modes = [(c == i).astype(float) for i in range(dim)]
        # rotation about axis k: (e_k x X)_c, i.e. for (i, j) = (x, y): (-y, x)
        pairs = [(0, 1)] if dim == 2 else [(0, 1), (1, 2), (2, 0)]
        for i, j in pairs:
            m = np.zeros(n)
            m[c == i] = -X[c == i, j]
            m[c == j] = X[c == j, i]
            modes.append(m)
        return np.column_stack(modes)


def free_dofs(form) -> np.ndarray:
    """Indices of the free DOFs exactly as :class:`NewtonSolver` restricts the tangent."""
    return np.flatnonzero(np.array(list(form.fes.FreeDofs(form.condense)), dtype=bool))


def displacement_layout(form, free: np.ndarray | None = None) -> DisplacementLayout:
    """Vertex and component of every free displacement DOF of a MINI (P1 + condensed
    bubble) or Taylor-Hood (hierarchical P2) ``form``.

    Built from each vertex's DOF numbers (:func:`vertex_dofs`), so it does not rely on
    NGSolve's DOF ordering (which for VectorH1 is: all x-components, then all y, then all z,
    each with the vertex DOFs first). Free DOFs that are no vertex's (P2 edge functions) get
    vertex -1 and the component of their block of the ordering.
    """
    from brainbulge.geometry.ngsolve_arrays import vertex_coordinates, vertex_dofs

    if free is None:
        free = free_dofs(form)
    mesh = form.mesh
    fes = form.fes
    rng = fes.Range(0)
    V = fes.components[0]
    dim = mesh.dim
    vert_of = np.full(V.ndof, -1, dtype=np.int64)
    comp_of = np.full(V.ndof, -1, dtype=np.int64)
    dofs = vertex_dofs(V, mesh)
    if dofs.shape != (mesh.nv, dim):
        raise InputError("the Krylov solver needs the MINI element (P1 + condensed bubbles)")
    vert_of[dofs] = np.arange(mesh.nv)[:, None]
    comp_of[dofs] = np.arange(dim)[None, :]
    free_u = free[(free >= rng.start) & (free < rng.stop)] - rng.start
    higher = vert_of[free_u] < 0
    if np.any(higher):
        if V.ndof % dim or not np.array_equal(comp_of[dofs], dofs // (V.ndof // dim)):
            raise InputError("the Krylov solver does not know this displacement space's "
                             "DOF numbering; use the direct solver")
        comp_of[free_u[higher]] = free_u[higher] // (V.ndof // dim)
    coords = vertex_coordinates(mesh)
    return DisplacementLayout(coords, vert_of[free_u], comp_of[free_u])

"""Frictionless contact with a rigid body known only through a NumPy signed distance.

The 3D skull is a signed distance sampled on the MRI grid (:class:`RigidSkull`), not a
symbolic expression, so the symbolic contact term of :mod:`mixed` cannot use it. Here the
contact is enforced at *contact points* of the boundary: its vertices (and, for P2
displacements, its edge midpoints), each with a lumped reference area ``A_i``. At the deformed
position ``x_i = X_i + u(X_i) = X_i + (P d)_i`` (``P`` evaluates the displacement DOFs ``d`` at
the points) the obstacle gives the gap ``g_i`` and its gradient ``n_i = grad g(x_i)``. The
contact energy is the same augmented Lagrangian as the symbolic one::

    Pi_c(d) = sum_i A_i S(z_i) / r,     z_i = lambda_i - r (g_i - g0_i - g_off)

so, with ``s = S'``::

    R_c = P^T [ -A_i s(z_i) n_i ],       K_c = P^T [ A_i r s'(z_i) n_i n_i^T ] P

(the curvature term ``-A_i s(z_i) grad^2 g`` is left out of ``K_c``: the tangent stays
symmetric positive semi-definite and Newton loses only its quadratic rate near curved
contact, not the solution). ``lambda_i`` is updated by Uzawa's rule ``lambda <- s(z)``; the
force at a point is along ``n_i`` only: the contact is frictionless by construction.
Written by hand because no library we use couples an NGSolve form to a sampled obstacle.
"""

from __future__ import annotations

import re
from typing import Protocol

import ngsolve as ngs
import numpy as np
import scipy.sparse as sp

from brainbulge.errors import InputError


class PointObstacle(Protocol):
    """A rigid body given by its signed distance on point arrays.

    ``gap_and_normal(x)`` returns ``g`` (n,) [length], positive outside the rigid body
    (admissible), and ``grad g`` (n, dim), the unit outward normal of the body near it.
    """

    def gap_and_normal(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]: ...


def smoothed_ramp(z: np.ndarray, eps: float) -> tuple[np.ndarray, np.ndarray]:
    """``s(z)`` and ``s'(z)`` of the C1 ramp used by every contact (see ``mixed``)."""
    s = np.where(z > eps, z - eps / 2, np.where(z > 0, z * z / (2 * eps), 0.0))
    ds = np.where(z > eps, 1.0, np.where(z > 0, z / eps, 0.0))
    return s, ds


def smoothed_ramp_potential(z: np.ndarray, eps: float) -> np.ndarray:
    """``S(z)`` with ``S' = s``."""
    return np.where(
        z > eps, z * z / 2 - eps * z / 2 + eps**2 / 6, np.where(z > 0, z**3 / (6 * eps), 0.0)
    )


class PointContact:
    """Contact of the boundary ``boundary`` (regex) of ``form``'s mesh with ``obstacle``.

    ``form`` provides the displacement space (first component of ``form.fes``), the penalty
    parameter ``form.r``, the smoothing ``form.eps_c`` and the mesh size ``form.h``.
    """

    def __init__(self, form, boundary: str, obstacle: PointObstacle) -> None:
        self.form = form
        self.boundary = boundary
        self.obstacle = obstacle
        mesh = form.mesh
        dim = mesh.dim
        self.dim = dim
        rx = re.compile(f"^(?:{boundary})$")
        names = mesh.GetBoundaries()
        faces = [el for el in mesh.Elements(ngs.BND) if rx.match(names[el.index])]
        if not faces:
            raise InputError(f"contact boundary {boundary!r} matches no mesh boundary")
        coords = np.array([v.point for v in mesh.vertices])[:, :dim]
        fverts = np.array([[v.nr for v in el.vertices] for el in faces])
        area = _facet_measure(coords[fverts])
        V = form.fes.components[0]
        order2 = V.globalorder >= 2
        # contact points: vertices, and edge midpoints of P2 displacements, lumped weights of
        # the uniform subdivision (P2 triangle: corner A/12, midpoint A/4; P2 segment: end
        # L/4, midpoint L/2; P1: A/dim at each vertex)
        verts, vinv = np.unique(fverts, return_inverse=True)
        vinv = vinv.reshape(fverts.shape)
        n_v = len(verts)
        w_corner = (1 / 12 if dim == 3 else 1 / 4) if order2 else 1 / dim
        weights = np.bincount(vinv.ravel(), np.repeat(area * w_corner, dim), minlength=n_v)
        X = coords[verts]
        rows, cols, vals = [], [], []
        off = form.fes.Range(0).start
        for k, v in enumerate(verts):
            for i, dof in enumerate(V.GetDofNrs(ngs.NodeId(ngs.VERTEX, int(v)))):
                rows.append(k * dim + i)
                cols.append(off + dof)
                vals.append(1.0)
        if order2:
            edges = sorted({e.nr for el in faces for e in el.edges})
            beta = _edge_bubble_midpoint_value(mesh, V)
            e_index = {e: n_v + j for j, e in enumerate(edges)}
            e_weight = np.zeros(len(edges))
            w_mid = 1 / 4 if dim == 3 else 1 / 2
            for el, a in zip(faces, area, strict=True):
                for e in el.edges:
                    e_weight[e_index[e.nr] - n_v] += a * w_mid
            Xe = []
            for j, e in enumerate(edges):
                ends = [v.nr for v in mesh.edges[e].vertices]
                Xe.append(coords[ends].mean(axis=0))
                k = n_v + j
                for end in ends:
                    for i, dof in enumerate(V.GetDofNrs(ngs.NodeId(ngs.VERTEX, end))):
                        rows.append(k * dim + i)
                        cols.append(off + dof)
                        vals.append(0.5)
                for i, dof in enumerate(V.GetDofNrs(ngs.NodeId(ngs.EDGE, e))):
                    rows.append(k * dim + i)
                    cols.append(off + dof)
                    vals.append(beta)
            X = np.vstack([X, np.array(Xe)])
            weights = np.concatenate([weights, e_weight])
        self.X = X
        self.weights = weights  # lumped reference area per point [length^(dim-1)]
        self.n_points = len(X)
        self.P = sp.csr_matrix((vals, (rows, cols)), shape=(self.n_points * dim, form.fes.ndof))
        self.lam = np.zeros(self.n_points)  # contact pressure multiplier [stress]
        # initial-gap adjustment (as for the symbolic contact): points that rest on the
        # obstacle up to the geometric error of the mesh touch it exactly
        g_rest, _ = obstacle.gap_and_normal(X)
        self.g_rest = g_rest
        self.g0 = np.where(np.abs(g_rest) < 0.05 * form.h, g_rest, 0.0)
        # boundary fields for output: contact pressure and gap on a P1 boundary space
        self._out_space = ngs.H1(mesh, order=1, definedon=mesh.Boundaries(boundary))
        self._out_dofs = np.array(
            [self._out_space.GetDofNrs(ngs.NodeId(ngs.VERTEX, int(v)))[0] for v in verts]
        )
        self.pressure_gf = ngs.GridFunction(self._out_space)
        self.gap_gf = ngs.GridFunction(self._out_space)
        self.update(form.gfu.vec.FV().NumPy())

    # --- state -----------------------------------------------------------------------
    def update(self, x: np.ndarray) -> None:
        """Gap and normal at the deformed contact points of the DOF vector ``x``."""
        u = (self.P @ x).reshape(self.n_points, self.dim)
        g, n = self.obstacle.gap_and_normal(self.X + u)
        if not (np.all(np.isfinite(g)) and np.all(np.isfinite(n))):
            g = np.full_like(g, np.nan)
        self.g = g - self.g0
        self.n = n
        r = self.form.r.Get()
        g_off = self.form.eps_c / (2 * r)  # makes g = 0 the fixed point of Uzawa
        self.z = self.lam - r * (self.g - g_off)

    def energy(self) -> float:
        r = self.form.r.Get()
        return float(self.weights @ smoothed_ramp_potential(self.z, self.form.eps_c) / r)

    def add_residual(self, R: np.ndarray) -> None:
        """``R += P^T (-A s(z) n)`` for the state of the last :meth:`update`."""
        s, _ = smoothed_ramp(self.z, self.form.eps_c)
        f = -(self.weights * s)[:, None] * self.n
        R += self.P.T @ f.ravel()

    def tangent(self) -> sp.csr_matrix:
        """``K_c = P^T blockdiag(A r s'(z) n n^T) P`` (full DOF numbering)."""
        _, ds = smoothed_ramp(self.z, self.form.eps_c)
        c = self.weights * self.form.r.Get() * ds
        on = np.flatnonzero(c > 0)
        d = self.dim
        blocks = c[on, None, None] * np.einsum("ni,nj->nij", self.n[on], self.n[on])
        rows = (on[:, None, None] * d + np.arange(d)[None, :, None]).repeat(d, axis=2)
        cols = (on[:, None, None] * d + np.arange(d)[None, None, :]).repeat(d, axis=1)
        m = self.n_points * d
        B = sp.csr_matrix((blocks.ravel(), (rows.ravel(), cols.ravel())), shape=(m, m))
        return (self.P.T @ B @ self.P).tocsr()

    def update_multipliers(self) -> None:
        """Uzawa: ``lambda <- s(z)``."""
        self.lam = smoothed_ramp(self.z, self.form.eps_c)[0]

    def pressure(self) -> np.ndarray:
        """Contact pressure ``s(z)`` at the points [stress]."""
        return smoothed_ramp(self.z, self.form.eps_c)[0]

    def max_penetration(self) -> float:
        """Largest ``max(-g, 0)`` at the contact points of the current state [length]."""
        self.update(self.form.gfu.vec.FV().NumPy())
        return float(max(np.max(-self.g), 0.0))

    def free_measure(self, tol: float) -> float:
        """Area of the boundary that is away from the obstacle by more than ``tol`` at rest."""
        return float(self.weights[self.g_rest - self.g0 > tol].sum())

    def fields(self) -> tuple[ngs.GridFunction, ngs.GridFunction]:
        """Contact pressure and gap at the boundary vertices as P1 boundary fields."""
        self.update(self.form.gfu.vec.FV().NumPy())
        nv = len(self._out_dofs)
        self.pressure_gf.vec.FV().NumPy()[self._out_dofs] = self.pressure()[:nv]
        self.gap_gf.vec.FV().NumPy()[self._out_dofs] = self.g[:nv]
        return self.pressure_gf, self.gap_gf


def _facet_measure(pts: np.ndarray) -> np.ndarray:
    """Length (2D) or area (3D) of facets given by their vertex coordinates (n, dim, dim)."""
    if pts.shape[1] == 2:
        return np.linalg.norm(pts[:, 1] - pts[:, 0], axis=1)
    return 0.5 * np.linalg.norm(np.cross(pts[:, 1] - pts[:, 0], pts[:, 2] - pts[:, 0]), axis=1)


def _edge_bubble_midpoint_value(mesh: ngs.Mesh, V: ngs.FESpace) -> float:
    """Value at the edge midpoint of NGSolve's lowest-order edge shape function."""
    gf = ngs.GridFunction(V)
    edge = mesh.edges[0]
    gf.vec[:] = 0
    gf.vec[V.GetDofNrs(ngs.NodeId(ngs.EDGE, edge.nr))[0]] = 1
    a, b = (np.array(mesh.vertices[v.nr].point) for v in edge.vertices)
    return float(gf(mesh(*((a + b) / 2)))[0])

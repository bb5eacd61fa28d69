"""Frictionless contact with a rigid body known through a NumPy signed distance.

The skull is a signed distance on point arrays (the 2D skull arc, or the 3D one sampled on
the MRI grid, :class:`RigidSkull`). The
contact is enforced at *contact points* of the boundary: its vertices (and, for P2
displacements, its edge midpoints), each with a lumped reference area ``A_i``. At the deformed
position ``x_i = X_i + (P d)_i`` (``P`` evaluates the displacement DOFs ``d`` at the points)
the obstacle gives the gap ``g_i`` and the normal ``n_i = grad g(x_i)``.

The contact pressure ``lambda_i >= 0`` is a Lagrange multiplier (exact, no penalty): the
residual gains the contact forces and the constraints are the Signorini conditions, written
with the complementarity function of the primal-dual active set method (semi-smooth Newton)::

    R_u = R_int(d) - P^T [A_i lambda_i n_i] = R_int - B^T lambda,     B_i = A_i n_i^T P_i
    C_i = lambda_i - max(0, lambda_i - c g_i) = 0     (g >= 0, lambda >= 0, lambda g = 0)

Active points (``lambda_i - c g_i > 0``) satisfy ``g_i = 0``, inactive ones ``lambda_i = 0``.
Newton's matrix for ``(d, lambda_A)`` is the symmetric saddle point
``[[K - P^T(A lambda grad^2 g)P, -B_A^T], [-B_A, 0]]``. The curvature term ``grad^2 g`` (central
differences of the normal) keeps Newton quadratic while the tissue slides over the curved
skull. A penalty (augmented Lagrangian) form of the same contact stalled on the brain: the
gap's curvature times a stiff penalty left Newton 1/16 line-search steps. The force at a point
is along ``n_i``: the contact is frictionless by construction. Written by hand because no
library we use couples an NGSolve form to a sampled obstacle.
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


class PointContact:
    """Contact of the boundary ``boundary`` (regex) of ``form``'s mesh with ``obstacle``.

    ``form`` provides the displacement space (first component of ``form.fes``), the state
    ``form.gfu`` and the mesh size ``form.h``.
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
            beta = edge_bubble_midpoint_value(mesh, V)
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
            X = np.vstack([X, _curved_midpoints(mesh, np.array(Xe))])
            weights = np.concatenate([weights, e_weight])
        self.X = X
        self.vertices = verts  # mesh vertex numbers of the first points
        self.weights = weights  # lumped reference area per point [length^(dim-1)]
        self.n_points = len(X)
        self.P = sp.csr_matrix((vals, (rows, cols)), shape=(self.n_points * dim, form.fes.ndof))
        self.lam = np.zeros(self.n_points)  # contact pressure [stress]
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
        self.x = self.X + u
        g, n = self.obstacle.gap_and_normal(self.x)
        if not (np.all(np.isfinite(g)) and np.all(np.isfinite(n))):
            g = np.full_like(g, np.nan)
        self.g = g - self.g0
        self.n = n

    def move_onto_obstacle(self, x: np.ndarray, which: np.ndarray) -> None:
        """Move the points ``which`` (mask) of the DOF vector ``x`` (in place) onto the
        obstacle along its normal, ``u_i <- u_i - g_i n_i / |n_i|^2`` (a Newton step on
        ``g(x_i) = 0``; the sampled skull's ``|grad g|`` is 1 only to first order, up to
        1.14 at the rounded cut edge). Mesh vertices with a normal only (a P2 edge midpoint
        is not a node of its own); the gaps are those of the last :meth:`update`."""
        n2 = np.sum(self.n**2, axis=1)
        which = which & (n2 > 0)  # no normal (deep inside a thin rigid body): left alone
        which[len(self.vertices):] = False
        move = -(np.where(which, self.g, 0.0) / np.where(which, n2, 1.0))[:, None] * self.n
        x += self.P.T @ move.ravel()

    def add_forces(self, R: np.ndarray, lam: np.ndarray | None = None) -> None:
        """``R -= B^T lambda = P^T [A_i lambda_i n_i]`` (the skull's push, as a residual)."""
        lam = self.lam if lam is None else lam
        f = (self.weights * lam)[:, None] * self.n
        R -= self.P.T @ f.ravel()

    def B(self, rows: np.ndarray) -> sp.csr_matrix:
        """Constraint rows ``B_i = A_i n_i^T P_i`` for the points ``rows`` (full numbering)."""
        d = self.dim
        m = len(rows)
        N = sp.csr_matrix(
            (
                (self.weights[rows, None] * self.n[rows]).ravel(),
                (np.repeat(np.arange(m), d), (rows[:, None] * d + np.arange(d)).ravel()),
            ),
            shape=(m, self.n_points * d),
        )
        return (N @ self.P).tocsr()

    def curvature(self) -> sp.csr_matrix:
        """``P^T blockdiag(A_i lambda_i grad^2 g(x_i)) P`` over the points with a force.

        Every point with ``lambda_i != 0`` counts, pulling ones (``lambda_i < 0``, left by
        the last Newton step and released by this one) too: their force ``-A_i lambda_i
        n(x_i)`` turns with ``x_i`` as well, and leaving their term out made the tangent
        inconsistent (the brain's Newton iterations converged linearly, at rates 0.2-0.35
        per iteration at 1.54M tets, once such points appeared)."""
        on = np.flatnonzero(self.lam != 0)
        d = self.dim
        blocks = (self.weights * self.lam)[on, None, None] * self.hessian(on)
        rows = (on[:, None, None] * d + np.arange(d)[None, :, None]).repeat(d, axis=2)
        cols = (on[:, None, None] * d + np.arange(d)[None, None, :]).repeat(d, axis=1)
        m = self.n_points * d
        H = sp.csr_matrix((blocks.ravel(), (rows.ravel(), cols.ravel())), shape=(m, m))
        return (self.P.T @ H @ self.P).tocsr()

    def active(self, c: float) -> np.ndarray:
        """Active set ``lambda - c g >= 0`` (``c`` [stress/length] weighs gap against
        pressure; points resting on the obstacle start active)."""
        return self.lam - c * self.g >= 0

    def complementarity(self, c: float) -> np.ndarray:
        """``A_i C_i / c`` [volume]: ``A g`` on active points, ``A lambda / c`` elsewhere."""
        return self.weights * (self.lam - np.maximum(0.0, self.lam - c * self.g)) / c

    def hessian(self, on: np.ndarray) -> np.ndarray:
        """``grad^2 g`` (m, dim, dim) at the deformed points ``on``: central differences
        of the obstacle's normal with a step of ``1e-3 h`` (the sampled skull is C2 away
        from its cut edge), symmetrised."""
        return self.hessian_at(self.x[on])

    def hessian_at(self, x: np.ndarray) -> np.ndarray:
        """``grad^2 g`` (m, dim, dim) at the points ``x`` (m, dim), as :meth:`hessian`."""
        if len(x) == 0:
            return np.zeros((0, self.dim, self.dim))
        delta = 1e-3 * self.form.h
        H = np.empty((len(x), self.dim, self.dim))
        for k in range(self.dim):
            e = np.zeros(self.dim)
            e[k] = delta
            H[:, :, k] = (
                self.obstacle.gap_and_normal(x + e)[1] - self.obstacle.gap_and_normal(x - e)[1]
            ) / (2 * delta)
        return 0.5 * (H + H.transpose(0, 2, 1))

    def pressure(self) -> np.ndarray:
        """Contact pressure at the points [stress]: the force ``A_i lambda_i n_i`` per
        reference area, ``lambda_i |n_i|`` at the last :meth:`update` (``lambda_i`` itself
        where ``g`` is a distance; the sampled skull's ``|grad g|`` reaches 1.14 at its
        rounded cut edge, where the pressures are highest)."""
        return self.lam * np.linalg.norm(self.n, axis=1)

    def max_penetration(self, points: np.ndarray | None = None) -> float:
        """Largest ``max(-g, 0)`` at the contact points (or the mask ``points`` of them) of
        the current state [length]."""
        self.update(self.form.gfu.vec.FV().NumPy())
        g = self.g if points is None else self.g[points]
        return float(np.maximum(np.max(-g, initial=0.0), 0.0)) + 0.0  # no -0.0 in reports

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


def edge_bubble_midpoint_value(mesh: ngs.Mesh, V: ngs.FESpace) -> float:
    """Value at the edge midpoint of NGSolve's lowest-order edge shape function."""
    gf = ngs.GridFunction(V)
    edge = mesh.edges[0]
    gf.vec[:] = 0
    gf.vec[V.GetDofNrs(ngs.NodeId(ngs.EDGE, edge.nr))[0]] = 1
    a, b = (np.array(mesh.vertices[v.nr].point) for v in edge.vertices)
    return float(gf(mesh(*((a + b) / 2)))[0])


def _curved_midpoints(mesh: ngs.Mesh, chord_mid: np.ndarray) -> np.ndarray:
    """Midpoints of boundary edges on the (curved, ``mesh.Curve``) boundary, given the
    midpoints of their chords: a chord midpoint lies inside a circle of radius R by
    ``h^2/(8R)``, which at coarse meshes exceeds the initial-gap tolerance."""
    from scipy.spatial import cKDTree

    dim = mesh.dim
    ref = [(0.5, 0.0, 0.0)] if dim == 2 else [(0.5, 0.0, 0.0), (0.5, 0.5, 0.0), (0.0, 0.5, 0.0)]
    mips = mesh.MapToAllElements(ngs.IntegrationRule(ref, [1.0] * len(ref)), ngs.BND)
    X = ngs.CF((ngs.x, ngs.y, ngs.z)[:dim])
    candidates = np.asarray(X(mips)).reshape(-1, dim)
    _, nearest = cKDTree(candidates).query(chord_mid)
    return candidates[nearest]

"""Segment contact of a rigid body's sharp edge points (2D): a comparison variant of the
hard-case benchmark (:mod:`bench_hard_cases`), not a production path.

Node-to-surface contact keeps the tissue's nodes out of the skull, but a sharp edge of the
skull can still cut into the tissue between two nodes: at a narrow opening the skull's edge
ended up inside the tissue while the nodes around it slid away. Here each edge point ``C``
(fixed) is a contact point of its own, kept outside the deformed tissue: with the tissue
boundary's segment ``[x_a, x_b]`` nearest to ``C`` and its outward unit normal ``n`` (the
tissue on its left),

    g = n . (C - x_a) = ((C - x_a) x (x_b - x_a)) / |x_b - x_a|  >= 0,

an exact multiplier ``lambda >= 0`` per edge point (the product's primal-dual active set),
the force ``-A lambda grad g`` on the segment's two nodes (``A``: the mesh size, so that
``lambda`` is a pressure) and the curvature term ``A lambda grad^2 g`` in the tangent
(central differences of the exact gradient). Where the nearest point is a boundary vertex,
``g`` is the larger of its two segments' values at a convex vertex and the smaller at a
concave one (tissue wrapped around the edge). The object offers what the product's
``ActiveSet`` uses of a ``PointContact``.

:class:`SmoothEdgeContact` measures the gap along interpolated vertex normals (a C1
boundary), with its exact gradient by forward-mode differentiation (:class:`_Dual`, implicit
in the projection). Its gradient still jumps where the edge point passes a vertex (the
projection's derivative differs on the vertex's two segments); :class:`VertexEdgeContact`
turns the gap, within a parameter distance ``blend`` of a vertex ``v``, smoothly into the
vertex gap ``(C - x_v) . N_v`` (the edge point against the tangent line at ``v``), so that
the gradient is the same from both segments. Cubic Hermite segments:
:mod:`hermite_edge_contact`.
"""

from __future__ import annotations

import re

import ngsolve as ngs
import numpy as np
import scipy.sparse as sp

from brainbulge.errors import InputError


def segment_gap(C: np.ndarray, a: np.ndarray, b: np.ndarray) -> tuple[float, np.ndarray]:
    """Signed distance of ``C`` from the line through ``a -> b`` (positive on its right) and
    its gradient with respect to ``(a, b)`` (4,) [length, -]."""
    t = b - a
    w = C - a
    L = float(np.hypot(t[0], t[1]))
    cross = w[0] * t[1] - w[1] * t[0]
    d_cross = np.array([C[1] - b[1], b[0] - C[0], a[1] - C[1], C[0] - a[0]])
    d_L = np.concatenate([-t, t]) / L
    return cross / L, d_cross / L - cross / L**2 * d_L


class EdgeContact:
    """The edge points ``points`` (k, 2) of a rigid body against the boundary ``boundary``
    (regex) of ``form``'s tissue."""

    def __init__(self, form, boundary: str, points: np.ndarray) -> None:
        mesh = form.mesh
        if mesh.dim != 2:
            raise InputError("edge contact is implemented for 2D meshes only")
        self.form = form
        self.dim = 2
        self.C = np.asarray(points, dtype=float).reshape(-1, 2)
        self.x = self.C  # the points do not move (where other contacts read positions)
        self.n_points = len(self.C)
        rx = re.compile(f"^(?:{boundary})$")
        names = mesh.GetBoundaries()
        segs = np.array([[v.nr for v in el.vertices] for el in mesh.Elements(ngs.BND)
                         if rx.match(names[el.index])])
        if not len(segs):
            raise InputError(f"edge contact boundary {boundary!r} matches no mesh boundary")
        X = np.array([v.point for v in mesh.vertices])[:, :2]
        # orient each segment with the tissue on its left: its right normal points away from
        # the element it bounds (the centroid of the whole mesh is inside for a hemidisk,
        # but not in general, so use each segment's own element)
        inside = _inner_points(mesh, rx)
        t = X[segs[:, 1]] - X[segs[:, 0]]
        right = np.column_stack([t[:, 1], -t[:, 0]])
        flip = np.einsum("ij,ij->i", right, inside - X[segs[:, 0]]) > 0
        segs[flip] = segs[flip][:, ::-1]
        self.segments = segs
        self.X = X
        self.boundary_vertices = np.unique(segs)
        V = form.fes.components[0]
        off = form.fes.Range(0).start
        self.vertex_dofs = np.full((mesh.nv, 2), -1, dtype=np.int64)
        for v in self.boundary_vertices:
            self.vertex_dofs[v] = [off + d for d in V.GetDofNrs(ngs.NodeId(ngs.VERTEX, int(v)))]
        self.ndof = form.fes.ndof
        #: weight of each edge point [length]: ``lambda`` is then a pressure [stress]
        self.weights = np.full(self.n_points, float(form.h))
        self.lam = np.zeros(self.n_points)
        self.g0 = np.zeros(self.n_points)
        self.vertices = np.zeros(0, dtype=np.int64)  # no mesh vertex of its own
        nearest = [int(self.boundary_vertices[np.argmin(np.linalg.norm(
            X[self.boundary_vertices] - c, axis=1))]) for c in self.C]
        # P marks each edge point's nearest boundary vertex at rest: the active set reads
        # from it whether the point can move (has free DOFs), nothing else
        rows = np.repeat(np.arange(2 * self.n_points), 1)
        cols = self.vertex_dofs[nearest].ravel()
        self.P = sp.csr_matrix((np.ones(len(rows)), (rows, cols)),
                               shape=(2 * self.n_points, self.ndof))
        self.update(form.gfu.vec.FV().NumPy())

    # --- state -----------------------------------------------------------------------
    def update(self, x: np.ndarray) -> None:
        """Gap of each edge point to the deformed boundary of the DOF vector ``x``."""
        pos = self.X.copy()
        bv = self.boundary_vertices
        pos[bv] += x[self.vertex_dofs[bv]]
        self.pos = pos
        a, b = pos[self.segments[:, 0]], pos[self.segments[:, 1]]
        self.g = np.zeros(self.n_points)
        self.seg = np.zeros(self.n_points, dtype=np.int64)
        self.xi = np.zeros(self.n_points)
        t = b - a
        L2 = np.einsum("ij,ij->i", t, t)
        for k, C in enumerate(self.C):
            xi = np.clip(np.einsum("ij,ij->i", C - a, t) / L2, 0.0, 1.0)
            dist = np.linalg.norm(a + xi[:, None] * t - C, axis=1)
            s = int(np.argmin(dist))
            self.xi[k] = xi[s]
            g, _ = segment_gap(C, a[s], b[s])
            if 0.0 < xi[s] < 1.0:
                self.g[k], self.seg[k] = g, s
                continue
            # nearest point at a vertex: its other segment decides by the corner's turn
            v = self.segments[s, 0] if xi[s] == 0.0 else self.segments[s, 1]
            other = np.flatnonzero(self.segments[:, 1] == v) if xi[s] == 0.0 else \
                np.flatnonzero(self.segments[:, 0] == v)
            if not len(other):
                self.g[k], self.seg[k] = g, s
                continue
            o = int(other[0])
            g_o, _ = segment_gap(C, a[o], b[o])
            first, second = (o, s) if xi[s] == 0.0 else (s, o)
            convex = (t[first, 0] * t[second, 1] - t[first, 1] * t[second, 0]) > 0
            pick = max if convex else min
            self.g[k], self.seg[k] = pick((g, s), (g_o, o))
            self.xi[k] = float(np.clip(np.dot(C - a[self.seg[k]], t[self.seg[k]])
                                       / L2[self.seg[k]], 0.0, 1.0))

    def _local(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """``grad g_k`` (4,) with respect to the segment's node positions, and their DOFs."""
        ia, ib = self.segments[self.seg[k]]
        _, grad = segment_gap(self.C[k], self.pos[ia], self.pos[ib])
        return grad, self.vertex_dofs[[ia, ib]].ravel()

    def _hessian(self, k: int) -> np.ndarray:
        """``grad^2 g_k`` (4, 4): central differences of the exact gradient."""
        ia, ib = self.segments[self.seg[k]]
        z = np.concatenate([self.pos[ia], self.pos[ib]])
        delta = 1e-6 * float(np.linalg.norm(z[2:] - z[:2]))
        H = np.empty((4, 4))
        for j in range(4):
            e = np.zeros(4)
            e[j] = delta
            gp = segment_gap(self.C[k], (z + e)[:2], (z + e)[2:])[1]
            gm = segment_gap(self.C[k], (z - e)[:2], (z - e)[2:])[1]
            H[:, j] = (gp - gm) / (2 * delta)
        return 0.5 * (H + H.T)

    def reference_points(self) -> np.ndarray:
        """The material points at the edge points now (k, 2) [length]: the reference
        positions of the nearest points of their segments (where a rezoned mesh must be
        fine: the tissue's singular points move with the skull's edges, not with the
        material)."""
        ia, ib = self.segments[self.seg].T
        return self.X[ia] + self.xi[:, None] * (self.X[ib] - self.X[ia])

    # --- what the active set uses ------------------------------------------------------
    def add_forces(self, R: np.ndarray, lam: np.ndarray | None = None) -> None:
        """``R -= B^T lambda``."""
        lam = self.lam if lam is None else lam
        for k in np.flatnonzero(lam != 0):
            grad, dofs = self._local(int(k))
            np.add.at(R, dofs, -self.weights[k] * lam[k] * grad)  # a DOF may repeat

    def B(self, rows: np.ndarray) -> sp.csr_matrix:
        """Constraint rows ``A_k grad g_k`` (full DOF numbering) of the points ``rows``."""
        r, c, v = [], [], []
        for m, k in enumerate(rows):
            grad, dofs = self._local(int(k))
            r += [m] * len(dofs)
            c += list(dofs)
            v += list(self.weights[k] * grad)
        return sp.csr_matrix((v, (r, c)), shape=(len(rows), self.ndof))

    def curvature(self) -> sp.csr_matrix:
        """``sum_k A_k lambda_k grad^2 g_k`` on the segments' DOFs."""
        r, c, v = [], [], []
        for k in np.flatnonzero(self.lam != 0):
            _, dofs = self._local(int(k))
            block = self.weights[k] * self.lam[k] * self._hessian(int(k))
            r += list(np.repeat(dofs, len(dofs)))
            c += list(np.tile(dofs, len(dofs)))
            v += list(block.ravel())
        return sp.csr_matrix((v, (r, c)), shape=(self.ndof, self.ndof))

    def active(self, c: float) -> np.ndarray:
        return self.lam - c * self.g >= 0

    def complementarity(self, c: float) -> np.ndarray:
        """``A_k C_k / c`` [volume], as :meth:`PointContact.complementarity`."""
        return self.weights * (self.lam - np.maximum(0.0, self.lam - c * self.g)) / c

    def release(self) -> int:
        """Edge points are never released (they are the skull's)."""
        return 0

    def max_penetration(self, points: np.ndarray | None = None) -> float:
        """Largest depth ``max(-g, 0)`` of an edge point inside the tissue [length]."""
        self.update(self.form.gfu.vec.FV().NumPy())
        g = self.g if points is None else self.g[points]
        return float(max(np.max(-g, initial=0.0), 0.0)) + 0.0

    def free_measure(self, tol: float) -> float:
        """Edge points free no boundary."""
        return 0.0

    def fields(self) -> tuple[ngs.CoefficientFunction, ngs.CoefficientFunction]:
        """No boundary field of its own (the edge points are not tissue vertices): zeros."""
        return ngs.CF(0.0), ngs.CF(0.0)

    def pressure(self) -> np.ndarray:
        """Contact pressure at the edge points [stress]."""
        return self.lam.copy()


def _inner_points(mesh: ngs.Mesh, rx: re.Pattern) -> np.ndarray:
    """For each boundary segment matching ``rx`` (in mesh order), the centroid of the
    triangle it bounds (n, 2)."""
    names = mesh.GetBoundaries()
    X = np.array([v.point for v in mesh.vertices])[:, :2]
    owner: dict[tuple[int, int], int] = {}
    els = [[v.nr for v in el.vertices] for el in mesh.Elements(ngs.VOL)]
    for e, vs in enumerate(els):
        for i in range(3):
            key = tuple(sorted((vs[i], vs[(i + 1) % 3])))
            owner[key] = e
    out = []
    for el in mesh.Elements(ngs.BND):
        if rx.match(names[el.index]):
            key = tuple(sorted(v.nr for v in el.vertices))
            out.append(X[els[owner[key]]].mean(axis=0))
    return np.array(out)


def _right_normal(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    t = b - a
    return np.array([t[1], -t[0]]) / float(np.hypot(t[0], t[1]))


#: the force along the interpolated normal at the projection held fixed (its derivative
#: leaves out d xi / d z: continuous across a vertex, where the exact one jumps)
FROZEN_PROJECTION = False


class _Dual:
    """A value with its gradient (forward-mode differentiation of :func:`smooth_gap`)."""

    __slots__ = ("v", "d")

    def __init__(self, v: float, d: np.ndarray) -> None:
        self.v, self.d = v, d

    def _lift(self, o):
        return o if isinstance(o, _Dual) else _Dual(float(o), np.zeros_like(self.d))

    def __add__(self, o):
        o = self._lift(o)
        return _Dual(self.v + o.v, self.d + o.d)

    __radd__ = __add__

    def __sub__(self, o):
        o = self._lift(o)
        return _Dual(self.v - o.v, self.d - o.d)

    def __rsub__(self, o):
        return self._lift(o) - self

    def __mul__(self, o):
        o = self._lift(o)
        return _Dual(self.v * o.v, self.d * o.v + o.d * self.v)

    __rmul__ = __mul__

    def __neg__(self):
        return _Dual(-self.v, -self.d)

    def __truediv__(self, o):
        o = self._lift(o)
        return _Dual(self.v / o.v, (self.d * o.v - o.d * self.v) / o.v**2)


def _sqrt(x):
    if isinstance(x, _Dual):
        r = float(np.sqrt(x.v))
        return _Dual(r, x.d / (2 * r))
    return float(np.sqrt(x))


def _normalized(v):
    n = _sqrt(v[0] * v[0] + v[1] * v[1])
    return [v[0] / n, v[1] / n]


def _vertex_normals(z):
    """Unit normals ``N_a``, ``N_b`` at the ends of ``a -> b`` of ``z = (p, a, b, q)``, each
    the normalized sum of its two segments' right unit normals (the segment's own at an
    end of the boundary)."""
    p, a, b, q = z[0:2], z[2:4], z[4:6], z[6:8]

    def rn(u, w):  # right unit normal of u -> w
        return _normalized([w[1] - u[1], u[0] - w[0]])

    n_ab = rn(a, b)
    end_a = float(_val(p[0])) == float(_val(a[0])) and float(_val(p[1])) == float(_val(a[1]))
    end_b = float(_val(q[0])) == float(_val(b[0])) and float(_val(q[1])) == float(_val(b[1]))
    Na = n_ab if end_a else _normalized([m + k for m, k in zip(rn(p, a), n_ab, strict=True)])
    Nb = n_ab if end_b else _normalized([m + k for m, k in zip(n_ab, rn(b, q), strict=True)])
    return Na, Nb


def _gap_terms(C, z, xi, blend: float = 0.0):
    """``f = (C - x(xi)) x n(xi)`` (zero at the projection) and ``g = (C - x) . n / |n|``
    for positions ``z`` (8 values or duals) and ``xi``; with ``blend > 0``, ``g`` turns
    smoothly into the vertex gap ``(C - x_v) . N_v`` within ``blend`` of a vertex ``v``
    (parameter distance; weight ``s(t) = 3 t^2 - 2 t^3``, ``t`` = distance / ``blend``)."""
    a, b = z[2:4], z[4:6]
    Na, Nb = _vertex_normals(z)
    x = [a[i] + xi * (b[i] - a[i]) for i in range(2)]
    w = [C[i] - x[i] for i in range(2)]
    n = [(1 - xi) * Na[i] + xi * Nb[i] for i in range(2)]
    f = w[0] * n[1] - w[1] * n[0]
    g = (w[0] * n[0] + w[1] * n[1]) / _sqrt(n[0] * n[0] + n[1] * n[1])
    if blend > 0:
        near_a = _val(xi) < 0.5
        if min(_val(xi), 1 - _val(xi)) < blend:
            v, N = (a, Na) if near_a else (b, Nb)
            t = (xi if near_a else 1 - xi) / blend
            s = t * t * (3 - 2 * t)
            g_v = (C[0] - v[0]) * N[0] + (C[1] - v[1]) * N[1]
            g = s * g + (1 - s) * g_v
    return f, g


def _val(x) -> float:
    return x.v if isinstance(x, _Dual) else x


def _projection(C: np.ndarray, z: np.ndarray) -> float | None:
    """``xi`` in [0, 1] where ``C - x(xi)`` is parallel to the interpolated normal (bisection),
    None when there is none."""
    lo, hi = 0.0, 1.0
    f_lo, f_hi = _gap_terms(C, z, lo)[0], _gap_terms(C, z, hi)[0]
    if f_lo * f_hi > 0:
        return None
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        f_mid = _gap_terms(C, z, mid)[0]
        if f_lo * f_mid <= 0:
            hi = mid
        else:
            lo, f_lo = mid, f_mid
    return 0.5 * (lo + hi)


def smooth_gap(C: np.ndarray, z: np.ndarray, blend: float = 0.0) -> float | None:
    """Gap of ``C`` along the boundary's interpolated normal on the segment ``a -> b``,
    ``z = (p, a, b, q)`` (8,) with ``p``, ``q`` the neighbouring vertices: vertex normals
    ``N_a``, ``N_b`` averaged from the adjacent segments, ``n(xi) = (1 - xi) N_a + xi N_b``,
    and ``xi`` where ``C - x(xi)`` is parallel to ``n(xi)``. None when no ``xi`` in [0, 1].
    ``blend``: the vertex gap near the vertices (:func:`_gap_terms`)."""
    xi = _projection(C, z)
    return None if xi is None else float(_gap_terms(C, z, xi, blend)[1])


def smooth_gap_gradient(C: np.ndarray, z: np.ndarray, blend: float = 0.0
                        ) -> np.ndarray | None:
    """Exact ``d g / d z`` (8,) of :func:`smooth_gap` (implicit in ``xi``: ``dg/dz = g_z -
    g_xi f_z / f_xi``), or None when ``C`` does not project onto the segment."""
    xi = _projection(C, z)
    if xi is None:
        return None
    eye = np.eye(9)
    zd = [_Dual(float(z[i]), eye[i]) for i in range(8)]
    f, g = _gap_terms(C, zd, _Dual(xi, eye[8]), blend)
    if FROZEN_PROJECTION:
        return g.d[:8]
    return g.d[:8] - g.d[8] * f.d[:8] / f.d[8]


class SmoothEdgeContact(EdgeContact):
    """:class:`EdgeContact` against a C1 boundary (:func:`smooth_gap`): the gap and its
    normal do not jump when the edge point passes a vertex of the tissue's boundary."""

    #: parameter distance from a vertex within which the gap turns into the vertex gap
    #: (:func:`_gap_terms`); 0: none
    blend = 0.0

    def __init__(self, form, boundary: str, points: np.ndarray) -> None:
        super().__init__(form, boundary, points)
        self.next_of = {int(a): int(b) for a, b in self.segments}
        self.prev_of = {int(b): int(a) for a, b in self.segments}

    def _quad(self, s: int) -> np.ndarray:
        a, b = (int(v) for v in self.segments[s])
        return np.array([self.prev_of.get(a, a), a, b, self.next_of.get(b, b)])

    def update(self, x: np.ndarray) -> None:
        super().update(x)  # positions, and the plain gap as the fallback
        if not hasattr(self, "next_of"):
            return
        mids = 0.5 * (self.pos[self.segments[:, 0]] + self.pos[self.segments[:, 1]])
        for k, C in enumerate(self.C):
            near = np.argsort(np.linalg.norm(mids - C, axis=1))[:8]
            best = None
            for s in near:
                g = smooth_gap(C, self.pos[self._quad(int(s))].ravel(), self.blend)
                if g is not None and (best is None or abs(g) < abs(best[0])):
                    best = (g, int(s))
            if best is not None:
                self.g[k], self.seg[k] = best

    def _grad_at(self, k: int, z: np.ndarray) -> np.ndarray:
        grad = smooth_gap_gradient(self.C[k], z, self.blend)
        return np.zeros(8) if grad is None else grad

    def _local(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        quad = self._quad(int(self.seg[k]))
        grad = self._grad_at(k, self.pos[quad].ravel())
        return grad, self.vertex_dofs[quad].ravel()

    def _hessian(self, k: int) -> np.ndarray:
        quad = self._quad(int(self.seg[k]))
        z = self.pos[quad].ravel()
        delta = 1e-6 * float(np.linalg.norm(z[4:6] - z[2:4]))
        H = np.empty((8, 8))
        for j in range(8):
            e = np.zeros(8)
            e[j] = delta
            H[:, j] = (self._grad_at(k, z + e) - self._grad_at(k, z - e)) / (2 * delta)
        return 0.5 * (H + H.T)


class VertexEdgeContact(SmoothEdgeContact):
    """:class:`SmoothEdgeContact` whose gap, within ``blend`` (parameter distance) of a
    boundary vertex ``v``, turns smoothly into the vertex gap ``(C - x_v) . N_v`` (the edge
    point against the tangent line at ``v``): the gap's gradient is then the same from the
    two segments that share ``v``, where the interpolated normal's projection makes it
    jump."""

    blend = 0.2

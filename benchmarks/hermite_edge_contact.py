"""The skull's edge points against cubic Hermite segments through the tissue boundary's
vertices (C1 positions too): the ``edge-hermite`` variant of the hard-case benchmark
(:mod:`bench_hard_cases`), beside :mod:`edge_contact`'s interpolated-normal boundary."""

from __future__ import annotations

import numpy as np

from edge_contact import EdgeContact, SmoothEdgeContact, _Dual, _normalized, _sqrt, _vertex_normals


def _hermite(z, xi):
    """Point and tangent of the cubic Hermite segment ``a -> b`` of ``z = (p, a, b, q)``
    whose end tangents are perpendicular to the averaged vertex normals (a C1 boundary
    through the vertices), with length ``|b - a|``."""
    a, b = z[2:4], z[4:6]
    dx, dy = b[0] - a[0], b[1] - a[1]
    L = _sqrt(dx * dx + dy * dy)
    Na, Nb = _vertex_normals(z)  # the unit tangents are the normals turned left
    Ta, Tb = [-Na[1], Na[0]], [-Nb[1], Nb[0]]
    h00, h10 = 2 * xi**3 - 3 * xi**2 + 1, xi**3 - 2 * xi**2 + xi
    h01, h11 = -2 * xi**3 + 3 * xi**2, xi**3 - xi**2
    d00, d10 = 6 * xi**2 - 6 * xi, 3 * xi**2 - 4 * xi + 1
    d01, d11 = -6 * xi**2 + 6 * xi, 3 * xi**2 - 2 * xi
    x = [h00 * a[i] + h10 * L * Ta[i] + h01 * b[i] + h11 * L * Tb[i] for i in range(2)]
    t = [d00 * a[i] + d10 * L * Ta[i] + d01 * b[i] + d11 * L * Tb[i] for i in range(2)]
    return x, t


def _hermite_gap(C, z, xi):
    """``(C - x(xi)) . n(xi)``, ``n`` the curve's right unit normal (outward)."""
    x, t = _hermite(z, xi)
    n = _normalized([t[1], -t[0]])
    return (C[0] - x[0]) * n[0] + (C[1] - x[1]) * n[1]


def hermite_closest(C: np.ndarray, z: np.ndarray) -> tuple[float, float]:
    """``(distance, xi)`` of the point of the Hermite segment closest to ``C``."""
    xs = np.linspace(0.0, 1.0, 9)
    d = [np.hypot(*(C - np.array(_hermite(z, s)[0]))) for s in xs]
    k = int(np.argmin(d))
    lo, hi = xs[max(k - 1, 0)], xs[min(k + 1, 8)]
    phi = (np.sqrt(5) - 1) / 2
    for _ in range(50):  # golden section on the squared distance
        m1, m2 = hi - phi * (hi - lo), lo + phi * (hi - lo)
        f1 = np.sum((C - np.array(_hermite(z, m1)[0])) ** 2)
        f2 = np.sum((C - np.array(_hermite(z, m2)[0])) ** 2)
        if f1 < f2:
            hi = m2
        else:
            lo = m1
    xi = 0.5 * (lo + hi)
    return float(np.hypot(*(C - np.array(_hermite(z, xi)[0])))), xi


class HermiteEdgeContact(SmoothEdgeContact):
    """:class:`EdgeContact` against a C1 boundary of cubic Hermite segments through the mesh
    vertices, by closest-point projection: the gap's gradient with respect to the nodes is
    the partial derivative at the fixed projection (exact, as the projection is stationary)
    and continuous where the projection passes a vertex."""

    def update(self, x: np.ndarray) -> None:
        EdgeContact.update(self, x)
        if not hasattr(self, "next_of"):
            return
        mids = 0.5 * (self.pos[self.segments[:, 0]] + self.pos[self.segments[:, 1]])
        self.xi_h = np.zeros(self.n_points)
        for k, C in enumerate(self.C):
            best = None
            for s in np.argsort(np.linalg.norm(mids - C, axis=1))[:8]:
                z = self.pos[self._quad(int(s))].ravel()
                dist, xi = hermite_closest(C, z)
                if best is None or dist < best[0]:
                    best = (dist, int(s), xi)
            _, s, xi = best
            self.seg[k], self.xi_h[k] = s, xi
            self.g[k] = float(_hermite_gap(C, self.pos[self._quad(s)].ravel(), xi))

    def _grad_at(self, k: int, z: np.ndarray, xi: float | None = None) -> np.ndarray:
        eye = np.eye(8)
        zd = [_Dual(float(z[i]), eye[i]) for i in range(8)]
        xi = float(self.xi_h[k]) if xi is None else xi
        return _hermite_gap(self.C[k], zd, xi).d

    def _hessian(self, k: int) -> np.ndarray:
        """Central differences of the gradient, the projection solved again at each side
        (so that its motion along the curve counts)."""
        z = self.pos[self._quad(int(self.seg[k]))].ravel()
        delta = 1e-6 * float(np.linalg.norm(z[4:6] - z[2:4]))
        H = np.empty((8, 8))
        for j in range(8):
            e = np.zeros(8)
            e[j] = delta
            gp = self._grad_at(k, z + e, hermite_closest(self.C[k], z + e)[1])
            gm = self._grad_at(k, z - e, hermite_closest(self.C[k], z - e)[1])
            H[:, j] = (gp - gm) / (2 * delta)
        return 0.5 * (H + H.T)

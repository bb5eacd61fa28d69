"""Rezoning's geometry (2D): a new reference mesh through the current deformation
(:mod:`brainbulge.geometry.rezone`)."""

from __future__ import annotations

import ngsolve as ngs
import numpy as np
import pytest

from brainbulge.geometry.hemidisk import Hemidisk
from brainbulge.geometry.rezone import deformed_quality, rezone, topology, triangle_quality


def _map(X: np.ndarray) -> np.ndarray:
    """A quadratic displacement (exact in P2) that shears the top of the hemidisk."""
    return np.stack([0.3 * X[:, 1] ** 2, 0.2 * X[:, 0] * X[:, 1]], axis=1)


@pytest.fixture(scope="module")
def rezoned():
    geo = Hemidisk(alpha_deg=80, beta_deg=30)
    mesh = geo.mesh(0.1)
    u = ngs.GridFunction(ngs.VectorH1(mesh, order=2))
    u.Set(ngs.CF((0.3 * ngs.y**2, 0.2 * ngs.x * ngs.y)))
    return geo, mesh, u, rezone(mesh, u, geo.project, 0.1, 0.02, geo.singular_points())


def test_rezoned_mesh_keeps_domain_regions_and_boundaries(rezoned) -> None:
    geo, mesh, _, rz = rezoned
    new = rz.mesh
    assert set(new.GetMaterials()) == set(mesh.GetMaterials())
    assert {"skull", "opening", "base"} <= set(new.GetBoundaries())
    for region in set(mesh.GetMaterials()):
        a_old = ngs.Integrate(ngs.CF(1), mesh, definedon=mesh.Materials(region))
        a_new = ngs.Integrate(ngs.CF(1), new, definedon=new.Materials(region))
        # the new mesh is straight-sided: the arc loses its chord segments, h^2/(8R) deep
        assert a_new == pytest.approx(a_old, rel=3e-3)
    X = np.array([v.point for v in new.vertices])
    names = new.GetBoundaries()
    for el in new.Elements(ngs.BND):
        P = X[[v.nr for v in el.vertices]]
        if names[el.index] in ("skull", "opening"):
            np.testing.assert_allclose(np.linalg.norm(P, axis=1), 1.0, atol=1e-12)
        elif names[el.index] == "base":
            np.testing.assert_allclose(P[:, 1], 0.0, atol=1e-12)
    # the sector edges stay on their radial lines
    s_lo, s_hi = np.radians(geo.sector_angles_deg)
    top = topology(new)
    sw = top.regions.index("swelling")
    for tri in top.tris[top.region == sw]:
        ang = np.arctan2(top.X[tri, 1], top.X[tri, 0])
        r = np.linalg.norm(top.X[tri], axis=1)
        assert np.all((ang >= s_lo - 1e-9) & (ang <= s_hi + 1e-9) | (r < 1e-12))


def test_pull_back_inverts_the_deformation(rezoned) -> None:
    """Interior vertices: ``X + u(X) = x`` solved to the interpolation error of the map
    (exact in P2 but for the curved elements at the arc); the image of the new mesh is better
    shaped than the image of the old one."""
    _, mesh, u, rz = rezoned
    top = topology(rz.mesh)
    exact = _map(top.X)
    on_boundary = {v.nr for el in rz.mesh.Elements(ngs.BND) for v in el.vertices}
    inner = np.array(sorted(set(range(len(top.X))) - on_boundary))
    np.testing.assert_allclose(rz.u_vertices[inner], exact[inner], atol=2e-5)
    # on the curved boundary only up to the chord error of the deformed polyline
    assert np.abs(rz.u_vertices - exact).max() < 0.01
    q_old = deformed_quality(mesh, u).min()
    q_new = triangle_quality(top.X + rz.u_vertices, top.tris).min()
    assert q_new > q_old


def test_rezoned_mesh_keeps_the_rim_refinement(rezoned) -> None:
    """Reference points given as ``rim_points`` (the edge-exclusion circles) are refined to
    ``h_rim`` at their images in the deformed domain, which the new mesh is made in."""
    geo, mesh, u, rz = rezoned
    rim = geo.rim_points(0.05, 0.005)
    fine = rezone(mesh, u, geo.project, 0.1, 0.02, geo.singular_points(), rim, 0.005)
    x_rim = rim + _map(rim)

    def median_edge_near_rim(r) -> float:
        top = topology(r.mesh)
        x = top.X + r.u_vertices  # the deformed vertices, where the mesh was made
        d = np.min(np.linalg.norm(x[:, None] - x_rim[None], axis=2), axis=1)
        P = x[top.tris[np.any(d[top.tris] < 0.003, axis=1)]]
        longest = np.max([np.linalg.norm(P[:, i] - P[:, (i + 1) % 3], axis=1)
                          for i in range(3)], axis=0)
        return float(np.median(longest))

    assert median_edge_near_rim(fine) < 2 * 0.005
    assert median_edge_near_rim(rz) > 3 * 0.005

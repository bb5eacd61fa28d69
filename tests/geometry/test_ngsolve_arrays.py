"""The NumPy views of an NGSolve mesh agree with NGSolve's per-entity API."""

import ngsolve as ngs
import numpy as np
import pytest
from netgen.csg import unit_cube
from netgen.geom2d import SplineGeometry

from brainbulge.geometry.ngsolve_arrays import (
    element_corners,
    element_vertices,
    vertex_coordinates,
    vertex_dofs,
)


def _two_region_square() -> ngs.Mesh:
    g = SplineGeometry()
    g.AddRectangle((0, 0), (1, 1), leftdomain=1, rightdomain=0)
    g.AddRectangle((0.3, 0.3), (0.7, 0.6), leftdomain=2, rightdomain=1)
    g.SetMaterial(1, "outer")
    g.SetMaterial(2, "inner")
    return ngs.Mesh(g.GenerateMesh(maxh=0.1))


MESHES = {"tet": lambda: ngs.Mesh(unit_cube.GenerateMesh(maxh=0.3)), "trig": _two_region_square}


@pytest.fixture(params=list(MESHES))
def mesh(request) -> ngs.Mesh:
    return MESHES[request.param]()


def test_vertices_and_elements_match_the_entity_loops(mesh):
    X = np.array([v.point for v in mesh.vertices])[:, : mesh.dim]
    els = np.array([[v.nr for v in el.vertices] for el in mesh.Elements(ngs.VOL)])
    regions = np.array([el.index for el in mesh.Elements(ngs.VOL)])
    got_els, got_regions = element_vertices(mesh)
    np.testing.assert_array_equal(vertex_coordinates(mesh), X)
    np.testing.assert_array_equal(got_els, els)
    np.testing.assert_array_equal(got_regions, regions)


def _spaces(mesh: ngs.Mesh) -> list[ngs.FESpace]:
    mini = ngs.VectorH1(mesh, order=1)
    mini.SetOrder(ngs.TET if mesh.dim == 3 else ngs.TRIG, 4 if mesh.dim == 3 else 3)
    mini.Update()
    return [ngs.H1(mesh, order=1), ngs.H1(mesh, order=2, dirichlet=".*"),
            ngs.VectorH1(mesh, order=1), ngs.VectorH1(mesh, order=2), mini]


def test_vertex_dofs_match_get_dof_nrs(mesh):
    for V in _spaces(mesh):
        expected = np.array([V.GetDofNrs(ngs.NodeId(ngs.VERTEX, v)) for v in range(mesh.nv)])
        np.testing.assert_array_equal(vertex_dofs(V, mesh), expected.reshape(mesh.nv, -1))


def test_vertex_dofs_of_a_space_on_some_regions():
    mesh = _two_region_square()
    els, regions = element_vertices(mesh)
    for name in ("outer", "inner"):
        Q = ngs.H1(mesh, order=1, definedon=mesh.Materials(name))
        on = np.array(mesh.Materials(name).Mask(), dtype=bool)[regions]
        verts = np.unique(els[on])
        dofs = vertex_dofs(Q, mesh, on)[:, 0]
        expected = [Q.GetDofNrs(ngs.NodeId(ngs.VERTEX, int(v)))[0] for v in verts]
        np.testing.assert_array_equal(dofs[verts], expected)
        off = np.setdiff1d(np.arange(mesh.nv), verts)
        assert len(off) > 0 and np.all(dofs[off] == -1)


def test_element_corners_are_the_element_vertices_in_order(mesh):
    """Corner k of element e is vertex ``element_vertices(mesh)[0][e, k]``."""
    xyz = ngs.CF((ngs.x, ngs.y, ngs.z)[: mesh.dim])
    at_corners = np.asarray(xyz(element_corners(mesh))).reshape(-1, mesh.dim + 1, mesh.dim)
    els, _ = element_vertices(mesh)
    np.testing.assert_allclose(at_corners, vertex_coordinates(mesh)[els], atol=1e-14)

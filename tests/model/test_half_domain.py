"""A case symmetric about the axis is solved on its half ``x >= 0`` (``u_x = 0`` on the axis)
and reported for the whole hemidisk: the mesh, the mirror images of the outputs, and one
run against the full domain."""

from __future__ import annotations

import math

import meshio
import ngsolve as ngs
import numpy as np
import pytest

from brainbulge.errors import InputError
from brainbulge.geometry.hemidisk import Hemidisk
from brainbulge.geometry.ngsolve_arrays import vertex_coordinates
from brainbulge.model.hemidisk import HemidiskCase, hemidisk_problem
from brainbulge.results.export.writers import VertexFields
from brainbulge.studies.hemidisk import run_hemidisk


def test_half_mesh_covers_x_positive_with_the_axis_a_boundary() -> None:
    """The half mesh: area pi R^2 / 4, every vertex at ``x >= 0``, the axis ``x = 0`` the
    boundary ``symmetry``; an opening off the axis cannot be halved."""
    geo = Hemidisk(alpha_deg=80, beta_deg=60, half=True)
    mesh = geo.mesh(0.1)
    assert ngs.Integrate(1, mesh) == pytest.approx(math.pi / 4, rel=1e-6)
    X = vertex_coordinates(mesh)
    assert X[:, 0].min() > -1e-12
    names = mesh.GetBoundaries()
    on_axis = {v.nr for el in mesh.Elements(ngs.BND) if names[el.index] == "symmetry"
               for v in el.vertices}
    assert len(on_axis) >= 1 / 0.1 and np.abs(X[sorted(on_axis), 0]).max() < 1e-12
    assert all(p[0] >= 0 for p in geo.singular_points())
    assert len(geo.singular_points()) == 3  # one opening corner, one sector edge, the centre
    with pytest.raises(InputError, match="symmetric"):
        Hemidisk(alpha_deg=80, beta_deg=60, opening_center_deg=60, half=True)


def test_the_case_chooses_the_half_domain_when_symmetric() -> None:
    """Half by default for a sector under a centred opening; full for an off-axis opening,
    a disk, or ``full_domain``; the half problem holds ``u_x = 0`` on the axis."""
    assert HemidiskCase().half
    assert not HemidiskCase(opening_center=60).half
    assert not HemidiskCase(disk=[0.2, 0.5, 0.15]).half
    assert not HemidiskCase(full_domain=True).half
    problem = hemidisk_problem(HemidiskCase(mesh_size=0.3, skull_edge_radius=0.0))
    assert problem.clamped_components == {0: "symmetry"}
    with pytest.raises(InputError, match="full_domain"):
        HemidiskCase(full_domain="yes")  # type: ignore[arg-type]


def test_mirrored_vertex_fields() -> None:
    """The mirror image of two triangles on the axis: the axis's vertices shared, the
    images' x and u_x reversed, the scalars kept, every triangle counter-clockwise."""
    points = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0]])
    cells = np.array([[0, 1, 2], [1, 3, 2]])
    u = np.array([[0.0, 0.1], [0.2, 0.3], [0.0, 0.4], [0.5, 0.6]])
    vf = VertexFields(points, cells, np.zeros(2, dtype=int), ["tissue"],
                      {"u": u, "J": np.arange(4.0)}, {"u": u[:2], "J": np.ones(2)},
                      {"J": np.arange(6.0).reshape(2, 3)})
    m = vf.mirrored()
    assert len(m.points) == 6 and len(m.cells) == 4
    np.testing.assert_array_equal(m.points[4:], [[-1.0, 0.0], [-1.0, 1.0]])
    np.testing.assert_array_equal(m.point_data["u"][4:], [[-0.2, 0.3], [-0.5, 0.6]])
    np.testing.assert_array_equal(m.point_data["J"], [0, 1, 2, 3, 1, 3])
    np.testing.assert_array_equal(m.cell_data["u"][2:], [[0.0, 0.1], [-0.2, 0.3]])
    a, b, c = (m.points[m.cells[:, k]] for k in range(3))
    area = (b - a)[:, 0] * (c - a)[:, 1] - (b - a)[:, 1] * (c - a)[:, 0]
    assert np.all(area > 0)
    # each corner value stays with its vertex: the image cell's corners in its own order
    for e in range(2):
        for k in range(3):
            vertex = m.cells[2 + e, k]
            same = np.flatnonzero(cells[e] == np.flatnonzero(
                np.all(points == m.points[vertex] * [-1, 1], axis=1))[0])[0]
            assert m.corner_data["J"][2 + e, k] == vf.corner_data["J"][e, same]


def test_half_run_reports_the_whole_hemidisk(tmp_path) -> None:
    """One run on the half and the full domain (the sharp edge, MINI, coarse): the summary's
    area integrals and extremes are the whole hemidisk's, the written mesh the whole
    hemidisk (mirrored), and the displacement and stretches agree to the discretisation
    error of the two meshes."""
    common = {"alpha": 80.0, "beta": 60.0, "contact": "noslip", "mesh_size": 0.1,
              "skull_edge_radius": 0.0, "element": "mini", "steps": 2}
    half = run_hemidisk(common, tmp_path / "half")
    full = run_hemidisk({**common, "full_domain": True}, tmp_path / "full")
    assert half["converged"] and full["converged"]
    assert half["dofs"] < 0.6 * full["dofs"]
    expected = math.pi / 2 * half["swelling_area_ratio_expected"]  # alpha/pi (Js-1) pi/2
    assert half["swelling_volume"] == pytest.approx(expected, rel=1e-3)
    assert full["swelling_volume"] == pytest.approx(expected, rel=1e-3)
    assert half["singular_points"] == full["singular_points"]
    for key in ("max_displacement", "p95_principal_strain", "p05_radial_stretch",
                "p95_tangential_stretch"):
        assert half[key] == pytest.approx(full[key], rel=0.01), key
    for key in ("max_radial_stretch", "max_tangential_stretch", "min_radial_stretch"):
        assert half[key] == pytest.approx(full[key], rel=0.05), key  # on the rims: h 0.1
    vtu = meshio.read(tmp_path / "half" / "fields.vtu")
    assert vtu.points[:, 0].min() == pytest.approx(-1.0) and vtu.points[:, 0].max() == 1.0
    u = vtu.point_data["u"]
    left = vtu.points[:, 0] < -0.5
    assert np.all(np.abs(u[left, 0]) <= np.abs(u[:, 0]).max())
    assert abs(u[:, 0].sum()) < 1e-9 * np.abs(u[:, 0]).sum()  # the mirror's u_x cancels
    assert half["boundary_self_crossings"] == 0 == full["boundary_self_crossings"]


@pytest.mark.parametrize("block", [256, 1])
def test_boundary_self_crossings_counts_a_fold(block, monkeypatch) -> None:
    """A square's boundary does not cross itself; moved into a bow tie, two of its sides
    cross once; chords with a common vertex do not count; the count does not depend on
    how many chords are tested at a time."""
    from brainbulge.results.measures import folds
    from brainbulge.results.measures.folds import boundary_self_crossings, outer_edges

    monkeypatch.setattr(folds, "BLOCK", block)

    pts = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    cells = np.array([[0, 1, 2], [0, 2, 3]])
    assert sorted(map(tuple, outer_edges(cells))) == [(0, 1), (0, 3), (1, 2), (2, 3)]
    assert boundary_self_crossings(pts, cells, np.zeros((4, 2))) == 0
    bow_tie = np.array([[0.0, 0.0], [0.0, 0.0], [-1.0, 0.0], [1.0, 0.0]])
    assert boundary_self_crossings(pts, cells, bow_tie) == 1

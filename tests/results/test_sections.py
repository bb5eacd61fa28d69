"""Plane sections of tet meshes: exact areas, outlines and linear fields; the section PNG."""

from __future__ import annotations

import matplotlib.image as mpimg
import numpy as np
import pytest
from scipy.spatial import Delaunay

from brainbulge.results.present.sections import plot_sections, section_triangles
from simple_meshes import box_mesh


def linear(x: np.ndarray) -> np.ndarray:
    return 1.0 + 2.0 * x[:, 0] - 3.0 * x[:, 1] + 0.5 * x[:, 2]


def perimeter(sec) -> float:
    e = sec.boundary_edges()
    return float(np.linalg.norm(sec.points[e[:, 0]] - sec.points[e[:, 1]], axis=1).sum())


@pytest.mark.parametrize("z", [0.5, 0.37, 0.0, 1.0])
def test_cube_section_area_outline_and_linear_field(z: float) -> None:
    """z = 0.5, 0, 1 hit mesh nodes and faces in the plane: each face counts once."""
    nodes, tets = box_mesh(4, 0.0, 1.0)
    sec = section_triangles(nodes, tets, linear(nodes), (0.3, 0.3, z), (0, 0, 1))
    expected = 0.0 if z == 1.0 else 1.0  # the top face has no tet above it
    assert sec.area() == pytest.approx(expected)
    if expected:
        assert sec.points[:, 2] == pytest.approx(z)
        assert sec.values == pytest.approx(linear(sec.points))
        assert perimeter(sec) == pytest.approx(4.0)
        assert len(sec.points) == len(np.unique(sec.points.round(12), axis=0))  # shared


def test_oblique_section_of_a_cube_is_the_regular_hexagon() -> None:
    nodes, tets = box_mesh(5, 0.0, 1.0)
    values = np.column_stack([linear(nodes), nodes])  # (n, k) values
    sec = section_triangles(nodes, tets, values, (0.5, 0.5, 0.5), (1, 1, 1))
    assert sec.area() == pytest.approx(3 * np.sqrt(3) / 4)  # hexagon of side sqrt(2)/2
    assert perimeter(sec) == pytest.approx(6 * np.sqrt(2) / 2)
    assert sec.values[:, 0] == pytest.approx(linear(sec.points))
    assert sec.values[:, 1:] == pytest.approx(sec.points)
    assert np.all(np.isin(sec.tet, np.arange(len(tets))))


def test_section_of_a_random_delaunay_mesh() -> None:
    rng = np.random.default_rng(0)
    corners = np.array(np.meshgrid([0, 1], [0, 1], [0, 1])).reshape(3, -1).T
    nodes = np.concatenate([corners, rng.random((3000, 3))])
    tets = Delaunay(nodes).simplices
    sec = section_triangles(nodes, tets, linear(nodes), (0.5, 0.5, 0.41), (0, 0, -2))
    assert sec.area() == pytest.approx(1.0)
    assert sec.values == pytest.approx(linear(sec.points))
    assert perimeter(sec) == pytest.approx(4.0)
    miss = section_triangles(nodes, tets, linear(nodes), (0, 0, 2.0), (0, 0, 1))
    assert len(miss.triangles) == 0 and miss.area() == 0.0


def test_plot_sections_writes_a_coloured_png(tmp_path) -> None:
    nodes, tets = box_mesh(6, -30.0, 30.0)
    r = np.linalg.norm(nodes, axis=1)
    u = 0.1 * nodes * np.exp(-(r / 30) ** 2)[:, None]
    fields = {"|u|": np.linalg.norm(u, axis=1), "lambda_n": 1 + 0.05 * nodes[:, 0] / 30}
    path = plot_sections(nodes, tets, u, fields, np.zeros(3), tmp_path / "sections.png",
                         ranges={"|u|": (0.0, 3.0)}, title="test")
    assert path.exists() and path.stat().st_size > 10_000
    img = mpimg.imread(path)[..., :3]
    saturation = img.max(axis=2) - img.min(axis=2)
    assert (saturation > 0.3).mean() > 0.05  # coloured pixels, not just axes


def test_plot_fields_marks_the_failure_site(tmp_path, saved_figures) -> None:
    """A stopped run's ``failure_site`` is a red cross at that position on every panel."""
    import brainbulge.results.present.figures as figures
    from brainbulge.results.export.writers import VertexFields

    pts = np.array([[-1.0, 0.0], [1.0, 0.0], [0.0, 1.0], [0.5, 0.5]])
    vals = np.array([0.9, 1.0, 1.1, 1.2])
    vf = VertexFields(pts, np.array([[0, 1, 3], [0, 3, 2]]), np.zeros(2, dtype=int), ["a"],
                      {"u": np.zeros((4, 2)), "lambda_n": vals, "lambda_t": vals}, {})
    figures.plot_fields(vf, tmp_path / "f.png", fields=("lambda_n", "lambda_t"),
                        mark=(0.25, 0.4))
    assert (tmp_path / "f.png").is_file() and len(saved_figures) == 1
    panels = [ax for ax in saved_figures[0].axes if ax.lines]  # (not the colour bars)
    assert len(panels) == 2
    for ax in panels:
        crosses = [ln for ln in ax.lines if ln.get_marker() == "x"]
        assert len(crosses) == 1
        np.testing.assert_allclose(crosses[0].get_xydata(), [[0.25, 0.4]])

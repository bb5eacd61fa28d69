"""The rim band's refinement (benchmarks/rim_band.py) on the toy brain: conforming, volumes
kept, the band's size reached, and the refined mesh read back as the CLI reads it."""

from pathlib import Path

import numpy as np
import pytest

import rim_band as rb
from brainbulge.geometry.brain import load_brain_mesh, save_brain_mesh
from brainbulge.geometry.brain.refine import TET_EDGES


@pytest.fixture(scope="module")
def toy(tmp_path_factory):
    from toy_brain import toy_mesh

    return toy_mesh(tmp_path_factory.mktemp("toy"))


def _longest(nodes: np.ndarray, tets: np.ndarray) -> np.ndarray:
    p = nodes[tets]
    return np.linalg.norm(p[:, TET_EDGES[:, 1]] - p[:, TET_EDGES[:, 0]], axis=2).max(axis=1)


def test_bisection_is_conforming_keeps_volumes_and_reaches_the_size(toy):
    d = rb.rim_distance(toy, "custom")
    h, band = 3.0, 6.0
    nodes, tets, parent = rb.refine_band(toy.nodes_mm, toy.tets, d, rb.graded_size(h, band, 1.0))
    assert len(tets) > 2 * len(toy.tets)
    assert set(np.unique(rb.face_counts(tets))) == {1, 2}  # no hanging face
    v0, v1 = toy.tet_volumes_mm3(), rb.tet_volumes_mm3(nodes, tets)
    assert v1.min() > 0
    np.testing.assert_allclose(np.bincount(parent, v1), v0, rtol=1e-10)
    for code in np.unique(toy.tissue):
        assert v1[toy.tissue[parent] == code].sum() == pytest.approx(
            v0[toy.tissue == code].sum(), rel=1e-12)
    in_band = d(nodes[tets].mean(axis=1)) < band
    assert in_band.sum() > 50 and _longest(nodes, tets)[in_band].max() <= h
    # the old nodes first, in their order; the new ones at midpoints of the old surface
    np.testing.assert_array_equal(nodes[:len(toy.nodes_mm)], toy.nodes_mm)


def test_the_band_mesh_is_read_back_with_its_boundaries(toy, tmp_path: Path):
    bm, info = rb.band_mesh(toy, "custom", rho_mm=6.0, band_rho=1.0, rho_per_h=2.0,
                            grading=1.0)
    assert info["faces_shared_by"].keys() == {"1", "2"}
    area = info["outer_area_mm2"]
    assert area[1] == pytest.approx(area[0], rel=1e-12)  # before the surface move
    assert all(abs(v) < 1e-9 * 1e6 for v in info["tissue_volume_change_mm3"].values())
    assert info["band_longest_edge_max_unmoved_mm"] <= 3.0  # the surface move bends a little
    assert info["quality"]["inverted_tets"] == 0
    save_brain_mesh(bm, tmp_path, flap="custom", figures=False)
    back = load_brain_mesh(tmp_path / "brain.npz")
    assert len(back.tets) == info["tets_after"]
    names = set(back.boundary_names("custom"))
    assert {"base", "skull", "flap"} <= names
    # the refined opening covers the same nominal area as the template's, to its faces' size
    assert back.flap_area_cm2("custom") == pytest.approx(toy.flap_area_cm2("custom"), rel=0.1)

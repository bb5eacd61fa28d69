"""Tissue interfaces fitted to the smoothed label surfaces (geometry/brain/interfaces.py).

A white-matter sphere (R = 20 mm) in a gray-matter ellipsoid, 1 mm voxels: the tagged
staircase overstates the sphere's area ~1.55x and tilts its faces ~45 deg from the radial
direction; fitted, the area is within a few per cent, the tilt ~10-17 deg, the nodes on
the sphere to about a millimetre, the volumes those of the voxels, no tet inverted.
"""

from __future__ import annotations

import numpy as np
import pytest

from bench_interfaces import sphere_image, sphere_metrics, tagged_mesh  # benchmarks/ on the path
from brainbulge.geometry.brain.interfaces import (
    face_neighbours,
    fit_interfaces,
    remove_teeth,
    tissue_level_sets,
)
from brainbulge.geometry.brain.labels import GRAY, WHITE
from brainbulge.geometry.brain.quality import quality_stats, tet_volumes_mm3


@pytest.fixture(scope="module")
def sphere_case():
    image = sphere_image()
    nodes, tets, tissue, icv = tagged_mesh(image, 50_000)
    fitted = fit_interfaces(nodes, tets, tissue, image, intracranial_volume_ml=icv)
    return image, (nodes, tets, tissue), fitted


def test_level_set_is_a_distance_to_the_sphere() -> None:
    image = sphere_image()
    ls = tissue_level_sets(image, np.array([GRAY, WHITE]))
    rng = np.random.default_rng(0)
    d = rng.normal(size=(500, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    # the zero level on the sphere to a tenth of a voxel (the voxelised sphere's flat caps:
    # up to 0.4); 4 mm off it a distance to ~10 % (voxel-centre distances to an oblique
    # boundary run up to ~0.4 voxel long)
    on = np.abs(ls.sample(WHITE, 20.0 * d))
    assert np.median(on) < 0.1 and on.max() < 0.4
    for r in (16.0, 24.0):
        assert np.abs(ls.sample(WHITE, r * d) - (r - 20.0)).max() < 0.5
    grad = ls.gradient(WHITE, 20.0 * d)
    assert np.abs(np.einsum("ij,ij->i", grad, d) - 1.0).max() < 0.2  # slope 0.87-1.0


def test_teeth_take_the_neighbours_tag() -> None:
    # two tets sharing face (1, 2, 3): each the other's only neighbour
    tets = np.array([[0, 1, 2, 3], [1, 2, 3, 4]])
    nb = face_neighbours(tets)
    assert (nb[0] >= 0).sum() == 1 and nb[0, 0] == 1 and nb[1, 3] == 0
    # a tet with fewer than 4 neighbours (on the outer surface) is never flipped
    assert np.array_equal(remove_teeth(np.array([1, 2]), nb), [1, 2])
    # a tet whose four neighbours are gray is a tooth (neighbour table given directly)
    nb4 = np.array([[1, 2, 3, 4], [0, -1, -1, -1], [0, -1, -1, -1], [0, -1, -1, -1],
                    [0, -1, -1, -1]])
    assert remove_teeth(np.array([2, 1, 1, 1, 3]), nb4)[0] == 1
    assert remove_teeth(np.array([2, 1, 2, 2, 3]), nb4)[0] == 2  # 2 of 4 differ: stays
    assert remove_teeth(np.array([2, 1, 3, 1, 1]), nb4)[0] == 1  # the majority of 4


def test_sphere_interface_is_fitted(sphere_case) -> None:
    _, (nodes, tets, tissue), (x, tag) = sphere_case
    before = sphere_metrics(nodes, tets, tissue)
    after = sphere_metrics(x, tets, tag)
    assert before["area_ratio"] > 1.4 and before["tilt_deg"] > 35  # the staircase
    assert after["area_ratio"] == pytest.approx(1.0, abs=0.05)
    assert after["tilt_deg"] < 15.0
    assert after["dist_p95_mm"] < 1.0 and after["dist_max_mm"] < 2.0
    assert after["white_volume_ratio"] == pytest.approx(1.0, abs=0.015)


def test_fitting_keeps_volumes_quality_and_the_outer_surface(sphere_case) -> None:
    image, (nodes, tets, tissue), (x, tag) = sphere_case
    vol = np.abs(np.linalg.det(image.affine[:3, :3]))
    for code in (GRAY, WHITE):
        voxel = (image.tissue == code).sum() * vol
        mesh = tet_volumes_mm3(x, tets)[tag == code].sum()
        assert mesh == pytest.approx(voxel, rel=0.01)
    q = quality_stats(x, tets)
    assert q["inverted_tets"] == 0 and q["min_dihedral_deg"] >= 10.0 - 1e-9
    t, f = np.nonzero(face_neighbours(tets) < 0)
    outer = np.unique(tets[t[:, None], np.array([[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]])[f]])
    assert np.array_equal(x[outer], nodes[outer])
    moved = np.linalg.norm(x - nodes, axis=1)
    assert moved.max() < 5.0 and (moved > 0).sum() > 100

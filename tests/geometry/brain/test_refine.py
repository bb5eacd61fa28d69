"""Uniform tetrahedral refinement (brainbulge.geometry.brain.refine)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import Delaunay

from brainbulge.geometry.brain.boundaries import boundary_faces, faces_once
from brainbulge.geometry.brain.quality import dihedral_angles_deg, tet_volumes_mm3
from brainbulge.geometry.brain.refine import move_onto_surface, refine_uniformly

R = 10.0  # mm


@pytest.fixture(scope="module")
def ball() -> tuple[np.ndarray, np.ndarray]:
    """Delaunay tets of points in a ball of radius R, with its surface sampled on the sphere."""
    rng = np.random.default_rng(3)
    d = rng.normal(size=(300, 3))
    surface = R * d / np.linalg.norm(d, axis=1)[:, None]
    inner = rng.uniform(-0.6 * R, 0.6 * R, size=(200, 3))
    nodes = np.concatenate([surface, inner])
    tets = Delaunay(nodes).simplices.astype(np.int64)
    vol = tet_volumes_mm3(nodes, tets)
    tets = tets[np.abs(vol) > 1e-6]
    vol = tet_volumes_mm3(nodes, tets)
    tets[vol < 0] = tets[vol < 0][:, [0, 2, 1, 3]]
    return nodes, tets


def sphere(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    r = np.linalg.norm(x, axis=1)
    return r - R, x / r[:, None]


def test_eight_children_fill_their_parent_conformingly(ball) -> None:
    nodes, tets = ball
    fine_nodes, fine_tets, parent, edges = refine_uniformly(nodes, tets)
    assert len(fine_tets) == 8 * len(tets)
    assert np.array_equal(fine_nodes[: len(nodes)], nodes)  # nested: old nodes first
    assert np.allclose(fine_nodes[len(nodes):], nodes[edges].mean(axis=1))
    vol = tet_volumes_mm3(fine_nodes, fine_tets)
    assert vol.min() > 0
    assert np.allclose(np.bincount(parent, vol), tet_volumes_mm3(nodes, tets))
    # conforming: every inner face shared by two tets, each surface face cut into four
    assert len(boundary_faces(fine_tets)[0]) == 4 * len(boundary_faces(tets)[0])
    # every child lies in its parent (its centroid has positive barycentric coordinates)
    c = fine_nodes[fine_tets].mean(axis=1)
    p = nodes[tets[parent]]
    T = np.stack([p[:, 1] - p[:, 0], p[:, 2] - p[:, 0], p[:, 3] - p[:, 0]], axis=2)
    lam = np.linalg.solve(T, (c - p[:, 0])[..., None])[..., 0]
    assert lam.min() > 0 and (1 - lam.sum(axis=1)).min() > 0


def test_quality_does_not_decay_with_repeated_refinement(ball) -> None:
    """Shortest-diagonal red refinement: the worst angle after two refinements is that of
    the first (the children fall into a few similarity classes)."""
    nodes, tets = ball
    n1, t1, _, _ = refine_uniformly(nodes, tets)
    n2, t2, _, _ = refine_uniformly(n1, t1)
    a0, a1, a2 = (dihedral_angles_deg(n, t).min() for n, t in ((nodes, tets), (n1, t1), (n2, t2)))
    assert a1 > 0.4 * a0
    assert a2 == pytest.approx(a1, rel=1e-6)


def test_p1_functions_are_nested(ball) -> None:
    """A coarse P1 function interpolated at the new nodes (edge midpoints: the mean of the
    two end values) equals the coarse function at every fine point, e.g. the centroids."""
    nodes, tets = ball
    f = np.random.default_rng(0).normal(size=len(nodes))
    fine_nodes, fine_tets, parent, edges = refine_uniformly(nodes, tets)
    f_fine = np.concatenate([f, f[edges].mean(axis=1)])
    c = fine_nodes[fine_tets].mean(axis=1)
    p = nodes[tets[parent]]
    T = np.stack([p[:, 1] - p[:, 0], p[:, 2] - p[:, 0], p[:, 3] - p[:, 0]], axis=2)
    lam = np.linalg.solve(T, (c - p[:, 0])[..., None])[..., 0]
    bary = np.column_stack([1 - lam.sum(axis=1), lam])
    coarse_at_c = np.einsum("ij,ij->i", bary, f[tets[parent]])
    assert np.allclose(f_fine[fine_tets].mean(axis=1), coarse_at_c)


def test_new_surface_nodes_move_onto_the_surface(ball) -> None:
    nodes, tets = ball
    fine_nodes, fine_tets, _, _ = refine_uniformly(nodes, tets)
    surface = np.unique(boundary_faces(fine_tets)[0])
    new = surface[surface >= len(nodes)]
    before = np.abs(np.linalg.norm(fine_nodes[new], axis=1) - R)
    assert before.max() > 0.1  # chord midpoints lie inside the sphere
    moved, stayed = move_onto_surface(fine_nodes, fine_tets, new, sphere)
    gap = np.abs(np.linalg.norm(moved[new], axis=1) - R)
    assert stayed == 0 and gap.max() < 1e-9
    assert tet_volumes_mm3(moved, fine_tets).min() > 0
    others = np.setdiff1d(np.arange(len(fine_nodes)), new)
    assert np.array_equal(moved[others], fine_nodes[others])
    # the refined ball's volume approaches the sphere's: closer than the chorded one
    exact = 4 / 3 * np.pi * R**3
    assert abs(tet_volumes_mm3(moved, fine_tets).sum() - exact) < 0.5 * abs(
        tet_volumes_mm3(nodes, tets).sum() - exact)


def test_a_move_that_would_flatten_a_tet_is_not_made(ball) -> None:
    """A surface at 'infinite' distance would pull the nodes through their tets: they stay."""
    nodes, tets = ball
    fine_nodes, fine_tets, _, _ = refine_uniformly(nodes, tets)
    surface = np.unique(boundary_faces(fine_tets)[0])
    new = surface[surface >= len(nodes)]

    def far(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:  # pulls every node 50 mm in
        phi, grad = sphere(x)
        return phi + 50.0, grad

    moved, stayed = move_onto_surface(fine_nodes, fine_tets, new, far)
    assert stayed == len(new)
    assert np.array_equal(moved, fine_nodes)


def test_boundary_faces_of_a_ball_close_its_surface(ball) -> None:
    """Every edge of the boundary faces is shared by exactly two of them (a closed surface),
    and :func:`faces_once` agrees with counting rows by ``np.unique`` on all faces, in
    whatever vertex order a face is listed."""
    nodes, tets = ball
    faces, owner = boundary_faces(tets)
    edges = np.sort(faces[:, [[0, 1], [1, 2], [2, 0]]].reshape(-1, 2), axis=1)
    assert (np.unique(edges, axis=0, return_counts=True)[1] == 2).all()
    assert np.isin(faces, tets[owner]).all()
    every = tets[:, [[0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3]]].reshape(-1, 3)
    every = np.random.default_rng(0).permuted(every, axis=1)
    _, inverse, counts = np.unique(np.sort(every, axis=1), axis=0, return_inverse=True,
                                   return_counts=True)
    assert (faces_once(every) == (counts[inverse.ravel()] == 1)).all()
    assert faces_once(every).sum() == len(faces)

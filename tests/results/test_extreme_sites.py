"""Where the 3D extremes are (``extreme_sites``) and the extremes of element values, on
fields with known answers (the solved toy brain: test_brain_outputs.py)."""

from __future__ import annotations

import numpy as np
import pytest

from brainbulge.results.measures.extreme_sites import SiteContext, element_fields
from simple_meshes import box_mesh


def _context(nodes, tets, regions, swelling):
    return SiteContext(nodes, tets, regions, swelling,
                       rim_distance=lambda X: np.abs(X[:, 0] - 10.0),
                       under_flap=lambda X: X[:, 2] > 5.0,
                       depth=lambda X: 10.0 - X[:, 2])


def test_element_values_of_an_affine_map_are_its_stretches() -> None:
    """u = A X: every element has F = I + A; along x (radial from a centre far out on -x)
    lambda_n = |F e_x|, and a uniform stretch s gives strain (s^2 - 1)/2 everywhere."""
    nodes, tets = box_mesh(3, 0.0, 3.0)
    A = np.array([[0.2, 0.1, 0.0], [0.0, -0.1, 0.0], [0.0, 0.0, 0.05]])
    centre = np.array([-1e7, 1.5, 1.5])
    f = element_fields(nodes, tets, nodes @ A.T, centre)
    F = np.eye(3) + A
    assert f["lambda_n"] == pytest.approx(np.linalg.norm(F[:, 0]), rel=1e-5)
    C = F.T @ F
    assert f["lambda_t"] == pytest.approx(np.sqrt(np.linalg.eigvalsh(C[1:, 1:]).max()), rel=1e-5)
    uni = element_fields(nodes, tets, 0.2 * nodes, centre)
    assert uni["max_principal_strain"] == pytest.approx(0.5 * (1.2**2 - 1), rel=1e-9)


def test_sites_say_region_interface_and_distances() -> None:
    nodes, tets = box_mesh(4, 0.0, 10.0)
    centroids = nodes[tets].mean(axis=1)
    regions = np.where(centroids[:, 0] < 5.0, "white_left", "gray_left")
    ctx = _context(nodes, tets, regions, regions == "white_left")
    inside_white = np.array([[1.0, 1.2, 8.3]])
    far_gray = np.array([[9.6, 9.1, 1.4]])
    (a, b) = ctx.describe(np.vstack([inside_white, far_gray]))
    assert a["region"] == "white_left" and not a["at_interface"]
    assert a["swelling_distance_mm"] == 0.0
    assert a["under_flap"] and a["depth_mm"] == pytest.approx(1.7)
    assert a["rim_distance_mm"] == pytest.approx(9.0)
    assert b["region"] == "gray_left" and not b["under_flap"]
    assert b["swelling_distance_mm"] > 4.0  # the nearest white centroid is > 5 mm in x away
    at = ctx.describe(np.array([[5.1, 4.0, 4.0]]))[0]  # next to the x = 5 interface
    assert at["region"] == "gray_left" and at["at_interface"]
    # the interface nodes lie on x = 5 (2.5 mm apart in y and z)
    assert at["interface_distance_mm"] < 1.9 and a["interface_distance_mm"] > 3.9
    # the containing tet, not just the nearest centroid
    t = ctx.containing_tets(centroids[[3, 40, 200]] + 1e-3)
    assert list(t) == [3, 40, 200]

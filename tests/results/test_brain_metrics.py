"""Clinical metrics of the 3D brain on tet meshes with prescribed displacements."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import Delaunay

from brainbulge.geometry.brain import MidSagittalPlane
from brainbulge.results.measures.brain_metrics import (
    MonroLocation,
    brain_volume_ml,
    bulge_volume_ml,
    monro_midline_shift_mm,
    positive_fraction,
    prescribed_swelling_volume_ml,
    swelling_volume_ml,
)
from simple_meshes import box_mesh


def ball_mesh(R: float, h: float) -> tuple[np.ndarray, np.ndarray]:
    """Delaunay tets of a lattice inside a ball and Fibonacci points on its sphere."""
    g = np.arange(-R, R + h / 2, h)
    lattice = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3)
    lattice = lattice[np.linalg.norm(lattice, axis=1) < R - 0.5 * h]
    n_s = int(4 * np.pi * R**2 / h**2 * 1.5)
    k = np.arange(n_s) + 0.5
    z = 1 - 2 * k / n_s
    th = np.pi * (1 + 5**0.5) * k
    r = np.sqrt(1 - z**2)
    sphere = R * np.stack([r * np.cos(th), r * np.sin(th), z], axis=1)
    nodes = np.concatenate([lattice, sphere])
    return nodes, Delaunay(nodes).simplices


def test_positive_fraction_closed_forms() -> None:
    f = np.array([[1, 1, 1, 1], [-1, -1, -1, -1], [1, 1, -1, -1], [1, -1, -1, -1],
                  [1, 1, 1, -1], [1, 0, 0, 0], [2.0, 2.0, -3.0, -3.0]])
    # one vertex above at 1, three at -1: the corner tet to the midpoints, (1/2)^3
    expected = [1, 0, 0.5, 0.125, 0.875, 1, None]
    got = positive_fraction(f)
    assert got[:6] == pytest.approx(expected[:6])
    # equal values (no division by their difference): crossing at 2/5 of each edge
    # the positive part is the tet minus the wedge; check against Monte Carlo
    lam = np.random.default_rng(0).dirichlet(np.ones(4), 200_000)
    assert got[6] == pytest.approx(((lam @ f[6]) > 0).mean(), abs=3e-3)


WHOLE = (40.0, 40.0)  # a window over the whole test box


def test_midline_shift_of_a_translation_is_signed() -> None:
    nodes, tets = box_mesh(6, -30.0, 30.0)
    plane = MidSagittalPlane((0.0, 0.0, 0.0), (1.0, 0.0, 0.0))
    centre = MonroLocation((0.0, 0.0, 0.0), "template")
    for d in (2.5, -1.5):
        u = np.zeros_like(nodes)
        u[:, 0] = d
        out = monro_midline_shift_mm(nodes, tets, u, plane, centre, window_mm=WHOLE)
        assert out["midline_shift_mm"] == pytest.approx(d)
        assert out["midline_shift_samples"] == 61 * 61  # the plane's 1 mm grid in the box
        assert out["midline_shift_point_mm"][0] == pytest.approx(0.0)
    # a plane normal that points left reports the same motion with the opposite sign
    left = MidSagittalPlane((0.0, 0.0, 0.0), (-2.0, 0.0, 0.0))
    out = monro_midline_shift_mm(nodes, tets, u, left, centre, window_mm=WHOLE)
    assert out["midline_shift_mm"] == pytest.approx(1.5)


def test_midline_shift_selects_tissue_and_window() -> None:
    """Interpolated at points of the plane (not at nodes near it): a displacement off the
    plane enters only through the tets the plane cuts; the window and the tissue mask choose
    where the largest ``|u . n|`` is looked for."""
    nodes, tets = box_mesh(6, -30.0, 30.0)  # nodes every 10 mm
    plane = MidSagittalPlane((0.0, 0.0, 0.0), (1.0, 0.0, 0.0))
    centre = MonroLocation((0.0, 0.0, 0.0), "template")
    u = np.zeros_like(nodes)
    u[:, 0] = 0.1 * nodes[:, 2] - 0.05 * nodes[:, 1]  # largest at z = 30, y = -30
    out = monro_midline_shift_mm(nodes, tets, u, plane, centre, window_mm=WHOLE)
    assert out["midline_shift_mm"] == pytest.approx(4.5)
    assert out["midline_shift_point_mm"] == pytest.approx([0.0, -30.0, 30.0])
    out = monro_midline_shift_mm(nodes, tets, u, plane, centre, window_mm=(40.0, 15.0))
    assert out["midline_shift_mm"] == pytest.approx(3.0)  # z = 15, y = -30
    y_positive = nodes[tets].mean(axis=1)[:, 1] > 0
    out = monro_midline_shift_mm(nodes, tets, u, plane, centre, window_mm=WHOLE,
                                 tissue_tets=y_positive)
    assert out["midline_shift_mm"] == pytest.approx(-4.5)  # z = -30, y = 30
    assert out["midline_shift_point_mm"] == pytest.approx([0.0, 30.0, -30.0])
    far = MonroLocation((0.0, 0.0, 200.0), "template")
    assert monro_midline_shift_mm(nodes, tets, u, plane, far)["midline_shift_samples"] == 0


def test_brain_and_swelling_volumes() -> None:
    nodes, tets = box_mesh(4, 0.0, 100.0)
    tets[::3] = tets[::3][:, [1, 0, 2, 3]]  # mixed orientation must not matter
    assert brain_volume_ml(nodes, tets) == pytest.approx(1000.0)
    stretch = 1.05
    u = (stretch - 1) * (nodes - 50.0)
    assert brain_volume_ml(nodes, tets, u) == pytest.approx(1000.0 * stretch**3)
    centroid = nodes[tets].mean(axis=1)
    mask = centroid[:, 0] < 50.0
    assert swelling_volume_ml(nodes, tets, u, mask) == pytest.approx(500.0 * (stretch**3 - 1))
    js = np.where(mask, stretch**3, 1.0)
    assert prescribed_swelling_volume_ml(nodes, tets, js) == pytest.approx(
        swelling_volume_ml(nodes, tets, u, mask))


def test_bulge_volume_through_a_plane_is_exact() -> None:
    """phi affine: the linear interpolation is exact, at any order."""
    nodes, tets = box_mesh(3, 0.0, 30.0)
    u = np.zeros_like(nodes)
    u[:, 0] = 4.0  # 4 mm x 30 x 30 mm beyond x = 30
    for order in (1, 2):
        vol = bulge_volume_ml(nodes, tets, u, lambda x: x[:, 0] - 30.0, order=order)
        assert vol == pytest.approx(4.0 * 30 * 30 / 1000, rel=1e-10)
    assert bulge_volume_ml(nodes, tets, 0 * u, lambda x: x[:, 0] - 30.0) == 0.0


def test_bulge_volume_of_a_sphere_converges_with_order() -> None:
    """Indicator of a ball of radius 10 inside a cube mesh (h = 3): exact geometry, so the
    error is that of the rule only; it falls like (h / order)^2."""
    nodes, tets = box_mesh(10, -15.0, 15.0)
    R = 10.0
    exact = 4 / 3 * np.pi * R**3 / 1000
    errors = []
    for order in (1, 2, 4):
        vol = bulge_volume_ml(nodes, tets, 0 * nodes, lambda x: R - np.linalg.norm(x, axis=1),
                              order=order)
        errors.append(abs(vol / exact - 1))
    assert errors[0] < 0.05  # measured 0.045, 0.011, 0.0028
    assert errors[1] < errors[0] / 3.5
    assert errors[2] < errors[1] / 3.5


def test_bulge_volume_of_a_translated_ball_is_the_lens_complement() -> None:
    """A ball of radius R moved by s out of a skull sphere of radius R: the volume outside is
    the ball minus the lens 'pi (4R + s)(2R - s)^2 / 12'."""
    R, s = 40.0, 8.0
    nodes, tets = ball_mesh(R, 5.0)
    u = np.zeros_like(nodes)
    u[:, 0] = s
    exact = (4 / 3 * np.pi * R**3 - np.pi * (4 * R + s) * (2 * R - s) ** 2 / 12) / 1000
    vol = bulge_volume_ml(nodes, tets, u, lambda x: np.linalg.norm(x, axis=1) - R, order=2)
    assert vol == pytest.approx(exact, rel=0.02)
    all_tets = bulge_volume_ml(nodes, tets, u, lambda x: np.linalg.norm(x, axis=1) - R,
                               order=2, margin_mm=np.inf)
    assert vol == pytest.approx(all_tets, rel=1e-12)  # the margin drops only inner tets

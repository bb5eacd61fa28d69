"""Recovered gradients (results/measures/recovery.py): exact on linear fields, convergent on smooth
ones, discontinuous across regions."""

from __future__ import annotations

import ngsolve as ngs
import numpy as np
import pytest

from brainbulge.results.measures.quadrature import quadrature_points
from brainbulge.results.measures.recovery import recovered_gradient
from conftest import unit_box_mesh


def _p1(mesh: ngs.Mesh, cf: ngs.CoefficientFunction) -> ngs.GridFunction:
    gf = ngs.GridFunction(ngs.VectorH1(mesh, order=1))
    gf.Set(cf)
    return gf


def test_a_linear_displacement_is_recovered_exactly() -> None:
    mesh = unit_box_mesh(3, h=0.4)
    u = _p1(mesh, ngs.CF((0.1 * ngs.x + 0.2 * ngs.y, -0.3 * ngs.z, 0.05 * ngs.x + ngs.z)))
    G = recovered_gradient(mesh, u)
    q = quadrature_points(mesh, order=2)
    got = np.asarray(G(q.points)).reshape(-1, 3, 3)
    expected = np.array([[0.1, 0.2, 0.0], [0.0, 0.0, -0.3], [0.05, 0.0, 1.0]])
    assert np.abs(got - expected).max() < 1e-10


def _errors(h: float) -> tuple[float, float]:
    """Volume-RMS error of the raw and the recovered gradient of the P1 interpolant of a
    smooth field, against the exact gradient."""
    mesh = unit_box_mesh(3, h=h)
    exact = ngs.CF((ngs.sin(2 * ngs.x) * ngs.y, ngs.exp(ngs.z) * ngs.x, ngs.cos(ngs.y + ngs.z)))
    u = _p1(mesh, exact)
    G = recovered_gradient(mesh, u)
    gx = ngs.CF((2 * ngs.cos(2 * ngs.x) * ngs.y, ngs.sin(2 * ngs.x), 0,
                 ngs.exp(ngs.z), 0, ngs.exp(ngs.z) * ngs.x,
                 0, -ngs.sin(ngs.y + ngs.z), -ngs.sin(ngs.y + ngs.z)), dims=(3, 3))
    raw = ngs.sqrt(ngs.Integrate(ngs.InnerProduct(ngs.Grad(u) - gx, ngs.Grad(u) - gx), mesh))
    rec = ngs.sqrt(ngs.Integrate(ngs.InnerProduct(G - gx, G - gx), mesh))
    return float(raw), float(rec)


def test_the_recovered_gradient_converges_faster_than_the_raw_one() -> None:
    """Halving h: the raw P1 gradient's error halves (order 1), the recovered one's falls
    faster and is smaller on each mesh."""
    raw_c, rec_c = _errors(0.3)
    raw_f, rec_f = _errors(0.15)
    assert rec_c < raw_c and rec_f < raw_f
    assert raw_c / raw_f == pytest.approx(2.0, rel=0.3)
    assert rec_c / rec_f > 2.4


def test_a_jump_between_regions_is_kept() -> None:
    """Two bonded regions with different gradients (a kink at x = 0.5): per region, both
    gradients are recovered exactly; one global projection smears them."""
    from netgen.occ import Box, Glue, OCCGeometry

    left, right = Box((0, 0, 0), (0.5, 1, 1)), Box((0.5, 0, 0), (1, 1, 1))
    left.mat("a")
    right.mat("b")
    mesh = ngs.Mesh(OCCGeometry(Glue([left, right])).GenerateMesh(maxh=0.3))
    ux = ngs.IfPos(ngs.x - 0.5, 0.3 * (ngs.x - 0.5), 0.1 * (ngs.x - 0.5))
    u = _p1(mesh, ngs.CF((ux, 0, 0)))
    q = quadrature_points(mesh, order=2)
    a = np.asarray(q(mesh.MaterialCF({"a": 1.0}, default=0.0))) > 0.5
    per_region = np.asarray(recovered_gradient(mesh, u)(q.points)).reshape(-1, 3, 3)[:, 0, 0]
    assert per_region[a] == pytest.approx(0.1, abs=1e-10)
    assert per_region[~a] == pytest.approx(0.3, abs=1e-10)
    smeared = np.asarray(recovered_gradient(mesh, u, per_region=False)(q.points))
    assert np.abs(smeared.reshape(-1, 3, 3)[:, 0, 0] - np.where(a, 0.1, 0.3)).max() > 0.05

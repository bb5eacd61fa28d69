"""A swelling incompressible inclusion in an incompressible matrix (docs/model.md section 8).

Incompressibility alone fixes the radial map: in plane strain ``r^2 = R^2 + (Js - 1) A^2``
outside the disk and ``r = sqrt(Js) R`` inside; for a sphere ``r^3 = R^3 + (Js - 1) A^3`` and
``r = Js^(1/3) R`` inside with ``Fe = I``. The traction-free outer boundary keeps the radial
symmetry, so the map is exact in the bounded domain too.
"""

from __future__ import annotations

import ngsolve as ngs
import numpy as np
import pytest

from brainbulge.geometry.inclusion import inclusion_mesh
from brainbulge.materials import MooneyRivlin
from brainbulge.model import Problem
from brainbulge.results.measures.fields import output_fields, sample
from brainbulge.results.measures.quadrature import quadrature_points
from brainbulge.solver import SolverOptions, solve

GRAY = MooneyRivlin(0.28, 333.0)
JS = 1.3
A = 0.1


def _solve(dim: int, h: float, element: str = "taylor-hood", h_inclusion: float = A / 4):
    mesh = inclusion_mesh(dim, A=A, h=h, h_inclusion=h_inclusion)
    problem = Problem(
        mesh,
        {"inclusion": GRAY, "matrix": GRAY},
        {"inclusion": JS},
        clamped_components={0: "sym_x", 1: "sym_y", 2: "sym_z"},
    )
    sol = solve(problem, element, SolverOptions(steps=3))
    assert sol.converged
    return mesh, sol


def _radius_errors(mesh, sol, dim: int, radii) -> float:
    rng = np.random.default_rng(0)
    worst = 0.0
    for R in radii:
        for _ in range(6):
            d = np.abs(rng.standard_normal(dim)) + 0.2
            d /= np.linalg.norm(d)
            X = R * d
            u = np.asarray(sol.form.u(mesh(*X)))
            r = np.linalg.norm(X + u)
            exact = (R**dim + (JS - 1) * A**dim) ** (1 / dim) if R >= A else JS ** (1 / dim) * R
            worst = max(worst, abs(r - exact) / exact)
    return worst


@pytest.mark.parametrize("dim,h", [(2, 0.1), (3, 0.25)])
def test_inclusion_radial_map(dim: int, h: float) -> None:
    mesh, sol = _solve(dim, h)
    err = _radius_errors(mesh, sol, dim, radii=[0.05, 0.15, 0.3, 0.6])
    assert err < 0.01, f"radius error {err:.2%}"


def test_inclusion_interface_stretches_2d() -> None:
    """On the matrix side of the interface: hoop sqrt(1.3) = 1.140, radial 1/sqrt(1.3)."""
    mesh, sol = _solve(2, 0.1, h_inclusion=A / 10)
    X = np.array([[A * 1.05 * np.cos(t), A * 1.02 * np.sin(t)] for t in (0.3, 0.8, 1.2)])
    pts = [mesh(*x) for x in X]
    from brainbulge.results.measures.fields import Samples

    F = np.tile(np.eye(3), (3, 1, 1))
    F[:, :2, :2] += np.array([np.asarray(ngs.Grad(sol.form.u)(p)).reshape(2, 2) for p in pts])
    s = Samples(X, np.zeros_like(X), F, np.zeros(3), np.ones(3))
    f = output_fields(s, centre=np.zeros(2))
    hoop_exact = np.sqrt(1 + (JS - 1) * A**2 / np.sum(X**2, axis=1))
    np.testing.assert_allclose(f["lambda_t"], hoop_exact, rtol=0.01)
    np.testing.assert_allclose(f["lambda_n"], 1 / hoop_exact, rtol=0.01)
    # at the interface itself (R = A) the exact hoop stretch is sqrt(Js) = 1.140
    assert np.sqrt(1 + (JS - 1)) == pytest.approx(1.140, abs=5e-4)


@pytest.mark.parametrize("dim,h", [(2, 0.1), (3, 0.3)])
def test_constraint_J_equals_Js(dim: int, h: float) -> None:
    """The multiplier enforces ``J = Js``: globally to round-off (the pressure space holds
    constants) and pointwise to discretisation accuracy."""
    mesh, sol = _solve(dim, h)
    form = sol.form
    J = ngs.Det(form.F())
    integral = abs(ngs.Integrate(J - form.Js_current(), mesh, order=6))
    total_swelling = ngs.Integrate(form.Js_current() - 1, mesh)
    assert integral < 1e-8 * total_swelling
    q = quadrature_points(mesh, order=4)
    s = sample(form, q.points)
    J_pts = np.linalg.det(s.F)
    pointwise = np.max(np.abs(J_pts - s.Js))
    assert pointwise < 0.05  # the pointwise error is not zero for P2/P1, but small
    matrix = s.Js == 1.0
    assert np.median(np.abs(J_pts[matrix] - 1)) < 1e-3

"""Contact with obstacles known only on point arrays (the 3D skull), docs/model.md sections 6 and 8.

- derivatives: the constraint rows and the curvature term are the derivatives of the gaps
  and of the contact forces, against a plane and a sphere;
- a swelling sphere in an incompressible ball that slides inside a rigid spherical skull with
  polar openings: away from the openings the exact radial map ``r^3 = R^3 + (Js - 1) A^3``;
  penetration below tolerance; contact forces normal while the surface slides;
- a closed skull is infeasible.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from brainbulge.errors import InfeasibleError
from brainbulge.geometry.sphere_skull import SphericalSkull
from brainbulge.model import Problem
from brainbulge.model.problem import Contact
from brainbulge.solver import NewtonSolver, SolverOptions
from brainbulge.solver.mixed import MixedForm
from conftest import unit_box_mesh
from contact_cases import GRAY, JS, A, _capped_ball


@dataclass
class Plane:
    """Half-space ``n . x > c`` is free; the rigid body lies below the plane."""

    normal: tuple[float, ...]
    c: float

    def gap_and_normal(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        n = np.asarray(self.normal) / np.linalg.norm(self.normal)
        return x @ n - self.c, np.broadcast_to(n, x.shape).copy()


def _contact_form(obstacle, element: str = "mini") -> MixedForm:
    mesh = unit_box_mesh(3, h=0.5)
    problem = Problem(mesh, {"tissue": GRAY}, {"tissue": 1.1}, contacts=[Contact("xmin", obstacle)])
    return MixedForm(problem, element=element)


CURVED = SphericalSkull(R=1.2, cap_deg=20, thickness=0.3, edge_radius=0.1)
CURVED_OFFSET = np.array([1.0, 0.5, 0.5])


@dataclass
class Shifted:
    """An obstacle moved by ``offset``."""

    obstacle: object
    offset: np.ndarray

    def gap_and_normal(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return self.obstacle.gap_and_normal(x - self.offset)


@pytest.mark.parametrize(
    "element,obstacle,spread",
    [
        ("mini", Plane((1.0, 0.2, 0.1), 0.02), 0.05),
        ("taylor-hood", Plane((1.0, 0.2, 0.1), 0.02), 0.05),
        ("mini", Shifted(CURVED, CURVED_OFFSET), 0.05),  # the xmin face inside a curved skull
        # P2 edge-midpoint points on the curved skull (the Taylor-Hood brain baseline); with
        # a spread of 0.05 one point lands 0.075 deep, where the closest core point jumps
        ("taylor-hood", Shifted(CURVED, CURVED_OFFSET), 0.02),
    ],
)
def test_point_contact_derivatives(element: str, obstacle, spread: float) -> None:
    """At fixed multipliers (pushing and pulling), d(contact forces)/dx is the curvature
    term and the constraint rows ``B`` are the derivative of the weighted gaps ``A g``."""
    rng = np.random.default_rng(1)
    form = _contact_form(obstacle, element)
    pc = form.point_contacts[0]
    # some multipliers negative: a Newton step leaves pulling points behind (released by
    # the next one), and their forces turn with the normal too
    pc.lam = rng.uniform(-5, 10, pc.n_points)
    assert (pc.lam < 0).any()
    x0 = spread * rng.standard_normal(form.fes.ndof)
    dx = rng.standard_normal(form.fes.ndof)
    pc.update(x0)
    Kc = -pc.curvature()
    B = pc.B(np.arange(pc.n_points))
    eps = 1e-6

    def forces(x):
        pc.update(x)
        r = np.zeros(form.fes.ndof)
        pc.add_forces(r)
        return r

    def weighted_gap(x):
        pc.update(x)
        return pc.weights * pc.g

    dR = (forces(x0 + eps * dx) - forces(x0 - eps * dx)) / (2 * eps)
    scale = np.linalg.norm(dR) + 1e-3 * np.linalg.norm(forces(x0))
    assert np.linalg.norm(dR - Kc @ dx) < 1e-5 * scale
    dg = (weighted_gap(x0 + eps * dx) - weighted_gap(x0 - eps * dx)) / (2 * eps)
    assert np.linalg.norm(dg - B @ dx) < 1e-6 * np.linalg.norm(dg)


@pytest.fixture(scope="module")
def capped_sphere():
    mesh, problem = _capped_ball(h=0.15, h_inclusion=A / 3, cap_deg=35)
    form = MixedForm(problem, element="mini")
    solver = NewtonSolver(form, SolverOptions(steps=2))
    sol = solver.solve()
    return mesh, form, solver, sol


def test_capped_sphere_radial_map(capped_sphere) -> None:
    mesh, form, _, sol = capped_sphere
    assert sol.converged
    rng = np.random.default_rng(0)
    worst = 0.0
    for R in (0.1, 0.25, 0.35, 0.5):
        for _ in range(6):
            d = np.abs(rng.standard_normal(3)) + 0.2
            d[2] *= 0.3  # away from the polar openings
            d /= np.linalg.norm(d)
            X = R * d
            r = np.linalg.norm(X + np.asarray(form.u(mesh(*X))))
            exact = (R**3 + (JS - 1) * A**3) ** (1 / 3) if R >= A else JS ** (1 / 3) * R
            worst = max(worst, abs(r - exact) / exact)
    assert worst < 0.01, f"radius error {worst:.2%}"


def test_capped_sphere_contact(capped_sphere) -> None:
    _, form, solver, sol = capped_sphere
    pc = form.point_contacts[0]
    assert solver.equations.max_penetration() < 1e-5  # of the radius 1
    assert sol.max_penetration == solver.equations.max_penetration()  # the solution carries it
    assert sol.swelling_reached == pytest.approx(JS, rel=1e-15)  # the inclusion's target
    p = pc.pressure()
    on = p > 0.1 * p.max()
    assert on.sum() > 10
    # the skull pushes along its normal only (frictionless): radial at the deformed point
    f = np.zeros(form.fes.ndof)
    pc.add_forces(f)
    forces = -(pc.P @ f).reshape(-1, 3)
    x = pc.X + (pc.P @ form.gfu.vec.FV().NumPy()).reshape(-1, 3)
    radial_dir = x / np.linalg.norm(x, axis=1)[:, None]
    assert np.allclose(np.cross(forces, radial_dir)[on], 0, atol=1e-6 * np.abs(forces).max())
    assert np.all(np.einsum("ij,ij->i", forces, radial_dir)[on] < 0)  # pushes inwards
    # ... while the tissue in contact slides along it towards the openings
    u = (pc.P @ form.gfu.vec.FV().NumPy()).reshape(-1, 3)
    radial = np.einsum("ij,ij->i", u, pc.X)
    tangential = np.linalg.norm(u - radial[:, None] * pc.X, axis=1)
    assert np.max(tangential[on]) > 100 * np.max(np.abs(radial[on]))


def test_closed_skull_is_infeasible() -> None:
    _, problem = _capped_ball(h=0.3, h_inclusion=A / 2, cap_deg=0.0)
    with pytest.raises(InfeasibleError, match="closed domain"):
        NewtonSolver(MixedForm(problem, element="mini")).solve()


def test_penetration_is_measured_where_points_can_move() -> None:
    """A clamped contact point that overlaps the obstacle at rest is not in contact and
    does not count as penetration; a free one that overlaps does (the 1.54M-tet brain
    reported 0.136 mm from a clamped point of its fixed base)."""
    from conftest import unit_box_mesh

    c = 0.4
    below = Plane((0.0, 1.0), c)  # rigid body y < c: overlaps the bottom edge by c
    mesh = unit_box_mesh(2)
    for contact in ("ymin", "ymin|xmin"):
        problem = Problem(mesh, {"tissue": GRAY}, {}, clamped="ymin",
                          contacts=[Contact(contact, below)])
        form = MixedForm(problem)
        solver = NewtonSolver(form)
        pc = form.point_contacts[0]
        assert pc.max_penetration() == pytest.approx(c)  # every point, clamped or not
        moving = pc.X[:, 1] > 1e-12  # off the clamped bottom edge
        expected = max(0.0, float(np.max(c - pc.X[moving, 1], initial=0.0)))
        assert solver.equations.max_penetration() == pytest.approx(expected, abs=1e-12)
        assert (expected > 0) == (contact == "ymin|xmin")


@dataclass
class Steeper:
    """The same rigid body with its gap multiplied by ``k`` (``|grad g| = k``)."""

    obstacle: object
    k: float

    def gap_and_normal(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        g, n = self.obstacle.gap_and_normal(x)
        return self.k * g, self.k * n


def test_contact_pressure_is_the_force_per_area_when_the_gap_is_no_distance() -> None:
    """A gap function whose gradient is not of unit length (the sampled skull's is up to
    1.14 at its rounded cut edge) describes the same rigid body: the solution and the
    reported contact pressure (force per reference area) do not change, the multiplier
    does (by 1/k)."""
    results = []
    for k in (1.0, 1.5):
        mesh, problem = _capped_ball(h=0.3, h_inclusion=A / 2, cap_deg=35)
        skull = problem.contacts[0].obstacle
        problem = Problem(mesh, problem.materials, problem.swelling,
                          clamped_components={0: "sym_x", 1: "sym_y", 2: "sym_z"},
                          contacts=[Contact("outer", Steeper(skull, k))])
        form = MixedForm(problem, element="mini")
        assert NewtonSolver(form, SolverOptions(steps=2)).solve().converged
        pc = form.point_contacts[0]
        pc.update(form.gfu.vec.FV().NumPy())
        results.append((form.gfu.vec.FV().NumPy().copy(), pc.pressure().copy(), pc.lam.copy()))
    (x1, p1, l1), (x2, p2, l2) = results
    on = p1 > 0.1 * p1.max()
    assert on.sum() > 5
    np.testing.assert_allclose(x2, x1, atol=1e-7 * np.abs(x1).max())
    np.testing.assert_allclose(p2[on], p1[on], rtol=1e-5)
    np.testing.assert_allclose(l2[on], l1[on] / 1.5, rtol=1e-5)


def test_points_moved_onto_the_obstacle_land_on_it() -> None:
    """``move_onto_obstacle`` puts the chosen points on the surface ``g = 0`` along the
    normal, also where ``|grad g| != 1`` (one step for a plane, a few on a curved body),
    and leaves the other points alone."""
    for obstacle, passes in ((Steeper(Plane((1.0, 0.2, 0.1), 0.02), 1.5), 1),
                             (Steeper(Shifted(CURVED, CURVED_OFFSET), 1.3), 3)):
        form = _contact_form(obstacle)
        pc = form.point_contacts[0]
        rng = np.random.default_rng(2)
        x = 0.05 * rng.standard_normal(form.fes.ndof)
        pc.update(x)
        which = (pc.g < 0) & (np.sum(pc.n**2, axis=1) > 0.25)
        assert which.any() and (~which).any()
        before = pc.g.copy()
        for _ in range(passes):
            pc.update(x)
            pc.move_onto_obstacle(x, which)
        pc.update(x)
        assert np.abs(pc.g[which]).max() < 1e-8
        np.testing.assert_array_equal(pc.g[~which], before[~which])

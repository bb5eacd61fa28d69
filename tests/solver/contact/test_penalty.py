"""The penalty contact against the rounded skull (:mod:`brainbulge.solver.contact.penalty`)
and the step bounds of the resolved edge (:mod:`brainbulge.solver.step_bounds`)."""

from __future__ import annotations

import math

import ngsolve as ngs
import numpy as np
import pytest

from brainbulge.geometry.ngsolve_arrays import vertex_coordinates
from brainbulge.model.hemidisk import PENALTY, HemidiskCase, hemidisk_problem
from brainbulge.solver import MixedForm
from brainbulge.solver.driver import StepControl, Tried
from brainbulge.solver.step_bounds import Slide, StepCap, vertex_scales


@pytest.fixture(scope="module")
def form():
    case = HemidiskCase(mesh_size=0.1, beta=60.0, full_domain=True)  # the whole arc
    return case, MixedForm(hemidisk_problem(case), element="taylor-hood")


def _expand(form: MixedForm, c: float) -> None:
    """``u = c X``: every point moves radially out by ``c`` of its radius."""
    form.u.Set(ngs.CF((c * ngs.x, c * ngs.y)))


def test_penalty_measures_the_depth_and_the_pressure(form) -> None:
    """``u = c X`` pushes the arc ``c R`` into the skull where the skull is: the deepest
    Gauss point is ``c R`` in, its pressure ``kappa c R``; the skull's own edge rounding is
    no deeper; at rest nothing is in contact."""
    case, f = form
    (pen,) = f.penalty_contacts
    assert pen.kappa == pytest.approx(PENALTY * case.tissue_material().shear_modulus)
    f.gfu.vec[:] = 0.0
    assert pen.max_penetration() == 0.0
    c = 1e-3
    _expand(f, c)
    assert pen.max_penetration() == pytest.approx(c * case.R, rel=1e-6)
    g, p = pen.at_vertices()
    X = vertex_coordinates(f.mesh)[pen.vertices]
    under = np.abs(np.degrees(np.arctan2(X[:, 1], X[:, 0])) - 90) > 40  # far from the edge
    under &= X[:, 1] > 1e-9  # not the base's ends
    np.testing.assert_allclose(g[under], -c * case.R, rtol=1e-6)
    np.testing.assert_allclose(p[under], pen.kappa * c * case.R, rtol=1e-6)
    f.gfu.vec[:] = 0.0


def test_penalty_energy_gives_the_contact_force(form) -> None:
    """The residual of the penalty's energy alone is ``-int kappa max(-g, 0) grad g . v``
    (the skull pushes back along ``grad g``): for ``u = c X`` and the virtual displacement
    ``v = X`` it is ``kappa c R^2`` times the skull arc's length (``g = -c R`` and ``grad g .
    X = -R`` where the skull's surface is the circle, which ends the rounding's angle behind
    each end face), plus the rounding's share (< 1 %)."""
    case, f = form
    (pen,) = f.penalty_contacts
    a = ngs.BilinearForm(f.fes)
    u = f.fes.TrialFunction()[0]
    a += ngs.Variation(pen.energy(u) * pen.ds)
    c = 1e-3
    _expand(f, c)
    r = f.gfu.vec.CreateVector()
    a.Apply(f.gfu.vec, r)
    v = ngs.GridFunction(f.fes)
    v.components[0].Set(ngs.CF((ngs.x, ngs.y)))
    work = ngs.InnerProduct(r, v.vec)
    skull_length = case.R * math.radians(180 - case.beta - 2 * case.obstacle.rounding_deg)
    expected = pen.kappa * c * case.R**2 * skull_length
    assert expected < work < 1.01 * expected
    f.gfu.vec[:] = 0.0


def test_opening_is_free_at_rest(form) -> None:
    """At rest the opening's arc and the arc under the roundings are away from the skull:
    the free length is ``R (beta + 2 rounding)``, less the arc where the rounding is still
    within the tolerance of the circle."""
    case, f = form
    (pen,) = f.penalty_contacts
    free = pen.free_measure(1e-4)  # above the curved boundary's geometric error
    opening = case.R * math.radians(case.beta + 2 * case.obstacle.rounding_deg)
    assert free == pytest.approx(opening, rel=0.02)
    assert case.R * math.radians(case.beta) < free < opening


def test_step_cap_bounds_every_vertex_move(form) -> None:
    """The cap scales an update so that the vertex that moves farthest, in units of its
    smallest edge, moves exactly ``cap`` of it; an update within the cap is left whole."""
    _, f = form
    dofs, h, _ = vertex_scales(f)
    cap = StepCap(f, 0.3)
    dx = f.gfu.vec.CreateVector()
    dx[:] = 0.0
    v = int(np.argmin(h))
    dx.FV().NumPy()[dofs[v]] = [0.6 * h[v], 0.8 * h[v]]  # |du| = h_v
    assert cap(f.gfu.vec, dx) == pytest.approx(0.3)
    dx.FV().NumPy()[dofs[v]] *= 0.2
    assert cap(f.gfu.vec, dx) == 1.0
    slide = Slide(f)
    assert slide(np.zeros(len(dx)), dx.FV().NumPy()) == pytest.approx(0.2)


@pytest.mark.parametrize("motion,factor", [(1.0, 1.5), (2.0, 1.0), (3.0, 2 / 3), (10.0, 0.5),
                                           (None, 1.5)])
def test_next_step_is_sized_by_the_motion(motion, factor) -> None:
    """``ds slide / motion``, clipped to ``[cut, grow] ds``; without a motion, growth after an
    easy step."""
    control = StepControl(cut=0.5, grow=1.5, fast_iterations=4, min_step=1e-3, slide=2.0)
    assert control.next_step(0.1, Tried(True, 3, None, motion)) == pytest.approx(0.1 * factor)


def test_edge_band_resolves_the_arc_at_the_edge() -> None:
    """The arc's segments within the band of an opening's edge are at most about the edge's
    mesh size (the edge radius / 3), the others coarser."""
    case = HemidiskCase(mesh_size=0.1, beta=60.0, skull_edge_radius=0.03)
    mesh = case.mesh()
    X = vertex_coordinates(mesh)
    near, far = [], []
    for el in mesh.Elements(ngs.BND):
        a, b = (X[v.nr] for v in el.vertices)
        mid = np.degrees(np.arctan2(*(0.5 * (a + b))[::-1]))
        if abs(np.linalg.norm(0.5 * (a + b)) - 1) > 0.01:
            continue  # the base
        length = np.linalg.norm(a - b)
        (near if min(abs(mid - 60), abs(mid - 120)) < 6 else far).append(length)
    assert max(near) < 1.3 * case.edge_h
    band = math.radians(2 * 6.0) * case.R  # the 12 deg counted at each edge
    assert len(near) >= (1 if case.half else 2) * band / (1.3 * case.edge_h)
    assert max(far) > 5 * case.edge_h  # the mesh size elsewhere

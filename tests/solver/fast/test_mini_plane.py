"""The plane-strain MINI residual and tangent (:mod:`brainbulge.solver.fast.mini_plane`).

Residual, condensed tangent and bubble operators against NGSolve's automatic differentiation
of the energy on the curved hemidisk mesh (two pressure zones), and Newton's path with them
against the plain path.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from brainbulge.geometry.ngsolve_arrays import vertex_coordinates
from brainbulge.materials.ogden import Ogden
from brainbulge.model.hemidisk import HemidiskCase, hemidisk_problem
from brainbulge.solver import MixedForm, NewtonSolver, SolverOptions
from brainbulge.solver.fast.hotspot import HotspotRelaxation
from brainbulge.solver.fast.mini_plane import PlaneMiniTangent, applies
from closed_forms import (
    assert_free_pattern_is_the_free_part,
    assert_local_systems_agree,
    assert_same_newton_path,
)


def _form(contact: str = "sliding", element: str = "mini") -> MixedForm:
    case = HemidiskCase(contact=contact, mesh_size=0.1, element=element,
                        skull_edge_radius=0.0)
    return MixedForm(hemidisk_problem(case), element=element)


@pytest.fixture(scope="module")
def form_and_state():
    form = _form()
    form.set_load(0.7)
    rng = np.random.default_rng(0)
    x = form.gfu.vec.FV().NumPy()
    x[:] = 1e-3 * rng.standard_normal(len(x))
    x[form.fes.components[0].ndof:] *= 100  # pressures of the order of the stresses
    return form, PlaneMiniTangent(form)


def test_residual_equals_ngsolves(form_and_state) -> None:
    form, mt = form_and_state
    assert applies(form) and len(form.pressure_zones) == 2
    assert form.mesh.GetCurveOrder() == 2  # curved boundary triangles
    res = form.gfu.vec.CreateVector()
    form.a.Apply(form.gfu.vec, res)
    ref = res.FV().NumPy()
    R = mt.residual(form.gfu.vec.FV().NumPy())
    assert np.abs(ref).max() > 1
    assert np.abs(R - ref).max() <= 1e-12 * np.abs(ref).max()


def test_tangent_and_bubble_operators_equal_ngsolves(form_and_state) -> None:
    form, mt = form_and_state
    x = form.gfu.vec
    form.a.AssembleLinearization(x)
    data, indices, indptr = form.a.mat.CSR()
    n = form.fes.ndof
    K_ad = sp.csr_matrix((np.array(data), np.array(indices), np.array(indptr)),
                         shape=(form.a.mat.height, form.a.mat.width))[:n, :n]
    K = mt.assemble(x.FV().NumPy())
    free = np.array(list(form.fes.FreeDofs(True)), dtype=bool)
    diff = (K - K_ad)[free][:, free]
    scale = np.abs(K_ad[free][:, free]).max()
    assert scale > 0
    assert np.abs(diff).max() <= 1e-13 * scale
    r = x.CreateVector()
    r.FV().NumPy()[:] = np.random.default_rng(1).standard_normal(n)
    for op, mine in ((form.a.harmonic_extension_trans, mt.extend_trans),
                     (form.a.harmonic_extension, mt.extend),
                     (form.a.inner_solve, mt.inner_solve)):
        y = r.CreateVector()
        y.data = op * r
        ref = y.FV().NumPy()[free] if op is form.a.harmonic_extension_trans else y.FV().NumPy()
        got = mine(r.FV().NumPy())
        got = got[free] if op is form.a.harmonic_extension_trans else got
        assert np.linalg.norm(ref) > 0
        assert np.linalg.norm(got - ref) <= 1e-10 * np.linalg.norm(ref)


def test_tangent_on_the_free_dofs_is_the_free_part_of_the_full_one(form_and_state) -> None:
    assert_free_pattern_is_the_free_part(*form_and_state, PlaneMiniTangent)


def test_a_folded_state_gives_a_non_finite_residual_and_tangent(form_and_state) -> None:
    form, mt = form_and_state
    x = np.zeros(form.fes.ndof)
    X = vertex_coordinates(form.mesh)
    x[:mt.nv] = -2 * X[:, 0]  # x -> -x: every element mirrored, J = -1
    assert not np.isfinite(mt.residual(x)).all()
    assert not np.isfinite(mt.assemble(x).data).all()


@pytest.mark.parametrize("contact", ["noslip", "sliding"])
def test_newton_takes_the_same_path_as_with_ngsolves_derivatives(contact: str) -> None:
    assert_same_newton_path(lambda: _form(contact), PlaneMiniTangent)


def test_other_forms_keep_ngsolves_derivatives() -> None:
    assert not applies(_form(element="taylor-hood"))
    form = _form()
    form.problem.materials = {r: Ogden((1.0,), (2.0,)) for r in form.problem.materials}
    assert not applies(form)


def test_hotspot_local_problems_take_the_same_element_systems_as_ngsolves() -> None:
    form = _form()
    solver = NewtonSolver(form, SolverOptions(steps=2))
    assert solver.solve().converged
    X = form.gfu.vec.FV().NumPy()
    v = int(np.argmin(np.linalg.norm(vertex_coordinates(form.mesh) - [0.2, 0.5], axis=1)))
    X[[v, v + solver.equations.closed.nH1]] += [0.01, -0.005]  # one vertex displaced
    solver.equations.residual(form.gfu.vec)
    relaxation = HotspotRelaxation(solver.equations)
    local = relaxation.local_problem(relaxation.hotspot(solver.equations.res.FV().NumPy()))
    assert local.closed is solver.equations.closed
    assert_local_systems_agree(local, X)

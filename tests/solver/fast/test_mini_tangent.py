"""The closed-form MINI tangent (:mod:`brainbulge.solver.fast.mini_tangent`).

Its Hessian against finite differences of the closed-form stress, its residual, assembled
and condensed matrix and bubble operators against NGSolve's AD of the energy, and Newton's
path with it against the path with NGSolve's residual and tangent.
"""

from __future__ import annotations

import ngsolve as ngs
import numpy as np
import pytest
import scipy.sparse as sp

from brainbulge.geometry.inclusion import inclusion_mesh
from brainbulge.materials import MooneyRivlin
from brainbulge.model import Problem
from brainbulge.solver import MixedForm, NewtonSolver
from brainbulge.solver.fast.hotspot import HotspotRelaxation
from brainbulge.solver.fast.mini_kernels import hessian
from brainbulge.solver.fast.mini_tangent import MiniTangent, applies
from closed_forms import (
    assert_free_pattern_is_the_free_part,
    assert_local_systems_agree,
    assert_same_newton_path,
)

SOFT = MooneyRivlin(0.03, 33.3)
STIFF = MooneyRivlin(0.28, 333.0)


def _problem(curved: bool = False) -> Problem:
    """A soft swelling sphere (Js 1.3) in a stiff ball (octant, symmetry planes), with
    straight tets unless ``curved``."""
    mesh = inclusion_mesh(3, A=0.3, h=0.3, h_inclusion=0.15)
    if not curved:
        mesh.Curve(1)
    return Problem(mesh, {"inclusion": SOFT, "matrix": STIFF}, {"inclusion": 1.3},
                   clamped_components={0: "sym_x", 1: "sym_y", 2: "sym_z"})


def _stress(F: np.ndarray, p: float, m: MooneyRivlin) -> np.ndarray:
    """First Piola-Kirchhoff stress ``P = dW/dF = tau F^-T`` [kPa]."""
    return m.kirchhoff_stress(F, p) @ np.linalg.inv(F).T


@pytest.mark.parametrize("m", [STIFF, MooneyRivlin(1.0, 0.0)])
def test_hessian_is_the_derivative_of_the_stress(m: MooneyRivlin) -> None:
    rng = np.random.default_rng(3)
    for scale in (0.05, 0.4):
        F = np.eye(3) + scale * rng.standard_normal((3, 3))
        assert np.linalg.det(F) > 0
        p = float(rng.standard_normal()) * 10
        A, H = np.empty((9, 9)), np.empty((3, 3))
        hessian(F, p, m.c1, m.c2, A, H)
        assert np.allclose(H, np.linalg.det(F) * np.linalg.inv(F).T, rtol=1e-13, atol=1e-14)
        h = 1e-6
        fd = np.empty((9, 9))
        for kl in range(9):
            dF = np.zeros(9)
            dF[kl] = h
            dF = dF.reshape(3, 3)
            fd[:, kl] = ((_stress(F + dF, p, m) - _stress(F - dF, p, m)) / (2 * h)).ravel()
        assert np.abs(A - fd).max() <= 1e-6 * np.abs(A).max()
        assert np.allclose(A, A.T, rtol=0, atol=1e-12 * np.abs(A).max())


@pytest.fixture(scope="module")
def form_and_state():
    form = MixedForm(_problem(), element="mini")
    form.set_load(1.0)
    rng = np.random.default_rng(7)
    x = form.gfu.vec.FV().NumPy()
    x[:] = 0.02 * rng.standard_normal(len(x))
    return form, MiniTangent(form)


def test_tangent_and_bubble_operators_equal_ngsolves(form_and_state) -> None:
    form, mt = form_and_state
    assert applies(form)
    x = form.gfu.vec
    form.a.AssembleLinearization(x)
    data, indices, indptr = form.a.mat.CSR()
    n = form.fes.ndof
    K_ad = sp.csr_matrix((np.array(data), np.array(indices), np.array(indptr)), shape=(n, n))
    K = mt.assemble(x.FV().NumPy())
    scale = np.abs(K_ad).max()
    assert np.abs(K - K_ad).max() <= 1e-13 * scale
    assert np.abs(K).max() == pytest.approx(scale)  # not both empty
    r = x.CreateVector()
    r.FV().NumPy()[:] = np.random.default_rng(1).standard_normal(n)
    for op, mine in ((form.a.harmonic_extension_trans, mt.extend_trans),
                     (form.a.harmonic_extension, mt.extend),
                     (form.a.inner_solve, mt.inner_solve)):
        y = r.CreateVector()
        y.data = op * r
        ref = y.FV().NumPy()
        assert np.linalg.norm(ref) > 0
        assert np.linalg.norm(mine(r.FV().NumPy()) - ref) <= 1e-10 * np.linalg.norm(ref)


def test_tangent_on_the_free_dofs_is_the_free_part_of_the_full_one(form_and_state) -> None:
    form, mt = form_and_state
    assert_free_pattern_is_the_free_part(form, mt, MiniTangent)
    ns = NewtonSolver(form)  # Newton's equations assemble on the free DOFs
    assert ns.equations.closed._pattern.shape == (len(ns.equations.free),) * 2


def test_residual_equals_ngsolves(form_and_state) -> None:
    form, mt = form_and_state
    res = form.gfu.vec.CreateVector()
    form.a.Apply(form.gfu.vec, res)
    ref = res.FV().NumPy()
    assert np.abs(ref).max() > 1
    assert np.abs(mt.residual(form.gfu.vec.FV().NumPy()) - ref).max() <= 1e-13 * np.abs(ref).max()


def test_a_degenerate_element_gives_a_non_finite_tangent(form_and_state) -> None:
    form, _ = form_and_state
    mt = MiniTangent(form)
    mt.coords = mt.coords.copy()
    v = mt.verts[0]
    mt.coords[v[0]] = mt.coords[v[1]]  # element 0 flattened
    assert not np.isfinite(mt.assemble(form.gfu.vec.FV().NumPy()).data).any()
    assert not np.isfinite(mt.residual(form.gfu.vec.FV().NumPy())).all()


def test_newton_takes_the_same_path_with_either_tangent() -> None:
    assert_same_newton_path(lambda: MixedForm(_problem(), element="mini"), MiniTangent)


def test_other_forms_keep_ngsolves_tangent() -> None:
    assert not applies(MixedForm(_problem(curved=True), element="mini"))
    assert not applies(MixedForm(_problem(), element="taylor-hood"))
    assert NewtonSolver(MixedForm(_problem(curved=True), element="mini")).equations.closed is None



def _fan_octant(n: int) -> ngs.Mesh:
    """Octant of the unit ball as a fan of ``n^2`` straight tets around the centre (every tet
    shares the centre vertex: the element loop needs ``n^2`` colours); boundaries ``free``
    (the sphere), ``xmin``, ``ymin``, ``zmin``; region ``tissue``."""
    from netgen.csg import Pnt
    from netgen.meshing import Element2D, Element3D, FaceDescriptor, MeshPoint
    from netgen.meshing import Mesh as NetgenMesh

    index, points = {}, [np.zeros(3)]
    for i in range(n + 1):  # the octahedron's face i + j + k = n, projected to the sphere
        for j in range(n + 1 - i):
            index[i, j] = len(points)
            p = np.array([i, j, n - i - j], float)
            points.append(p / np.linalg.norm(p))
    triangles = [(index[i, j], index[i + 1, j], index[i, j + 1])
                 for i in range(n) for j in range(n - i)]
    triangles += [(index[i + 1, j], index[i + 1, j + 1], index[i, j + 1])
                  for i in range(n) for j in range(n - i - 1)]
    m = NetgenMesh(dim=3)
    ids = [m.Add(MeshPoint(Pnt(*p))) for p in points]
    for k, name in enumerate(("free", "xmin", "ymin", "zmin")):
        m.Add(FaceDescriptor(surfnr=k + 1, domin=1, domout=0, bc=k + 1))
        m.SetBCName(k, name)
    m.SetMaterial(1, "tissue")
    P = np.array(points)
    for a, b, c in triangles:
        if np.linalg.det(P[[a, b, c]]) < 0:
            b, c = c, b
        m.Add(Element3D(1, [ids[0], ids[a], ids[b], ids[c]]))
        m.Add(Element2D(1, [ids[a], ids[c], ids[b]]))
        for axis in range(3):  # an edge on a coordinate plane closes it with the centre
            for e0, e1 in ((a, b), (b, c), (c, a)):
                if P[e0, axis] == 0 and P[e1, axis] == 0:
                    m.Add(Element2D(axis + 2, [ids[0], ids[e0], ids[e1]]))
    return ngs.Mesh(m)


def test_a_set_up_it_cannot_do_falls_back_to_ngsolves_tangent(caplog) -> None:
    """A mesh whose element loop needs more than 128 colours (144 tets around one vertex)
    is solved with NGSolve's tangent, saying so, and right (free swelling, ``u = (Js^(1/3)
    - 1) X``); 121 tets around one vertex still take the closed form."""
    import logging

    Js = 1.3
    X = ngs.CF((ngs.x, ngs.y, ngs.z))
    for n, closed in ((11, True), (12, False)):
        mesh = _fan_octant(n)
        problem = Problem(mesh, {"tissue": STIFF}, {"tissue": Js},
                          clamped_components={0: "xmin", 1: "ymin", 2: "zmin"})
        caplog.clear()
        with caplog.at_level(logging.WARNING, logger="brainbulge"):
            ns = NewtonSolver(MixedForm(problem, element="mini"))
            sol = ns.solve()
        assert (ns.equations.closed is not None) == closed
        warned = "closed-form tangent not used (more than 128 colours" in caplog.text
        assert warned != closed, caplog.text
        assert sol.converged
        error = sol.form.u - (Js ** (1 / 3) - 1) * X
        assert ngs.Integrate(ngs.InnerProduct(error, error), mesh) ** 0.5 < 1e-10


def test_hotspot_local_problems_take_the_same_element_systems_as_ngsolves(form_and_state) -> None:
    form, mt = form_and_state
    solver = NewtonSolver(form)
    assert solver.equations.closed is not None
    relaxation = HotspotRelaxation(solver.equations)
    local = relaxation.local_problem(np.array([int(mt.verts[0, 0])]))
    assert local.closed is solver.equations.closed
    assert_local_systems_agree(local, form.gfu.vec.FV().NumPy())

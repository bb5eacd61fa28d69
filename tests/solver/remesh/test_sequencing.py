"""Mesh sequencing (:mod:`brainbulge.solver.remesh.sequencing`) on the capped ball of
contact_cases: a swelling sphere in an incompressible ball octant sliding in a rigid
spherical skull with polar openings, meshed twice (h = 0.3 and 0.15).

- the carried-over state is exact where it can be: affine ``u`` and per-zone affine ``p`` at
  fine vertices inside the coarse mesh (inside the same zone, for ``p``; elsewhere the zone's
  pressure starts at 0); contact pressures from the nearest point; pressed points end on the
  obstacle, unless that folds an element;
- Newton from the carried-over coarse solution reaches the fine ramp's state, in fewer fine
  iterations; when it fails, the fine mesh ramps from Js = 1 and reaches it all the same.
"""

from __future__ import annotations

import ngsolve as ngs
import numpy as np
import pytest
from scipy.spatial import cKDTree

from brainbulge.errors import InputError
from brainbulge.geometry.ngsolve_arrays import element_vertices, vertex_coordinates, vertex_dofs
from brainbulge.solver import NewtonSolver, SolverOptions
from brainbulge.solver.mixed import MixedForm
from brainbulge.solver.options import Solution
from brainbulge.solver.remesh.sequencing import (
    interpolate_state,
    measure_ratio,
    press_onto_obstacles,
    solve_sequenced,
)
from contact_cases import _coords, _forms

OPTIONS = SolverOptions(steps=2)
FOLD_RATIO = OPTIONS.sequencing.fold_ratio
COARSE_TOLERANCE = OPTIONS.sequencing.coarse_tolerance


def _vertex_u(form: MixedForm) -> np.ndarray:
    V = form.fes.components[0]
    dofs = [V.GetDofNrs(ngs.NodeId(ngs.VERTEX, v))[:3] for v in range(form.mesh.nv)]
    return form.u.vec.FV().NumPy()[np.array(dofs)]


def _zone_vertices(mesh: ngs.Mesh, zone: str) -> np.ndarray:
    mask = mesh.Materials(zone).Mask()
    return np.unique([v.nr for el in mesh.Elements(ngs.VOL) if mask[el.index]
                      for v in el.vertices])


@pytest.fixture(scope="module")
def ramp():
    """The fine mesh's own load ramp (the reference)."""
    _, fine = _forms()
    solver = NewtonSolver(fine, OPTIONS)
    sol = solver.solve()
    assert sol.converged
    return fine, sol


def test_carried_state_is_exact_for_affine_fields() -> None:
    coarse, fine = _forms()
    for form in (coarse, fine):
        form.mesh.Curve(1)  # straight elements: P1 interpolation of affine fields is exact
    G = np.diag([0.01, -0.02, 0.03])  # u_i = 0 on the symmetry plane X_i = 0
    Xc = _coords(coarse.mesh)
    V = coarse.fes.components[0]
    uvec = coarse.u.vec.FV().NumPy()
    for v in range(coarse.mesh.nv):
        uvec[list(V.GetDofNrs(ngs.NodeId(ngs.VERTEX, v))[:3])] = G @ Xc[v]
    slopes = {}
    for k, zone in enumerate(coarse.pressure_zones):
        a = np.array([1.0, -2.0, 0.5]) * (k + 1)
        slopes[zone] = (k - 1.0, a)
        Q = coarse.fes.components[1 + k]
        pvec = coarse.gfu.components[1 + k].vec.FV().NumPy()
        for v in _zone_vertices(coarse.mesh, zone):
            pvec[Q.GetDofNrs(ngs.NodeId(ngs.VERTEX, int(v)))[0]] = k - 1.0 + a @ Xc[v]
    pc_c = coarse.point_contacts[0]
    pc_c.lam = np.zeros(pc_c.n_points)  # nothing pressed: no projection onto the skull
    coarse.set_load(0.5)
    interpolate_state(coarse, fine, FOLD_RATIO)

    X = _coords(fine.mesh)
    inside = coarse.mesh(*X.T)["nr"] >= 0
    assert inside.mean() > 0.5
    u = _vertex_u(fine)
    assert np.abs(u[inside] - X[inside] @ G.T).max() < 1e-12
    # vertices outside the coarse mesh (its chords miss slivers of the sphere) are found
    # inwards, within a fine element: off by at most |G| h
    assert np.abs(u - X @ G.T).max() < np.abs(G).max() * 0.15
    for k, zone in enumerate(fine.pressure_zones):
        Q = fine.fes.components[1 + k]
        c0, a = slopes[zone]
        verts = _zone_vertices(fine.mesh, zone)
        p = fine.gfu.components[1 + k].vec.FV().NumPy()[
            [Q.GetDofNrs(ngs.NodeId(ngs.VERTEX, int(v)))[0] for v in verts]]
        err = np.abs(p - (c0 + X[verts] @ a))
        nr = coarse.mesh(*X[verts].T)["nr"]
        mask = coarse.mesh.Materials(zone).Mask()
        zone_of = np.array([mask[el.index] for el in coarse.mesh.Elements(ngs.VOL)])
        same = (nr >= 0) & zone_of[np.maximum(nr, 0)]
        assert same.mean() > 0.3
        assert err[same].max() < 1e-12  # in a coarse element of the zone: interpolated
        assert (~same).any() and np.all(p[~same] == 0.0)  # else 0
    assert fine.load.Get() == 0.5


def test_contact_pressures_and_pressed_points() -> None:
    coarse, fine = _forms()
    solver = NewtonSolver(coarse, OPTIONS)
    assert solver.solve().converged
    interpolate_state(coarse, fine, FOLD_RATIO)
    pc_c, pc_f = coarse.point_contacts[0], fine.point_contacts[0]
    pc_f.update(fine.gfu.vec.FV().NumPy())
    _, j = cKDTree(pc_c.x).query(pc_f.x)
    assert np.array_equal(pc_f.lam, pc_c.lam[j])
    pressed = pc_f.lam > 0
    assert pressed.sum() > 10
    assert np.abs(pc_f.g[pressed]).max() < 1e-4  # on the skull (radius 1)


def test_sequenced_solve_reaches_the_fine_solution_in_fewer_iterations(ramp) -> None:
    fine_ref, sol_ref = ramp
    coarse, fine = _forms()
    sol, record = solve_sequenced(coarse, fine, OPTIONS)
    assert sol.converged and record.coarse_converged and record.fine_converged
    assert [s.load for s in sol.steps] == [1.0]
    assert sol.newton_iterations < sol_ref.newton_iterations
    # the carried-over state's residual: the fine Newton's first, above the tolerance
    assert record.initial_residual > OPTIONS.newton.tolerance
    u_ref = _vertex_u(fine_ref)
    assert np.abs(_vertex_u(fine) - u_ref).max() < 1e-4 * np.abs(u_ref).max()
    lam_ref = fine_ref.point_contacts[0].lam
    assert np.abs(fine.point_contacts[0].lam - lam_ref).max() < 1e-4 * lam_ref.max()
    assert sol.max_penetration < 1e-5


def test_a_solved_coarse_form_is_carried_over_without_a_new_solve(ramp) -> None:
    """``coarse_solution``: the coarse form already at its equilibrium (the previous member of
    a mesh family) is carried over as it is (its state bit for bit: a new solve, at the
    coarse tolerance, would move it), to the same fine state."""
    fine_ref, _ = ramp
    coarse, fine = _forms()
    csol = NewtonSolver(coarse, OPTIONS).solve()
    assert csol.converged
    x0 = coarse.gfu.vec.FV().NumPy().copy()
    lam0 = [pc.lam.copy() for pc in coarse.point_contacts]
    sol, record = solve_sequenced(coarse, fine, OPTIONS, coarse_solution=csol)
    assert sol.converged and record.fine_converged
    assert record.coarse_newton_iterations == csol.newton_iterations
    assert np.array_equal(coarse.gfu.vec.FV().NumPy(), x0)
    assert all(np.array_equal(pc.lam, b) for pc, b in zip(coarse.point_contacts, lam0,
                                                           strict=True))
    u_ref = _vertex_u(fine_ref)
    assert np.abs(_vertex_u(fine) - u_ref).max() < 1e-4 * np.abs(u_ref).max()


def test_sequencing_falls_back_to_the_ramp(ramp, monkeypatch) -> None:
    fine_ref, _ = ramp

    def fails(self: NewtonSolver) -> Solution:
        return Solution(form=self.form, load=1.0, converged=False, note="forced")

    monkeypatch.setattr(NewtonSolver, "equilibrate", fails)
    coarse, fine = _forms()
    sol, record = solve_sequenced(coarse, fine, OPTIONS)
    assert record.coarse_converged and not record.fine_converged
    assert sol.converged and len(sol.steps) >= 2  # the ramp
    u_ref = _vertex_u(fine_ref)
    assert np.abs(_vertex_u(fine) - u_ref).max() < 1e-4 * np.abs(u_ref).max()


def test_sequencing_needs_the_mini_element() -> None:
    coarse, fine = _forms(element="taylor-hood")
    with pytest.raises(InputError, match="MINI"):
        interpolate_state(coarse, fine, FOLD_RATIO)


def test_equilibrate_restores_the_state_when_newton_fails() -> None:
    """One Newton iteration from the carried-over state is not enough: ``equilibrate``
    reports the failure and leaves the state and contact pressures as they were."""
    coarse, fine = _forms()
    assert NewtonSolver(coarse, OPTIONS).solve().converged
    interpolate_state(coarse, fine, FOLD_RATIO)
    x0 = fine.gfu.vec.FV().NumPy().copy()
    lam0 = fine.point_contacts[0].lam.copy()
    solver = NewtonSolver(fine, SolverOptions(max_iterations=1))
    sol = solver.equilibrate()
    assert not sol.converged and sol.rejected_steps == 1 and "did not converge" in sol.message
    assert sol.message.endswith("after 1 iterations: max_iterations = 1 reached)")
    assert np.array_equal(fine.gfu.vec.FV().NumPy(), x0)
    assert np.array_equal(fine.point_contacts[0].lam, lam0)


def test_equilibrate_adds_the_contact_curvature_once_the_residual_is_small(ramp) -> None:
    """From a carried-over state the tangent leaves the contact curvature out while the
    scaled residual is above ``carried_curvature_tolerance`` (a modified Newton method) and
    takes the exact tangent below it; the state reached is the fine ramp's."""
    fine_ref, _ = ramp
    coarse, fine = _forms()
    assert NewtonSolver(coarse, OPTIONS).solve().converged
    interpolate_state(coarse, fine, FOLD_RATIO)
    probe = NewtonSolver(fine, OPTIONS)
    tol = 0.1 * probe.equations.scaled_norm(probe.equations.residual(fine.gfu.vec))
    solver = NewtonSolver(fine, SolverOptions(steps=2, carried_curvature_tolerance=tol))
    calls: list[tuple[float, bool]] = []
    tangent = solver.equations.tangent

    def spy(x: ngs.BaseVector, curvature: bool = True):
        norm = solver.equations.scaled_norm(solver.equations.res.FV().NumPy())
        calls.append((norm, curvature))
        return tangent(x, curvature)

    solver.equations.tangent = spy
    assert solver.equilibrate().converged
    assert all(on == (norm <= tol) for norm, on in calls)
    assert {on for _, on in calls} == {False, True}
    u_ref = _vertex_u(fine_ref)
    assert np.abs(_vertex_u(fine) - u_ref).max() < 1e-4 * np.abs(u_ref).max()


def test_the_coarse_stage_stops_at_its_own_tolerance() -> None:
    """The coarse state is only a start: its Newton stops at COARSE_TOLERANCE (fewer
    iterations than at the requested tolerance), the fine mesh's at the requested
    tolerance; both read off the states left on the two meshes."""

    def residual(form: MixedForm) -> float:
        ns = NewtonSolver(form, OPTIONS)
        return ns.equations.scaled_norm(ns.equations.residual(form.gfu.vec))

    coarse, fine = _forms()
    sol, record = solve_sequenced(coarse, fine, OPTIONS)
    assert sol.converged and record.coarse_converged
    assert COARSE_TOLERANCE > OPTIONS.newton.tolerance
    assert COARSE_TOLERANCE * 1e-3 < residual(coarse) <= COARSE_TOLERANCE
    assert residual(fine) <= OPTIONS.newton.tolerance
    tight, _ = _forms()
    assert NewtonSolver(tight, OPTIONS).solve().newton_iterations > record.coarse_newton_iterations


class _KinkedSkull:
    """The unit sphere as skull (``g = 1 - |x|``), every point 0.01 inside it, except that
    the point at ``spot`` is 0.5 inside with a tangential normal: projecting it onto the
    skull moves it by 0.5 along the surface, across its neighbours (elements of h = 0.15)."""

    def __init__(self, spot: np.ndarray, tangent: np.ndarray) -> None:
        self.spot, self.tangent = spot, tangent

    def gap_and_normal(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        r = np.linalg.norm(x, axis=1)
        g, n = 0.99 - r, -x / r[:, None]
        at = np.linalg.norm(x - self.spot, axis=1) < 1e-9
        g[at], n[at] = -0.5, self.tangent
        return g, n


def test_moves_onto_the_obstacle_that_fold_elements_are_undone() -> None:
    _, fine = _forms()
    mesh = fine.mesh
    X = vertex_coordinates(mesh)
    els, _ = element_vertices(mesh)
    pc = fine.point_contacts[0]
    vd = vertex_dofs(fine.fes.components[0], mesh)
    i = int(np.argmin(np.abs(X[pc.vertices, 2] - 0.5 * X[pc.vertices].max(axis=0)[2])))
    spot = X[pc.vertices[i]]
    radial = spot / np.linalg.norm(spot)
    tangent = np.cross(radial, [0.0, 0.0, 1.0])
    pc.obstacle = _KinkedSkull(spot, tangent / np.linalg.norm(tangent))
    pc.lam = np.ones(pc.n_points)
    x = fine.gfu.vec.FV().NumPy()
    x[:] = 0.0
    moved_alone = x.copy()
    pc.update(moved_alone)
    pc.move_onto_obstacle(moved_alone, pc.lam > 0)
    assert measure_ratio(X, els, moved_alone[vd]).min() < 0  # the kinked move folds
    press_onto_obstacles(fine, X, els, FOLD_RATIO)
    J = measure_ratio(X, els, x[vd])
    assert J.min() >= FOLD_RATIO
    assert np.all(x[vd[pc.vertices[i]]] == 0.0)  # the folding move undone
    r = np.linalg.norm(X[pc.vertices] + x[vd[pc.vertices]], axis=1)
    kept = np.abs(r - np.linalg.norm(X[pc.vertices], axis=1)) > 0
    assert kept.mean() > 0.9  # the others pressed onto the skull
    assert np.allclose(r[kept], 0.99, atol=1e-3)

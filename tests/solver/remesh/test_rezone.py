"""Rezoning (2D): a new reference mesh through the current deformation, and load stepping
that exchanges meshes (tissue sliding around the skull's cut edge)."""

from __future__ import annotations

import ngsolve as ngs
import numpy as np
import pytest

from brainbulge.errors import ConvergenceError, InputError
from brainbulge.geometry.hemidisk import Hemidisk
from brainbulge.geometry.rezone import _topology, deformed_quality, rezone, triangle_quality
from brainbulge.model.hemidisk import HemidiskCase, hemidisk_problem
from brainbulge.solver import MixedForm, NewtonSolver, SolverOptions
from brainbulge.solver.remesh.rezoning import Rezoning, solve_with_rezoning


def _map(X: np.ndarray) -> np.ndarray:
    """A quadratic displacement (exact in P2) that shears the top of the hemidisk."""
    return np.stack([0.3 * X[:, 1] ** 2, 0.2 * X[:, 0] * X[:, 1]], axis=1)


@pytest.fixture(scope="module")
def rezoned():
    geo = Hemidisk(alpha_deg=80, beta_deg=30)
    mesh = geo.mesh(0.1)
    u = ngs.GridFunction(ngs.VectorH1(mesh, order=2))
    u.Set(ngs.CF((0.3 * ngs.y**2, 0.2 * ngs.x * ngs.y)))
    return geo, mesh, u, rezone(mesh, u, geo.project, 0.1, 0.02, geo.singular_points())


def test_rezoned_mesh_keeps_domain_regions_and_boundaries(rezoned) -> None:
    geo, mesh, _, rz = rezoned
    new = rz.mesh
    assert set(new.GetMaterials()) == set(mesh.GetMaterials())
    assert {"skull", "opening", "base"} <= set(new.GetBoundaries())
    for region in set(mesh.GetMaterials()):
        a_old = ngs.Integrate(ngs.CF(1), mesh, definedon=mesh.Materials(region))
        a_new = ngs.Integrate(ngs.CF(1), new, definedon=new.Materials(region))
        # the new mesh is straight-sided: the arc loses its chord segments, h^2/(8R) deep
        assert a_new == pytest.approx(a_old, rel=3e-3)
    X = np.array([v.point for v in new.vertices])
    names = new.GetBoundaries()
    for el in new.Elements(ngs.BND):
        P = X[[v.nr for v in el.vertices]]
        if names[el.index] in ("skull", "opening"):
            np.testing.assert_allclose(np.linalg.norm(P, axis=1), 1.0, atol=1e-12)
        elif names[el.index] == "base":
            np.testing.assert_allclose(P[:, 1], 0.0, atol=1e-12)
    # the sector edges stay on their radial lines
    s_lo, s_hi = np.radians(geo.sector_angles_deg)
    top = _topology(new)
    sw = top.regions.index("swelling")
    for tri in top.tris[top.region == sw]:
        ang = np.arctan2(top.X[tri, 1], top.X[tri, 0])
        r = np.linalg.norm(top.X[tri], axis=1)
        assert np.all((ang >= s_lo - 1e-9) & (ang <= s_hi + 1e-9) | (r < 1e-12))


def test_pull_back_inverts_the_deformation(rezoned) -> None:
    """Interior vertices: ``X + u(X) = x`` solved to the interpolation error of the map
    (exact in P2 but for the curved elements at the arc); the image of the new mesh is better
    shaped than the image of the old one."""
    _, mesh, u, rz = rezoned
    top = _topology(rz.mesh)
    exact = _map(top.X)
    on_boundary = {v.nr for el in rz.mesh.Elements(ngs.BND) for v in el.vertices}
    inner = np.array(sorted(set(range(len(top.X))) - on_boundary))
    np.testing.assert_allclose(rz.u_vertices[inner], exact[inner], atol=2e-5)
    # on the curved boundary only up to the chord error of the deformed polyline
    assert np.abs(rz.u_vertices - exact).max() < 0.01
    q_old = deformed_quality(mesh, u).min()
    q_new = triangle_quality(top.X + rz.u_vertices, top.tris).min()
    assert q_new > q_old


def test_rezoning_keeps_the_solution() -> None:
    """Rezoning after every load step (forced by an unreachable quality bound) changes the
    mesh, not the problem: the same displacements as on the fixed mesh, within the
    discretisation error, and ``J = Js`` on the final, rezoned mesh."""
    case = HemidiskCase(alpha=80, beta=60, contact="noslip", mesh_size=0.1)
    geo = case.geometry
    fixed = MixedForm(hemidisk_problem(case))
    assert NewtonSolver(fixed, SolverOptions(steps=4)).solve().converged
    rezoning = Rezoning(lambda m: hemidisk_problem(case, m), geo.project, 0.1, 0.02,
                        geo.singular_points(), q_min=1.1)
    sol = solve_with_rezoning(hemidisk_problem(case), rezoning,
                              options=SolverOptions(steps=4))
    assert sol.converged and sol.rezones >= 2
    assert sol.form.mesh is not fixed.mesh
    pts = [(0.0, 0.99), (0.0, 0.5), (-0.3, 0.8), (0.4, 0.3)]
    u_fixed = np.array([fixed.u(fixed.mesh(*p)) for p in pts])
    u_rez = np.array([sol.form.u(sol.form.mesh(*p)) for p in pts])
    np.testing.assert_allclose(u_rez, u_fixed, atol=0.01 * np.abs(u_fixed).max())
    # J = Js weakly (P1 pressure): the swollen volume per region is exact, and the
    # pointwise defect no worse than on the fixed mesh
    for form in (fixed, sol.form):
        for region in ("swelling", "tissue"):
            dV = ngs.Integrate(ngs.Det(form.F()) - form.Js, form.mesh,
                               definedon=form.mesh.Materials(region))
            assert abs(dV) < 1e-9

    def defect(f: MixedForm) -> float:
        return float(ngs.Integrate((ngs.Det(f.F()) - f.Js) ** 2, f.mesh)) ** 0.5

    assert defect(sol.form) < 2 * defect(fixed)


def test_start_load_is_checked() -> None:
    with pytest.raises(InputError, match="start_load"):
        SolverOptions(start_load=1.0)


def test_a_failed_rezoning_goes_on_without_it() -> None:
    """A rezoning that fails (here: the projection refuses) leaves the old mesh's converged
    state, and the ramp goes on there to full load, as without rezoning."""
    case = HemidiskCase(alpha=80, beta=60, contact="noslip", mesh_size=0.1)
    geo = case.geometry

    def refuse(label: str, X: np.ndarray) -> np.ndarray:
        raise ConvergenceError("no projection")

    rezoning = Rezoning(lambda m: hemidisk_problem(case, m), refuse, 0.1, 0.02,
                        geo.singular_points(), q_min=1.1)
    problem = hemidisk_problem(case)
    sol = solve_with_rezoning(problem, rezoning, options=SolverOptions(steps=4))
    assert sol.converged and sol.rezones == 0
    assert sol.form.mesh is problem.mesh
    assert sol.load == 1.0


def test_stop_hooks_keep_the_last_converged_state() -> None:
    """``stop_on_failure`` ends the ramp at the last converged load instead of cutting the
    step; ``stop_when`` after an accepted step. Both keep that state."""
    case = HemidiskCase(alpha=80, beta=60, contact="noslip", mesh_size=0.1)
    asked: list[float] = []

    def stop(t: float) -> bool:
        asked.append(t)
        return True

    form = MixedForm(hemidisk_problem(case))
    # one Newton iteration per attempt cannot converge a quarter of the swelling
    sol = NewtonSolver(form, SolverOptions(steps=4, max_iterations=1,
                                           stop_on_failure=stop)).solve()
    assert sol.stopped_early and not sol.converged
    assert asked == [0.0] and sol.load == 0.0 and sol.rejected_steps == 1
    assert np.abs(form.u.vec.FV().NumPy()).max() == 0.0  # back at the undeformed state

    form = MixedForm(hemidisk_problem(case))
    sol = NewtonSolver(form, SolverOptions(steps=4, stop_when=lambda: True)).solve()
    assert sol.stopped_early and sol.load == pytest.approx(0.25) and len(sol.steps) == 1
    J_err = ngs.Integrate(ngs.Det(form.F()) - form.Js, form.mesh)  # at load 0.25
    Js_025 = ngs.Integrate(1 + 0.25 * (form.Js - 1) - form.Js, form.mesh)
    assert abs(J_err - Js_025) < 1e-9


def test_rezoned_mesh_keeps_the_rim_refinement(rezoned) -> None:
    """Reference points given as ``rim_points`` (the edge-exclusion circles) are refined to
    ``h_rim`` at their images in the deformed domain, which the new mesh is made in."""
    geo, mesh, u, rz = rezoned
    rim = geo.rim_points(0.05, 0.005)
    fine = rezone(mesh, u, geo.project, 0.1, 0.02, geo.singular_points(), rim, 0.005)
    x_rim = rim + _map(rim)

    def median_edge_near_rim(r) -> float:
        top = _topology(r.mesh)
        x = top.X + r.u_vertices  # the deformed vertices, where the mesh was made
        d = np.min(np.linalg.norm(x[:, None] - x_rim[None], axis=2), axis=1)
        P = x[top.tris[np.any(d[top.tris] < 0.003, axis=1)]]
        longest = np.max([np.linalg.norm(P[:, i] - P[:, (i + 1) % 3], axis=1)
                          for i in range(3)], axis=0)
        return float(np.median(longest))

    assert median_edge_near_rim(fine) < 2 * 0.005
    assert median_edge_near_rim(rz) > 3 * 0.005

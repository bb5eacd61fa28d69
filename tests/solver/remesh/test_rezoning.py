"""Load stepping that exchanges meshes (2D rezoning,
:mod:`brainbulge.solver.remesh.rezoning`: tissue sliding around the skull's cut edge)."""

from __future__ import annotations

import ngsolve as ngs
import numpy as np
import pytest

from brainbulge.errors import ConvergenceError, InputError
from brainbulge.model.hemidisk import HemidiskCase, hemidisk_problem
from brainbulge.solver import MixedForm, NewtonSolver, SolverOptions
from brainbulge.solver.options import RezoningOptions
from brainbulge.solver.remesh.rezoning import Rezoning, solve_with_rezoning

#: rezoning after every accepted load step (a quality bound no triangle reaches)
ALWAYS = SolverOptions(steps=4, rezoning=RezoningOptions(q_min=1.1))


def test_rezoning_keeps_the_solution() -> None:
    """Rezoning after every load step (forced by an unreachable quality bound) changes the
    mesh, not the problem: the same displacements as on the fixed mesh, within the
    discretisation error, and ``J = Js`` on the final, rezoned mesh; the half domain's
    symmetry axis stays a boundary."""
    case = HemidiskCase(alpha=80, beta=60, contact="noslip", mesh_size=0.1,
                        skull_edge_radius=0.0)
    geo = case.geometry
    fixed = MixedForm(hemidisk_problem(case))
    assert NewtonSolver(fixed, SolverOptions(steps=4)).solve().converged
    rezoning = Rezoning(lambda m: hemidisk_problem(case, m), geo.project, 0.1, 0.02,
                        geo.singular_points())
    sol = solve_with_rezoning(hemidisk_problem(case), rezoning, options=ALWAYS)
    assert sol.converged and sol.rezones >= 2
    assert sol.form.mesh is not fixed.mesh
    assert case.half and "symmetry" in sol.form.mesh.GetBoundaries()  # the axis kept
    pts = [(0.0, 0.99), (0.0, 0.5), (0.3, 0.8), (0.4, 0.3)]  # the half domain x >= 0
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
    case = HemidiskCase(alpha=80, beta=60, contact="noslip", mesh_size=0.1,
                        skull_edge_radius=0.0)
    geo = case.geometry

    def refuse(label: str, X: np.ndarray) -> np.ndarray:
        raise ConvergenceError("no projection")

    rezoning = Rezoning(lambda m: hemidisk_problem(case, m), refuse, 0.1, 0.02,
                        geo.singular_points())
    problem = hemidisk_problem(case)
    sol = solve_with_rezoning(problem, rezoning, options=ALWAYS)
    assert sol.converged and sol.rezones == 0
    assert sol.form.mesh is problem.mesh
    assert sol.load == 1.0


def test_stop_hooks_keep_the_last_converged_state() -> None:
    """``stop_on_failure`` ends the ramp at the last converged load instead of cutting the
    step; ``stop_when`` after an accepted step. Both keep that state."""
    case = HemidiskCase(alpha=80, beta=60, contact="noslip", mesh_size=0.1,
                        skull_edge_radius=0.0)
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

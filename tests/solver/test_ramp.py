"""The load ramp's failure reports (:mod:`brainbulge.solver.ramp`) on the coarse capped ball
of contact_cases: where the largest unbalanced force is, and what a diverged ramp says."""

from __future__ import annotations

import ngsolve as ngs
import numpy as np
import pytest

from brainbulge.solver import NewtonSolver, SolverOptions
from brainbulge.solver.options import DIVERGENCE_ADVICE
from contact_cases import _coords, _forms

OPTIONS = SolverOptions(steps=2)


def test_residual_site_is_the_vertex_pushed_out_of_equilibrium() -> None:
    """At a converged state, a displacement kick at one free vertex makes the force
    residual largest there: ``residual_site`` returns that vertex's deformed position."""
    coarse, _ = _forms()
    solver = NewtonSolver(coarse, OPTIONS)
    assert solver.solve().converged
    V = coarse.fes.components[0]
    X = _coords(coarse.mesh)
    free = np.zeros(coarse.fes.ndof, dtype=bool)
    free[solver.equations.free] = True
    # a free interior vertex, far from the points of the contact boundary
    inner = [v for v in range(coarse.mesh.nv)
             if all(free[d] for d in V.GetDofNrs(ngs.NodeId(ngs.VERTEX, v)))
             and np.min(np.linalg.norm(coarse.point_contacts[0].X - X[v], axis=1)) > 0.2]
    v = inner[len(inner) // 2]
    dofs = list(V.GetDofNrs(ngs.NodeId(ngs.VERTEX, v)))
    x = coarse.gfu.vec
    x.FV().NumPy()[dofs] += 0.02 * coarse.h
    site = solver.equations.residual_site(x)
    np.testing.assert_allclose(site, X[v] + x.FV().NumPy()[dofs], atol=1e-12)



def test_a_diverged_ramp_says_where_the_force_was_unbalanced() -> None:
    """Newton limited to one iteration per attempt cannot take a load step: the message
    and the Solution's failure name the load, the smallest step tried, the last attempt's
    residual, iterations and why it gave up, and the deformed position of the largest
    unbalanced force; a caller may give its own advice."""
    coarse, _ = _forms()
    sol = NewtonSolver(coarse, SolverOptions(steps=1, max_iterations=1, min_step=0.3)).solve()
    assert not sol.converged and sol.load == 0.0 and sol.swelling_reached == 1.0
    failure = sol.failure
    assert failure is not None and failure.kept == 0.0
    assert failure.step == pytest.approx(0.5) and failure.load == pytest.approx(0.5)
    assert sol.failure_site is failure.site and np.all(np.isfinite(failure.site))
    assert failure.iterations == 1 and failure.residual > OPTIONS.newton.tolerance
    assert failure.reason == "max_iterations = 1 reached"
    assert (f"(the last attempt: |R| = {failure.residual:.2e} after 1 Newton iteration, "
            "max_iterations = 1 reached)") in sol.message
    assert "largest unbalanced force was at (" in sol.message
    where = ", ".join(f"{c:.4g}" for c in sol.failure_site)
    assert where in sol.message
    assert sol.message.endswith(DIVERGENCE_ADVICE)
    assert sol.describe("Look there.").endswith("is kept; the last attempt's largest "
                                                f"unbalanced force was at ({where}). Look there.")

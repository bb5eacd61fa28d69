"""Inexact Newton (:mod:`brainbulge.solver.inexact`): Eisenstat-Walker forcing terms and the
Krylov-driven Newton against the direct one."""

from __future__ import annotations

import numpy as np
import pytest

from brainbulge.solver import MixedForm, NewtonSolver, SolverOptions
from inclusion_cases import _inclusion_problem


def test_forcing_terms_follow_the_residual_ratio() -> None:
    """Eisenstat-Walker choice 2: tight when Newton converges fast, capped, safeguarded,
    and never tighter than the Newton tolerance needs."""
    from brainbulge.solver.inexact import forcing_term

    cap, floor = SolverOptions().linear.eta_max, SolverOptions().linear.eta_min

    def eta(eta: float, ratio: float, norm: float, tol: float) -> float:
        return forcing_term(eta, ratio, norm, tol, cap, floor)

    assert eta(cap, 0.9, 1.0, 1e-9) == cap  # slow progress: loose
    assert eta(cap, 1e-3, 1e-3, 1e-12) == pytest.approx(0.9e-6)
    # the cap wins over the floor 0.1 tol / |R| (GMRES's norm is not Newton's)
    assert eta(cap, 1e-3, 1e-8, 1e-9) == pytest.approx(min(1e-2, cap))
    assert eta(0.5, 1e-6, 1.0, 1e-20) == pytest.approx(min(0.9 * 0.25, cap))
    assert eta(cap, 0.0, 1e-30, 0.0) == floor
    assert forcing_term(0.5, 0.9, 1.0, 1e-9, 0.5, floor) == 0.5  # another cap



@pytest.mark.parametrize("element", ["mini", "taylor-hood"])
def test_inexact_newton_reaches_the_direct_solution(element: str) -> None:
    """Newton with Krylov at Eisenstat-Walker tolerances converges to the same state as
    Newton with the direct solver, in about as many iterations."""
    problem = _inclusion_problem()
    sols = {}
    for linear in ("pardiso", "krylov"):
        form = MixedForm(problem, element=element)
        sol = NewtonSolver(form, SolverOptions(steps=2, linear_solver=linear)).solve()
        assert sol.converged
        sols[linear] = (form.gfu.vec.FV().NumPy().copy(), sol.newton_iterations)
    (x_d, it_d), (x_k, it_k) = sols["pardiso"], sols["krylov"]
    free = np.abs(x_d) > 0
    assert np.max(np.abs(x_k - x_d)) <= 1e-6 * np.max(np.abs(x_d[free]))
    assert it_k <= it_d + 3

"""The direct (PARDISO) solver: its symmetric-indefinite mode, stale analyses and the
fallback to LU, one analysis per sparsity pattern, and the interface both linear solvers
offer Newton's method. On the swollen soft inclusion of inclusion_cases."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from brainbulge.errors import ConvergenceError
from brainbulge.solver import MixedForm, NewtonSolver, SolverOptions
from brainbulge.solver.linear.direct import PardisoSolver
from inclusion_cases import _inclusion_problem


class _Wrapped:
    """A PARDISO solver object passed through (tests replace one method)."""

    def __init__(self, inner) -> None:
        object.__setattr__(self, "inner", inner)

    def __getattr__(self, name):
        return getattr(self.inner, name)

    def __setattr__(self, name, value) -> None:
        setattr(self.inner, name, value)



def test_direct_solver_redoes_a_stale_analysis_before_falling_back_to_lu(swollen) -> None:
    """A numeric factorisation on a reused analysis keeps the scaling and matching PARDISO
    computed from the values analysed then; when that solve misses 1e-6 it is redone once
    with a fresh analysis (2D alpha 80 / beta 30 fold: 4e-3 -> 1e-10; h 0.04 headline: 8 LU
    fallbacks -> 0), and only a miss after that counts for the LU fallback."""
    _, _, K, r = swollen

    class Stale(_Wrapped):  # factors on a reused analysis give 3x too large solutions
        def factorize(self, A):
            object.__setattr__(self, "stale", self.inner._analysed)
            self.inner.factorize(A)

        def solve(self, A, b):
            return (3.0 if self.stale else 1.0) * self.inner.solve(A, b)

    solver = PardisoSolver()
    solver._symmetric = Stale(solver._symmetric)
    solver.solve(K, r)
    assert solver._symmetric.reanalyses == 0
    K2 = (3.0 * K).tocsr()  # the same pattern, other values
    x = solver.solve(K2, r)
    assert np.linalg.norm(K2 @ x - r) <= 1e-9 * np.linalg.norm(r)
    assert solver._symmetric.reanalyses == 1 and solver.lu_solves == 0



def test_direct_solver_falls_back_to_lu_when_the_symmetric_mode_fails(swollen) -> None:
    """A symmetric-mode result that misses 1e-6 (as on contact saddle points of the 111k-tet
    brain) is replaced by unsymmetric LU, for the rest of the run after two misses in a row;
    a matrix neither mode solves raises."""
    _, _, K, r = swollen

    class Broken(_Wrapped):  # a factorisation whose solutions are 3x too large
        def solve(self, A, b):
            return 3.0 * self.inner.solve(A, b)

    solver = PardisoSolver()
    good = solver._symmetric
    solver._symmetric = Broken(good)
    x = solver.solve(K, r)
    assert np.linalg.norm(K @ x - r) <= 1e-9 * np.linalg.norm(r)
    assert solver.lu_solves == 1 and not solver._lu_only  # one miss: LU for that matrix
    solver._symmetric = good
    solver.solve(K, r)
    assert solver.lu_solves == 1  # the symmetric mode again
    solver._symmetric = Broken(good)
    solver.solve(K, r)
    solver.solve(K, r)
    assert solver._lu_only and solver.lu_solves == 3  # two misses in a row: LU from now on
    solver._symmetric = good
    solver.solve(K, r)
    assert solver.lu_solves == 4
    solver._general = Broken(solver._general)
    with pytest.raises(ConvergenceError, match="lost accuracy"):
        solver.solve(K, r)



def test_direct_solver_analyses_a_sparsity_pattern_once(swollen, monkeypatch) -> None:
    """Tangents on a known pattern (or a subset of it: a smaller active set, dropped zeros)
    are factorised without a new symbolic analysis (PARDISO phase 22, not 12), and solved
    as accurately as with one; a new nonzero position brings a new analysis."""
    _, _, K, r = swollen
    solver = PardisoSolver()
    phases: list[int] = []
    inner = solver._symmetric
    original = type(inner)._call_pardiso

    def spy(self, A, b):
        phases.append(self.phase)
        return original(self, A, b)

    monkeypatch.setattr(type(inner), "_call_pardiso", spy)
    K = K.tocsr()
    x = solver.solve(K, r)
    assert 12 in phases
    K2 = K.copy()
    K2.data = K2.data * (1 + 0.1 * np.cos(np.arange(K2.nnz)))  # new values, same pattern
    K2 = 0.5 * (K2 + K2.T)
    C = K2.tocoo()
    pick = np.flatnonzero(C.row != C.col)[:6]  # six pairs dropped: a subset of the pattern
    drop = sp.coo_matrix((np.ones(6), (C.row[pick], C.col[pick])), shape=K2.shape)
    K2 = (K2 - K2.multiply((drop + drop.T) > 0)).tocsr()
    K2.eliminate_zeros()
    assert K2.nnz < K.nnz
    phases.clear()
    x2 = solver.solve(K2, r)
    assert 22 in phases and 12 not in phases
    assert np.linalg.norm(K2 @ x2 - r) <= 1e-9 * np.linalg.norm(r)
    assert np.linalg.norm(x2 - x) > 1e-6 * np.linalg.norm(x)  # another matrix, solved anew
    n = K.shape[0]
    K3 = (K + sp.coo_matrix(([1e-3, 1e-3], ([0, n - 1], [n - 1, 0])), shape=K.shape)).tocsr()
    phases.clear()
    x3 = solver.solve(K3, r)
    assert 12 in phases  # the new entries (0, n-1) need a new analysis
    assert np.linalg.norm(K3 @ x3 - r) <= 1e-9 * np.linalg.norm(r)



def test_symmetric_pardiso_solves_the_hemidisk_saddle_point_without_lu() -> None:
    """With scaling and weighted matching the symmetric-indefinite mode solves the hemidisk's
    pressure/contact saddle point (h 0.04, corner 0.004) to the refinement tolerance; with
    MKL's defaults it left 99 perturbed pivots and fell back to LU for the whole run. (With
    the rim refinement at 0.004 the first two tangents of the second load step still miss
    1e-6 and LU takes over, as designed.)"""
    from brainbulge.model.hemidisk import HemidiskCase, hemidisk_problem

    case = HemidiskCase(alpha=80, beta=60, swelling=1.2, contact="noslip", mesh_size=0.04,
                        corner_mesh_size=0.004, rim_mesh_size=0.04)  # (no rim refinement)
    solver = NewtonSolver(MixedForm(hemidisk_problem(case)), SolverOptions(steps=2))
    sol = solver.solve()
    assert sol.converged
    assert solver.linear.lu_solves == 0



def test_both_linear_solvers_offer_what_newton_calls() -> None:
    """PARDISO and the Krylov solver both implement :class:`LinearSolver`: the solve with a
    tolerance and a guess, the new-load-step hook, release and iteration counts."""
    from brainbulge.solver.linear import LinearSolver, make_linear_solver

    form = MixedForm(_inclusion_problem(), element="mini")
    for name in ("pardiso", "krylov"):
        linear = make_linear_solver(name, form)
        assert isinstance(linear, LinearSolver)
        assert isinstance(linear.stats.iterations, list)

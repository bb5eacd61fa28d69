"""The direct (PARDISO) solver: its symmetric-indefinite mode, stale analyses and the
fallback to LU, one analysis per sparsity pattern, and the interface both linear solvers
offer Newton's method. On the swollen soft inclusion of inclusion_cases."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from brainbulge.errors import ConvergenceError
from brainbulge.solver import MixedForm, NewtonSolver, SolverOptions
from brainbulge.solver.linear.direct import PardisoSolver, pattern_reusing_pardiso
from inclusion_cases import _inclusion_problem


class _Wrapped:
    """A PARDISO factorisation passed through (tests replace one method)."""

    def __init__(self, inner) -> None:
        object.__setattr__(self, "inner", inner)

    def __getattr__(self, name):
        return getattr(self.inner, name)

    def __setattr__(self, name, value) -> None:
        if name in self.__dict__:  # the wrapper's own flags
            object.__setattr__(self, name, value)
        else:
            setattr(self.inner, name, value)


class _Broken(_Wrapped):
    """A factorisation whose solutions are 3x too large while ``broken``."""

    def __init__(self, inner) -> None:
        super().__init__(inner)
        object.__setattr__(self, "broken", True)

    def solve(self, A, b):
        return (3.0 if self.broken else 1.0) * self.inner.solve(A, b)


def test_direct_solver_redoes_a_stale_analysis_before_falling_back_to_lu(swollen) -> None:
    """A numeric factorisation on a reused analysis keeps the scaling and matching PARDISO
    computed from the values analysed then; when that solve misses 1e-6 it is redone once
    with a fresh analysis (2D alpha 80 / beta 30 fold: 4e-3 -> 1e-10; h 0.04 headline: 8 LU
    fallbacks -> 0), and only a miss after that counts for the LU fallback."""
    _, _, K, r = swollen

    class Stale(_Wrapped):  # factors on a reused analysis give 3x too large solutions
        def factorize(self, A):
            object.__setattr__(self, "stale", self.inner.analysed)
            self.inner.factorize(A)

        def solve(self, A, b):
            return (3.0 if self.stale else 1.0) * self.inner.solve(A, b)

    symmetric = Stale(pattern_reusing_pardiso(mtype=-2))
    solver = PardisoSolver(symmetric=symmetric)
    solver.solve(K, r)
    assert symmetric.reanalyses == 0 and symmetric.analyses == 1
    K2 = (3.0 * K).tocsr()  # the same pattern, other values
    x = solver.solve(K2, r)
    assert np.linalg.norm(K2 @ x - r) <= 1e-9 * np.linalg.norm(r)
    assert symmetric.reanalyses == 1 and symmetric.analyses == 2 and solver.lu_solves == 0


def test_direct_solver_falls_back_to_lu_when_the_symmetric_mode_fails(swollen) -> None:
    """A symmetric-mode result that misses 1e-6 (as on contact saddle points of the 111k-tet
    brain) is replaced by unsymmetric LU, for the rest of the run after two misses in a row;
    a matrix neither mode solves raises."""
    _, _, K, r = swollen
    symmetric = _Broken(pattern_reusing_pardiso(mtype=-2))
    general = _Broken(pattern_reusing_pardiso(mtype=11))
    general.broken = False
    solver = PardisoSolver(symmetric=symmetric, general=general)
    x = solver.solve(K, r)
    assert np.linalg.norm(K @ x - r) <= 1e-9 * np.linalg.norm(r)
    assert solver.lu_solves == 1 and not solver.lu_only  # one miss: LU for that matrix
    symmetric.broken = False
    solver.solve(K, r)
    assert solver.lu_solves == 1  # the symmetric mode again
    symmetric.broken = True
    solver.solve(K, r)
    solver.solve(K, r)
    assert solver.lu_only and solver.lu_solves == 3  # two misses in a row: LU from now on
    symmetric.broken = False
    solver.solve(K, r)
    assert solver.lu_solves == 4
    general.broken = True
    with pytest.raises(ConvergenceError, match="lost accuracy"):
        solver.solve(K, r)


def test_direct_solver_analyses_a_sparsity_pattern_once(swollen) -> None:
    """Tangents on a known pattern (or a subset of it: a smaller active set, dropped zeros)
    are factorised without a new symbolic analysis (PARDISO phase 22, not 12), and solved
    as accurately as with one; a new nonzero position brings a new analysis."""
    _, _, K, r = swollen
    symmetric = pattern_reusing_pardiso(mtype=-2)
    solver = PardisoSolver(symmetric=symmetric)
    K = K.tocsr()
    x = solver.solve(K, r)
    assert symmetric.analyses == 1
    K2 = K.copy()
    K2.data = K2.data * (1 + 0.1 * np.cos(np.arange(K2.nnz)))  # new values, same pattern
    K2 = 0.5 * (K2 + K2.T)
    C = K2.tocoo()
    pick = np.flatnonzero(C.row != C.col)[:6]  # six pairs dropped: a subset of the pattern
    drop = sp.coo_matrix((np.ones(6), (C.row[pick], C.col[pick])), shape=K2.shape)
    K2 = (K2 - K2.multiply((drop + drop.T) > 0)).tocsr()
    K2.eliminate_zeros()
    assert K2.nnz < K.nnz
    x2 = solver.solve(K2, r)
    assert symmetric.analyses == 1 and symmetric.reanalyses == 0  # numeric phase 22 only
    assert np.linalg.norm(K2 @ x2 - r) <= 1e-9 * np.linalg.norm(r)
    assert np.linalg.norm(x2 - x) > 1e-6 * np.linalg.norm(x)  # another matrix, solved anew
    n = K.shape[0]
    K3 = (K + sp.coo_matrix(([1e-3, 1e-3], ([0, n - 1], [n - 1, 0])), shape=K.shape)).tocsr()
    x3 = solver.solve(K3, r)
    assert symmetric.analyses == 2  # the new entries (0, n-1) need a new analysis
    assert np.linalg.norm(K3 @ x3 - r) <= 1e-9 * np.linalg.norm(r)
    assert solver.lu_solves == 0


def test_symmetric_pardiso_solves_the_hemidisk_saddle_point_without_lu() -> None:
    """With scaling and weighted matching the symmetric-indefinite mode solves the hemidisk's
    pressure/contact saddle point (h 0.04, corner 0.004) to the refinement tolerance; with
    MKL's defaults it left 99 perturbed pivots and fell back to LU for the whole run. (With
    the rim refinement at 0.004 the first two tangents of the second load step still miss
    1e-6 and LU takes over, as designed.)"""
    from brainbulge.model.hemidisk import HemidiskCase, hemidisk_problem

    case = HemidiskCase(alpha=80, beta=60, swelling=1.2, contact="noslip", mesh_size=0.04,
                        skull_edge_radius=0.0, corner_mesh_size=0.004,
                        rim_mesh_size=0.04)  # (no rim refinement)
    solver = NewtonSolver(MixedForm(hemidisk_problem(case)), SolverOptions(steps=2))
    sol = solver.solve()
    assert sol.converged
    assert solver.equations.linear.lu_solves == 0



def test_both_linear_solvers_offer_what_newton_calls() -> None:
    """PARDISO and the Krylov solver both implement :class:`LinearSolver`: the solve with a
    tolerance and a guess, the new-load-step hook, release and iteration counts."""
    from brainbulge.solver.linear import LinearSolver, make_linear_solver

    form = MixedForm(_inclusion_problem(), element="mini")
    for name in ("pardiso", "krylov"):
        linear = make_linear_solver(name, form)
        assert isinstance(linear, LinearSolver)
        assert isinstance(linear.stats.iterations, list)


def test_symmetric_pardiso_solves_a_pressure_zone_island(tmp_path, caplog) -> None:
    """Two white-matter tets of the toy brain that share one vertex, retagged CSF: an island
    of the CSF pressure zone, whose constant pressure MINI's condensed pressure block does
    not see (a singular pivot). With 1x1 pivots the symmetric mode solves every tangent of
    the run; with Bunch-Kaufman's 2x2 pivots three missed 1e-6 (up to 1.9e1) and went to
    LU, as on the template with fitted tissue interfaces."""
    import logging

    from brainbulge.geometry.brain.labels import TISSUES
    from brainbulge.studies.craniectomy import run_brain
    from toy_brain import toy_mesh

    bm = toy_mesh(tmp_path / "mesh")
    code = {name: c for c, name in TISSUES.items()}
    island = [839, 428]
    csf_nodes = np.unique(bm.tets[bm.tissue == code["csf"]])
    assert np.all(bm.tissue[island] == code["white"])  # (the toy mesh as it was measured)
    assert np.isin(bm.tets[island[1]], bm.tets[island[0]]).sum() == 1
    assert not np.isin(bm.tets[island], csf_nodes).any()
    bm.tissue[island] = code["csf"]
    config = {"flap": "custom", "flap_centre_mm": [-40.0, 20.0, 40.0],
              "flap_diameter_mm": 70.0, "swell": "left", "steps": 1}
    with caplog.at_level(logging.DEBUG, logger="brainbulge.solver.linear.direct"):
        summary = run_brain(config, tmp_path / "run", brain_mesh=bm)
    assert summary["converged"]
    misses = [r.getMessage() for r in caplog.records if "PARDISO symmetric" in r.getMessage()]
    assert not misses, misses

"""The Newton tangent with the contact curvature of point contacts, on the coarse capped ball
of contact_cases."""

from __future__ import annotations

from brainbulge.solver import NewtonSolver, SolverOptions
from contact_cases import _forms

OPTIONS = SolverOptions(steps=2)


def test_tangent_with_contact_curvature_matches_the_plain_scipy_construction() -> None:
    """The tangent built by plans (curvature added on the pattern, free part gathered) is
    the one SciPy builds, ``(K - sum_c P^T H P)[free][:, free]``, at a state with pressed
    points, and stays so for a second tangent (the plans reused)."""
    import scipy.sparse as sp

    coarse, _ = _forms()
    solver = NewtonSolver(coarse, OPTIONS)
    assert solver.solve().converged
    x = coarse.gfu.vec
    pc = coarse.point_contacts[0]
    assert (pc.lam > 0).sum() > 10
    for _ in range(2):
        K = solver.equations.tangent(x)
        mat = coarse.a.mat
        ref = sp.csr_matrix(mat.CSR(), shape=(mat.height, mat.width)) - pc.curvature()
        ref = ref[solver.equations.free][:, solver.equations.free]
        assert pc.curvature().nnz > 0
        assert abs(K - ref).max() <= 1e-12 * abs(ref).max()

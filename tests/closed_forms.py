"""Shared checks of the closed-form residual and tangent (:mod:`brainbulge.solver.fast`)
against the plain path through NGSolve's automatic differentiation."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from brainbulge.solver import MixedForm, NewtonSolver, SolverOptions


def assert_same_newton_path(make_form: Callable[[], MixedForm], closed_type: type) -> None:
    """Newton on ``make_form()`` with the closed form (of ``closed_type``) and without it
    (NGSolve's ``Apply`` and ``AssembleLinearization``): the same iterations, states equal
    to 1e-8."""
    results = []
    for closed in (True, False):
        form = make_form()
        ns = NewtonSolver(form, SolverOptions(steps=2, tolerance=1e-10, closed_form=closed))
        kind = ns.equations.closed
        assert isinstance(kind, closed_type) if closed else kind is None
        res = ns.solve()
        assert res.converged
        results.append((res.newton_iterations, form.gfu.vec.FV().NumPy().copy()))
    (it1, x1), (it2, x2) = results
    assert it1 == it2
    assert np.abs(x1 - x2).max() <= 1e-8 * np.abs(x2).max()


def assert_local_systems_agree(local, X: np.ndarray) -> None:  # noqa: ANN001 - LocalProblem
    """A hotspot's local residual and tangent at ``X`` from the closed form's element
    systems equal those from NGSolve's integrators, element by element, to 1e-12."""
    assert local.closed is not None and len(local.elements) > 5
    lam = local.multipliers()
    R, K = local.assemble(X, lam, tangent=True)
    local.closed = None  # NGSolve's integrators, element by element
    R_ad, K_ad = local.assemble(X, lam, tangent=True)
    assert np.abs(R_ad).max() > 0
    assert np.abs(R - R_ad).max() <= 1e-12 * np.abs(R_ad).max()
    assert abs(K - K_ad).max() <= 1e-12 * abs(K_ad).max()


def assert_free_pattern_is_the_free_part(form: MixedForm, mt, closed_type: type) -> None:  # noqa: ANN001
    """The tangent assembled on the free DOFs' pattern (``closed_type(form, free)``, as
    Newton's equations make it) equals the free rows and columns of the full one (``mt``'s,
    on all DOFs): the same pattern, the same values."""
    free = np.flatnonzero(np.array(list(form.fes.FreeDofs(True)), dtype=bool))
    assert not np.isin(mt.ext_dofs, free).all()  # fixed DOFs among the elements' DOFs
    x = form.gfu.vec.FV().NumPy()
    ref = mt.assemble(x)[free][:, free]
    ref.sort_indices()
    K = closed_type(form, free).assemble(x)
    assert K.shape == (len(free), len(free)) and K.has_sorted_indices
    assert np.array_equal(K.indptr, ref.indptr) and np.array_equal(K.indices, ref.indices)
    assert np.array_equal(K.data, ref.data) and np.abs(K.data).max() > 0
    assert not (K.indices.flags.writeable or K.indptr.flags.writeable)  # shared by plans

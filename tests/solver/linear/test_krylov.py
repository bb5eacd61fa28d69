"""The block-preconditioned Krylov solver against the direct one on a small 3D MINI problem.

A soft swelling inclusion (CSF-like, mu 10x smaller) in a stiff matrix, at a swollen state
reached by Newton's method: the displacement block of that tangent is indefinite there.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg  # noqa: F401 - sp.linalg

from brainbulge.errors import ConvergenceError
from brainbulge.model import Problem
from brainbulge.solver import MixedForm, NewtonSolver, SolverOptions
from brainbulge.solver.linear.direct import PardisoSolver
from brainbulge.solver.linear.krylov import BlockKrylovSolver
from brainbulge.solver.linear.layout import displacement_layout, free_dofs
from brainbulge.solver.options import KrylovOptions
from inclusion_cases import STIFF, _inclusion_problem

# several AMG levels even on this small mesh
AMG = {"max_coarse": 30}


def _direct(K, r):
    return PardisoSolver().solve(K, r)


def test_layout_matches_ngsolve_ordering(swollen) -> None:
    """VectorH1 (order 1 + bubbles) numbers x of all vertices and bubbles, then y, then z."""
    form, ns, _, _ = swollen
    lay = displacement_layout(form)
    V = form.fes.components[0]
    per_comp = V.ndof // 3
    free_u = ns.equations.free[ns.equations.is_u_free]
    np.testing.assert_array_equal(lay.component, free_u // per_comp)
    np.testing.assert_array_equal(lay.vertex, free_u % per_comp)
    assert per_comp == form.mesh.nv + form.mesh.ne  # one bubble per tet and component


def _rest_stiffness(form):
    """The displacement block of the tangent at the undeformed, unloaded state (``p = 0``):
    the linearised isochoric stiffness, whose kernel holds the rigid motions."""
    ns = NewtonSolver(form, SolverOptions())
    form.set_load(0.0)
    K = ns.equations.tangent(form.gfu.vec)
    return K[ns.equations.is_u_free][:, ns.equations.is_u_free]


def test_rigid_modes_in_the_kernel_of_the_rest_stiffness(box3d) -> None:
    # straight-sided tets (the inclusion mesh is curved: P1 there is not linear in x)
    problem = Problem(box3d, {"tissue": STIFF}, {"tissue": 1.1})
    form = MixedForm(problem, element="mini")  # no boundary condition: all DOFs free
    A = _rest_stiffness(form)
    modes = displacement_layout(form).rigid_body_modes()
    assert modes.shape[1] == 6
    for m in modes.T:
        assert np.linalg.norm(A @ m) <= 1e-10 * abs(A).max() * np.linalg.norm(m)


@pytest.fixture(scope="module")
def swollen_taylor_hood():
    """As ``swollen``, with Taylor-Hood (hierarchical P2 / P1): a tangent at load 0.7 and
    the residual at load 1, over the free DOFs."""
    form = MixedForm(_inclusion_problem(), element="taylor-hood")
    ns = NewtonSolver(form, SolverOptions(tolerance=1e-10))
    for load in (0.4, 0.7):
        form.set_load(load)
        assert ns.newton().converged
    K = ns.equations.tangent(form.gfu.vec)
    form.set_load(1.0)
    return form, ns, K, ns.equations.residual(form.gfu.vec)[ns.equations.free].copy()


def test_taylor_hood_layout_and_rigid_modes(box3d) -> None:
    """P2 edge DOFs have no vertex (-1), the component of their block of NGSolve's
    ordering, and zero rigid-motion coefficients: the modes are still in the kernel."""
    form = MixedForm(Problem(box3d, {"tissue": STIFF}, {"tissue": 1.1}), element="taylor-hood")
    lay = displacement_layout(form)
    V = form.fes.components[0]
    per_comp = V.ndof // 3
    assert np.count_nonzero(lay.linear) == 3 * form.mesh.nv
    assert np.count_nonzero(~lay.linear) == 3 * form.mesh.nedge
    np.testing.assert_array_equal(lay.component, np.arange(V.ndof) // per_comp)
    modes = lay.rigid_body_modes()
    assert np.all(modes[~lay.linear] == 0)
    A = _rest_stiffness(form)
    for m in modes.T:
        assert np.linalg.norm(A @ m) <= 1e-10 * abs(A).max() * np.linalg.norm(m)


def test_taylor_hood_two_level_cycle_matches_direct_solve(swollen_taylor_hood) -> None:
    form, _, K, r = swollen_taylor_hood
    solver = BlockKrylovSolver.from_form(form, rtol=1e-10, amg=AMG)
    x = solver.solve(K, r)
    x_direct = _direct(K, r)
    assert np.linalg.norm(x - x_direct) <= 1e-6 * np.linalg.norm(x_direct)
    assert solver.stats.iterations[-1] <= 100  # 50 here


def _displacement_cycle(form, K):
    """The Krylov solver's displacement preconditioner set up on the (symmetric)
    displacement block ``A`` of ``K`` (which it cuts out of ``K``): ``(cycle, A)``."""
    solver = BlockKrylovSolver.from_form(form, rtol=1e-10, amg=AMG)
    A = K[solver.iu][:, solver.iu].tocsr()
    assert abs(A - A.T).max() <= 1e-12 * abs(A).max()
    solver.amg_u.setup(K)
    return solver.amg_u, A


def _asymmetry(cycle, a: np.ndarray, b: np.ndarray) -> float:
    """``|z(a) . b - a . z(b)| / (|z(a)| |b|)``: 0 for a symmetric preconditioner ``z``."""
    za, zb = cycle(a), cycle(b)
    return abs(za @ b - a @ zb) / (np.linalg.norm(za) * np.linalg.norm(b))


def test_taylor_hood_two_level_cycle_is_symmetric(swollen_taylor_hood) -> None:
    """Forward sweep, P1 V-cycle (itself symmetric), backward sweep: ``z(a) . b = a .
    z(b)``."""
    form, ns, K, _ = swollen_taylor_hood
    cycle, A = _displacement_cycle(form, K)
    a, b = np.random.default_rng(1).standard_normal((2, A.shape[0]))
    assert _asymmetry(cycle, a, b) <= 1e-10
    assert np.linalg.norm(cycle(a) - cycle(a)) == 0  # no state kept between applications


def test_displacement_cycle_is_symmetric_after_setup_and_update(swollen) -> None:
    """Symmetric Gauss-Seidel sweeps on both sides of an exact coarse solve: ``z(a) . b =
    a . z(b)``, also once ``update`` has put a new matrix on the finest level (pyamg's own
    ``change_solve_matrix`` would bring back a one-sided forward sweep there)."""
    form, ns, K, _ = swollen
    cycle, A = _displacement_cycle(form, K)
    assert len(cycle.ml.levels) > 1
    a, b = np.random.default_rng(2).standard_normal((2, A.shape[0]))
    stiffer = np.where(ns.equations.is_u_free, 0.1 * K.diagonal(), 0.0)  # on A's diagonal
    for M in (K, (K + sp.diags(stiffer)).tocsr()):
        cycle.update(M)
        assert _asymmetry(cycle, a, b) <= 1e-10
    # a one-sided smoother (forward on both sides) is not symmetric: the check can fail
    forward = ("gauss_seidel", {"sweep": "forward"})
    cycle.options = {**cycle.options, "presmoother": forward, "postsmoother": forward}
    cycle.setup(K)
    assert len(cycle.ml.levels) > 1
    assert _asymmetry(cycle, a, b) > 1e-6


def test_matches_direct_solve(swollen) -> None:
    form, ns, K, r = swollen
    solver = BlockKrylovSolver.from_form(form, rtol=1e-10, amg=AMG)
    x = solver.solve(K, r)
    x_direct = _direct(K, r)
    assert np.linalg.norm(x - x_direct) <= 1e-6 * np.linalg.norm(x_direct)
    assert solver.stats.residuals[-1] <= 1e-10
    # an effective preconditioner (AMG hierarchies, not a single level): 35 here
    assert solver.stats.iterations[-1] <= 60


def test_true_residual_check_raises_when_the_budget_is_too_small(swollen) -> None:
    form, _, K, r = swollen
    solver = BlockKrylovSolver.from_form(form, KrylovOptions(max_iterations=3), rtol=1e-10,
                                         amg=AMG)
    with pytest.raises(ConvergenceError, match="relative residual"):
        solver.solve(K, r)
    # a failed solve rebuilds the hierarchy next time; a looser tolerance is met
    solver.maxiter = 500
    x = solver.solve(K, r, rtol=1e-4)
    assert np.linalg.norm(r - K @ x) <= 1e-4 * np.linalg.norm(r)
    assert solver.stats.setups == 2


def test_setup_is_reused_across_right_hand_sides_and_matrices(swollen) -> None:
    form, ns, K1, r1 = swollen
    solver = BlockKrylovSolver.from_form(form, rtol=1e-10, amg=AMG)
    x1 = solver.solve(K1, r1)
    r2 = np.random.default_rng(0).standard_normal(len(r1)) * np.abs(r1).max()
    x2 = solver.solve(K1, r2)
    # the tangent one Newton step later: a changed matrix, same hierarchy
    x = form.gfu.vec
    saved = x.FV().NumPy().copy()
    dx = x.CreateVector()
    dx.FV().NumPy()[:] = 0
    dx.FV().NumPy()[ns.equations.free] = x1
    dx.data += form.a.harmonic_extension * dx
    x.data -= dx
    K2 = ns.equations.tangent(x)
    x.FV().NumPy()[:] = saved
    assert abs(K2 - K1).max() > 1e-3 * abs(K1).max()
    x3 = solver.solve(K2, r1)
    assert solver.stats.setups == 1
    for K, r, sol in ((K1, r2, x2), (K2, r1, x3)):
        ref = _direct(K, r)
        assert np.linalg.norm(sol - ref) <= 1e-6 * np.linalg.norm(ref)
    # refresh() rebuilds the hierarchies at the next solve
    solver.solve(K2, r1)
    assert solver.stats.setups == 1
    solver.refresh()
    solver.solve(K2, r1)
    assert solver.stats.setups == 2


def test_a_rebuild_drops_the_old_hierarchies_first_and_solves_as_a_fresh_solver(
        swollen, monkeypatch) -> None:
    """A refresh builds the AMG hierarchies without the old ones alive (two displacement
    hierarchies at once had been ~1 GB more at 1.40M tets); it solves as the same steps
    unwatched do, and as the direct solver to the tolerance."""
    import pyamg

    form, ns, K1, r1 = swollen
    K2 = (K1 + sp.diags(np.where(ns.equations.is_u_free, 0.3 * np.abs(K1.diagonal()), 0.0))
          ).tocsr()
    solver = BlockKrylovSolver.from_form(form, rtol=1e-10, amg=AMG)
    solver.solve(K1, r1)
    old = [solver.amg_u.ml, solver.amg_p.ml]
    held = []
    build = pyamg.smoothed_aggregation_solver

    def watched(*args, **kwargs):
        held.append(any(ml is o for ml in (solver.amg_u.ml, solver.amg_p.ml) for o in old))
        return build(*args, **kwargs)

    monkeypatch.setattr(pyamg, "smoothed_aggregation_solver", watched)
    solver.refresh()
    rebuilt = solver.solve(K2, r1)
    assert solver.stats.setups == 2
    assert held == [False, False]  # no old hierarchy kept while one is built
    monkeypatch.setattr(pyamg, "smoothed_aggregation_solver", build)
    again = BlockKrylovSolver.from_form(form, rtol=1e-10, amg=AMG)
    again.solve(K1, r1)
    again.refresh()
    x = again.solve(K2, r1)  # (the same to the solves' tolerance: runs differ by ~1e-12)
    assert np.linalg.norm(rebuilt - x) <= 1e-10 * np.linalg.norm(x)
    ref = _direct(K2, r1)
    assert np.linalg.norm(rebuilt - ref) <= 1e-6 * np.linalg.norm(ref)


def test_schur_matrix_is_kept_until_the_next_load_step(swollen, monkeypatch) -> None:
    """``S~`` and its AMG are built once per load step (``new_load_step``): a changed
    displacement block within a load step keeps them, and the solves stay exact to the
    tolerance."""
    form, ns, K1, r1 = swollen
    K2 = K1 + sp.diags(np.where(ns.equations.is_u_free, 0.3 * np.abs(K1.diagonal()), 0.0))
    solver = BlockKrylovSolver.from_form(form, rtol=1e-10, amg=AMG)
    solver.solve(K1, r1)
    x2 = solver.solve(K2, r1)
    assert solver.stats.schur_builds == 1
    ref = _direct(K2, r1)
    assert np.linalg.norm(x2 - ref) <= 1e-6 * np.linalg.norm(ref)
    import brainbulge.solver.linear.krylov as krylov

    trims = []
    monkeypatch.setattr(krylov, "release_free_memory", lambda: trims.append(1))
    solver.new_load_step()
    assert trims == [1]  # a new load step gives the heap's free pages back
    x2 = solver.solve(K2, r1)
    assert solver.stats.schur_builds == 2 and solver.stats.setups == 1
    assert np.linalg.norm(x2 - ref) <= 1e-6 * np.linalg.norm(ref)


def test_an_initial_guess_saves_iterations_and_a_bad_one_is_dropped(swollen) -> None:
    """A loose solution as the guess of a tighter solve (the Newton retry): fewer
    iterations than from zero, the same tolerance relative to |r|; a guess worse than zero
    costs nothing."""
    form, _, K, r = swollen
    solver = BlockKrylovSolver.from_form(form, amg=AMG)
    loose = solver.solve(K, r, rtol=1e-3)
    tight_from_zero = solver.solve(K, r, rtol=1e-8)
    tight_from_loose = solver.solve(K, r, rtol=1e-8, x0=loose)
    its = solver.stats.iterations
    assert its[2] < its[1]
    assert np.linalg.norm(r - K @ tight_from_loose) <= 1e-8 * np.linalg.norm(r)
    assert np.linalg.norm(tight_from_loose - tight_from_zero) <= 1e-5 * np.linalg.norm(
        tight_from_zero)
    assert solver.solve(K, r, rtol=1e-3, x0=tight_from_zero) is not tight_from_zero
    assert its[3] == 0  # already converged: returned at once
    solver.solve(K, r, rtol=1e-8, x0=-1e3 * tight_from_zero)  # worse than zero: ignored
    assert its[4] == its[1]


def test_zero_right_hand_side(swollen) -> None:
    form, _, K, r = swollen
    solver = BlockKrylovSolver.from_form(form, amg=AMG)
    assert not np.any(solver.solve(K, np.zeros_like(r)))
    assert free_dofs(form).size == K.shape[0]


def test_extra_constraint_rows_of_an_active_set(swollen) -> None:
    """``[[K, -G^T], [-G, 0]]`` with constraint rows ``G`` on a few displacement DOFs (as the
    contact multipliers of the active set), a different number at each solve."""
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    form, ns, K, r = swollen
    solver = BlockKrylovSolver.from_form(form, rtol=1e-10, amg=AMG)
    iu = np.flatnonzero(ns.equations.is_u_free)
    rng = np.random.default_rng(1)
    for n_c in (5, 12):
        cols = rng.choice(iu, n_c, replace=False)
        G = sp.csr_matrix((rng.uniform(0.5, 1.0, n_c), (np.arange(n_c), cols)),
                          shape=(n_c, K.shape[0]))
        K_aug = sp.bmat([[K, -G.T], [-G, None]], format="csr")
        r_aug = np.concatenate([r, 1e-3 * rng.standard_normal(n_c)])
        x = solver.solve(K_aug, r_aug)
        ref = spla.spsolve(K_aug.tocsc(), r_aug)  # pypardiso rejects the empty diagonal
        assert np.linalg.norm(x - ref) <= 1e-6 * np.linalg.norm(ref)
    assert solver.stats.setups == 1


def test_augmented_active_set_system_has_the_same_solution(swollen) -> None:
    """``K + r B^T B`` with ``b - r B^T c`` (what both linear solvers get) solves the plain
    saddle point ``[[K, -B^T], [-B, 0]] [dx, dlam] = [b, c]`` exactly."""
    from brainbulge.solver.contact.saddle import augmented

    form, ns, K, r = swollen
    rng = np.random.default_rng(3)
    iu = np.flatnonzero(ns.equations.is_u_free)
    rows = rng.choice(iu, size=12, replace=False)
    B = sp.csr_matrix((rng.uniform(0.5, 2.0, 12), (np.arange(12), rows)), shape=(12, K.shape[0]))
    c = rng.normal(size=12)
    plain = sp.bmat([[K, -B.T], [-B, None]], format="csr")
    ref = sp.linalg.spsolve(plain.tocsc(), np.concatenate([r, c]))
    Ka, ba = augmented(K, r, B, c, ns.equations.is_u_free)
    aug = sp.bmat([[Ka, -B.T], [-B, None]], format="csr")
    x = sp.linalg.spsolve(aug.tocsc(), np.concatenate([ba, c]))
    np.testing.assert_allclose(x, ref, rtol=1e-8, atol=1e-10 * np.abs(ref).max())
    assert not np.allclose(Ka.toarray(), K.toarray())  # the matrix did change


def _nodal_constraints(form, ns, K, m: int, seed: int = 5):
    """``m`` constraint rows ``B_i = A_i n_i^T`` on distinct vertices (unit normals ``n_i``),
    as the P1 contact points give them, and a right-hand side ``c``."""
    rng = np.random.default_rng(seed)
    layout = displacement_layout(form, ns.equations.free)
    iu = np.flatnonzero(ns.equations.is_u_free)
    v_all, count = np.unique(layout.vertex, return_counts=True)
    verts = rng.choice(v_all[count == layout.dim], size=m, replace=False)  # wholly free
    rows, cols, vals = [], [], []
    for i, v in enumerate(verts):
        n = rng.normal(size=layout.dim)
        n *= rng.uniform(0.5, 2.0) / np.linalg.norm(n)
        for comp in range(layout.dim):
            rows.append(i)
            cols.append(iu[(layout.vertex == v) & (layout.component == comp)][0])
            vals.append(n[comp])
    B = sp.csr_matrix((vals, (rows, cols)), shape=(m, K.shape[0]))
    return B, rng.normal(size=m)


def test_nodal_elimination_solves_the_active_set_saddle_point(swollen) -> None:
    """Eliminating nodal normal constraints (projected system, same size, no multiplier
    rows) gives the plain saddle point's displacements, pressures and multipliers, with the
    direct solver and with GMRES + AMG on the projected matrix."""
    from brainbulge.solver.contact.saddle import NodalElimination

    form, ns, K, r = swollen
    B, c = _nodal_constraints(form, ns, K, m=15)
    assert NodalElimination.applies(B)
    assert not NodalElimination.applies(sp.vstack([B, B[:1]]).tocsr())  # a shared DOF
    plain = sp.bmat([[K, -B.T], [-B, None]], format="csr")
    ref = sp.linalg.spsolve(plain.tocsc(), np.concatenate([r, c]))
    K0 = K.copy()
    elim = NodalElimination(K, B, c, ns.equations.is_u_free)
    Kp, bp = elim.system(r)
    assert Kp.shape == K.shape
    np.testing.assert_allclose(abs(Kp - Kp.T).max(), 0.0, atol=1e-12 * abs(Kp).max())
    x = elim.recover(_direct(Kp, bp))
    np.testing.assert_allclose(x, ref, rtol=1e-7, atol=1e-9 * np.abs(ref).max())
    assert np.abs(ref[K.shape[0]:]).min() > 0  # the multipliers are not trivially zero
    assert (K != K0).nnz == 0  # projected in place, and back after recover
    krylov = BlockKrylovSolver.from_form(form)
    Kp, bp = elim.system(r)
    # 1e-12: the pressures are sensitive (1e-10 left 3e-5 relative errors with schur_drop)
    xk = elim.recover(krylov.solve(Kp, bp, rtol=1e-12))
    np.testing.assert_allclose(xk, ref, rtol=1e-5, atol=1e-7 * np.abs(ref).max())

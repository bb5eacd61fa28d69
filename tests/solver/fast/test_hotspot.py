"""Nonlinear elimination of a residual hotspot (:mod:`brainbulge.solver.fast.hotspot`) on the
capped ball of test_point_contact (MINI, a swelling sphere sliding in a spherical skull).

From the converged state with one vertex displaced, the residual sits at that vertex; the
local solve must bring the state back (the global residual to ~1e-5 of where it was) while
moving no DOF outside the patch; its tangent must be the derivative of its residual; a
residual spread over the body, a vertex pressed on the skull, and a local result that raises
the global residual must leave the state as it was.
"""

from __future__ import annotations

import numpy as np
import pytest

from brainbulge.geometry.ngsolve_arrays import vertex_coordinates, vertex_dofs
from brainbulge.solver import NewtonSolver, SolverOptions, mixed
from brainbulge.solver.fast.hotspot import HotspotRelaxation, LocalProblem
from brainbulge.solver.mixed import MixedForm
from brainbulge.solver.options import HotspotOptions
from contact_cases import A, _capped_ball


@pytest.fixture(scope="module", params=["split", "one expression"])
def converged(request):
    """Converged, with the energy split per pressure zone (an integrator per region, as
    interpreted or >= 200k-tet forms) or as one expression (one integrator everywhere)."""
    _, problem = _capped_ball(h=0.15, h_inclusion=A / 3, cap_deg=35)
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(mixed, "split_energy", lambda *args: request.param == "split")
        form = MixedForm(problem, element="mini")
    assert len(form.a.integrators) == (2 if request.param == "split" else 1)
    solver = NewtonSolver(form, SolverOptions(steps=2))
    assert solver.solve().converged
    x_conv = form.gfu.vec.FV().NumPy().copy()
    lam_conv = [pc.lam.copy() for pc in form.point_contacts]
    return form, solver, x_conv, lam_conv


@pytest.fixture
def state(converged):
    """The converged state, restored before each test."""
    form, solver, x_conv, lam_conv = converged
    form.gfu.vec.FV().NumPy()[:] = x_conv
    for pc, lam in zip(form.point_contacts, lam_conv, strict=True):
        pc.lam = lam.copy()
    solver.equations.residual(form.gfu.vec)
    return form, solver, x_conv


def _displace(form, point, shift) -> int:
    """Displace the mesh vertex nearest ``point`` by ``shift``; its number."""
    v = int(np.argmin(np.linalg.norm(vertex_coordinates(form.mesh) - point, axis=1)))
    dofs = vertex_dofs(form.fes.components[0], form.mesh)[v]
    form.gfu.vec.FV().NumPy()[dofs] += shift
    return v


def test_relax_returns_a_displaced_vertex_to_equilibrium(state) -> None:
    form, solver, x_conv = state
    x = form.gfu.vec
    v = _displace(form, [0.3, 0.3, 0.3], [0.02, -0.01, 0.015])
    norm = solver.equations.scaled_norm(solver.equations.residual(x))
    relaxation = HotspotRelaxation(solver.equations, HotspotOptions(rings=1))
    assert list(relaxation.hotspot(solver.equations.res.FV().NumPy())) == [v]
    new = relaxation.relax(x, norm)
    assert norm > 1e-2 and new < 1e-3 * norm
    rec = relaxation.records[-1]
    assert rec.kept and rec.hotspot == 1 and 1 <= rec.iterations <= 5
    # only the patch moved: every DOF outside it kept its value to the bit
    d = x.FV().NumPy() - x_conv
    moved = np.flatnonzero(d)
    assert 0 < len(moved) <= len(relaxation.last_dofs) < 0.5 * len(d)
    assert set(moved) <= set(relaxation.last_dofs)
    u = form.fes.Range(0)  # back where it was (the patch's border is not equilibrated)
    dofs = vertex_dofs(form.fes.components[0], form.mesh)[v]
    assert np.abs(d[dofs]).max() < 0.02 * 0.02
    assert np.abs(d[u.start : u.stop]).max() < 0.1 * 0.02
    assert new == pytest.approx(solver.equations.scaled_norm(solver.equations.res.FV().NumPy()))


def _local_problem(form, solver, v: int) -> LocalProblem:
    """The local problem of the patch ``v`` + one ring, its active contact points included."""
    return HotspotRelaxation(solver.equations, HotspotOptions(rings=1)).local_problem(np.array([v]))


@pytest.mark.parametrize("where", ["interior", "on the skull"])
def test_local_tangent_is_the_derivative_of_the_local_residual(state, where) -> None:
    form, solver, _ = state
    x = form.gfu.vec
    if where == "interior":
        v = _displace(form, [0.3, 0.3, 0.3], [0.02, -0.01, 0.015])
    else:
        pc = form.point_contacts[0]
        v = _displace(form, pc.X[np.argmax(pc.lam)], [0.003, -0.002, 0.001])
    local = _local_problem(form, solver, v)
    assert (local.n_lam > 0) == (where == "on the skull")
    X = x.FV().NumPy().copy()
    lam = local.multipliers()
    R, K = local.assemble(X, lam, tangent=True)
    rng = np.random.default_rng(1)
    n = len(local.dofs)
    dy = rng.standard_normal(n + local.n_lam) * 1e-6
    dy[:n] *= np.where(local.scale > 1e-3, 1, 1e3)  # pressures ~1e3 x displacements
    dy[n:] *= 1e3 * max(1.0, abs(lam).max(initial=0))
    Xp, Xm = X.copy(), X.copy()
    Xp[local.dofs] += dy[:n]
    Xm[local.dofs] -= dy[:n]
    fd = (local.assemble(Xp, lam + dy[n:], tangent=False)[0]
          - local.assemble(Xm, lam - dy[n:], tangent=False)[0]) / 2
    assert np.linalg.norm(fd - K @ dy) < 1e-6 * np.linalg.norm(K @ dy)
    # the local residual is the global one at the local DOFs (contact forces included)
    solver.equations.residual(x)
    assert np.allclose(R[:n], solver.equations.res.FV().NumPy()[local.dofs], rtol=0,
                       atol=1e-10 * abs(R[:n]).max())


def test_a_spread_residual_has_no_hotspot(state) -> None:
    form, solver, _ = state
    x = form.gfu.vec
    eq = solver.equations
    free = eq.free[eq.is_u_free]  # (bubbles are not free DOFs of the condensed form)
    noise = np.random.default_rng(2).standard_normal(len(free))
    x.FV().NumPy()[free] += 1e-4 * noise
    norm = solver.equations.scaled_norm(solver.equations.residual(x))
    relaxation = HotspotRelaxation(solver.equations)
    assert relaxation.hotspot(solver.equations.res.FV().NumPy()) is None
    before = x.FV().NumPy().copy()
    assert relaxation.relax(x, norm) == norm
    assert np.array_equal(x.FV().NumPy(), before) and not relaxation.records


def test_a_vertex_pressed_on_the_skull_is_relaxed_back_onto_it(state) -> None:
    form, solver, x_conv = state
    pc = form.point_contacts[0]
    i = int(np.argmax(pc.lam))
    lam_conv = pc.lam[i]
    X = pc.X[i]
    v = _displace(form, X, -0.01 * X / np.linalg.norm(X))  # off the skull, inwards
    x = form.gfu.vec
    norm = solver.equations.scaled_norm(solver.equations.residual(x))
    assert pc.g[i] > 5e-3
    relaxation = HotspotRelaxation(solver.equations)
    assert v in relaxation.hotspot(solver.equations.res.FV().NumPy())
    new = relaxation.relax(x, norm)
    assert relaxation.records[-1].kept and relaxation.last_patch[v]
    assert new < 1e-2 * norm
    assert abs(pc.g[i]) < 1e-6  # back on the skull (pc.update by the residual)
    assert pc.lam[i] == pytest.approx(lam_conv, rel=0.05)
    dofs = vertex_dofs(form.fes.components[0], form.mesh)[v]
    assert np.abs(x.FV().NumPy()[dofs] - x_conv[dofs]).max() < 0.02 * 0.01


def test_a_local_result_that_raises_the_residual_is_not_kept(state, monkeypatch) -> None:
    form, solver, _ = state
    x = form.gfu.vec
    _displace(form, [0.3, 0.3, 0.3], [0.02, -0.01, 0.015])
    norm = solver.equations.scaled_norm(solver.equations.residual(x))
    before = x.FV().NumPy().copy()

    def overshoot(self, X, target, max_iterations):  # a "solution" far off
        X[self.dofs] += 0.05
        return 1

    monkeypatch.setattr(LocalProblem, "solve", overshoot)
    relaxation = HotspotRelaxation(solver.equations)
    assert relaxation.relax(x, norm) == pytest.approx(norm, rel=1e-12)
    assert not relaxation.records[-1].kept
    assert np.array_equal(x.FV().NumPy(), before)
    kept_residual = solver.equations.res.FV().NumPy().copy()  # restored, not evaluated again
    assert np.allclose(kept_residual, solver.equations.residual(x), rtol=0,
                       atol=1e-12 * np.abs(kept_residual).max())


def test_the_same_solution_with_and_without_relaxation(converged) -> None:
    form, solver, x_conv, _ = converged
    assert solver.relaxation is not None and solver.relaxation.records  # it acted
    _, problem = _capped_ball(h=0.15, h_inclusion=A / 3, cap_deg=35)
    plain = MixedForm(problem, element="mini")
    off = NewtonSolver(plain, SolverOptions(steps=2, hotspot_relaxation=False))
    assert off.relaxation is None  # the plain path
    assert off.solve().converged
    u = form.fes.Range(0)
    d = plain.gfu.vec.FV().NumPy() - x_conv
    assert np.abs(d[u.start : u.stop]).max() < 1e-6

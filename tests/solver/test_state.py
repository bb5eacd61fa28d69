"""The solve's state (:mod:`brainbulge.solver.state`) and Newton as a function returning a
result (:func:`brainbulge.solver.newton.newton`), on the coarse capped ball of contact_cases
(contact pressures, so every part of the state is exercised)."""

from __future__ import annotations

import numpy as np

from brainbulge.solver import NewtonSolver, SolverOptions
from brainbulge.solver.newton import NewtonObserver, Reason, newton
from brainbulge.solver.state import State
from contact_cases import _forms

OPTIONS = SolverOptions(steps=2)


def _arrays(state: State) -> tuple[np.ndarray, list[np.ndarray], float]:
    return (state.x.FV().NumPy().copy(), [lam.copy() for lam in state.multipliers],
            state.load)


def test_a_snapshot_restores_x_lambda_and_the_load_exactly() -> None:
    """snapshot -> change everything -> restore gives back the same bits; a snapshot is a
    copy (changing the state does not change it); reset is the undeformed body at t = 0."""
    form, _ = _forms()
    assert NewtonSolver(form, OPTIONS).solve().converged
    state = State(form)
    x0, lam0, t0 = _arrays(state)
    assert t0 == 1.0 and any(np.any(lam > 0) for lam in lam0)
    snap = state.snapshot()
    state.x.FV().NumPy()[:] += 0.1
    state.set_multipliers([lam + 1.0 for lam in state.multipliers])
    form.set_load(0.3)
    assert not np.array_equal(snap.x.FV().NumPy(), state.x.FV().NumPy())
    state.restore(snap)
    x1, lam1, t1 = _arrays(state)
    assert np.array_equal(x1, x0) and t1 == t0
    assert all(np.array_equal(a, b) for a, b in zip(lam1, lam0, strict=True))
    state.set_multipliers([lam + 1.0 for lam in state.multipliers])
    state.restore(snap, multipliers=False)  # x and t only
    assert all(np.array_equal(a, b + 1.0) for a, b in zip(state.multipliers, lam0, strict=True))
    state.reset()
    x2, lam2, t2 = _arrays(state)
    assert not x2.any() and t2 == 0.0 and not any(lam.any() for lam in lam2)


class _Count(NewtonObserver):
    def __init__(self) -> None:
        self.norms: list[float] = []
        self.steps: list[float] = []

    def iteration(self, it: int, norm: float) -> None:
        self.norms.append(norm)

    def step(self, s: float, eq, eta) -> None:
        self.steps.append(s)


def test_newton_returns_its_result_and_the_step_limit_scales_every_update() -> None:
    """One Newton solve at half load: the result holds each iterate's residual (as the
    observer saw them), the reason and no failure site; nothing is left on the solver. A
    step limit of 1/2 halves every update before it is taken: the residual then falls
    only linearly (~1/2 per iteration), so the solve takes more iterations to the same
    tolerance and ends at the same state."""
    results, states = {}, {}
    for name, limit in (("full", None), ("half", lambda x, dx: 0.5)):
        form, _ = _forms()
        solver = NewtonSolver(form, SolverOptions(max_iterations=60))
        form.set_load(0.5)
        watch = _Count()
        res = newton(solver.equations, solver.opt, limit_step=limit, observers=[watch])
        assert res.converged and res.reason is Reason.CONVERGED and res.site is None
        assert list(res.residuals) == watch.norms and len(res.residuals) == res.iterations + 1
        assert res.norm <= solver.opt.newton.tolerance
        results[name], states[name] = res, form.gfu.vec.FV().NumPy().copy()
        if limit is not None:
            assert all(s == 1.0 for s in watch.steps)  # the halved update is accepted whole
            ratios = np.array(res.residuals[1:6]) / np.array(res.residuals[:5])
            assert np.all(ratios > 0.4) and np.all(ratios < 0.8)  # -> 1/2: linear
            assert abs(ratios[-1] - 0.5) < 0.05
    assert results["half"].iterations > results["full"].iterations + 5
    scale = np.abs(states["full"]).max()
    assert np.abs(states["half"] - states["full"]).max() < 1e-6 * scale


def test_a_failed_newton_solve_says_why_and_where() -> None:
    """One iteration allowed: the result is not converged, its reason MAX_ITERATIONS with the
    user's phrase, and a finite failure site."""
    form, _ = _forms()
    solver = NewtonSolver(form, SolverOptions(max_iterations=1))
    form.set_load(1.0)
    res = solver.newton()
    assert not res.converged and res.reason is Reason.MAX_ITERATIONS
    assert res.detail == "max_iterations = 1 reached" and res.iterations == 1
    assert res.site is not None and np.all(np.isfinite(res.site))

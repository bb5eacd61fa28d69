"""Newton from a given start state (another flap's solution on the same mesh), else the
load ramp from ``Js = 1``.

A start at full load converges in a few Newton iterations when it is close (a smaller flap
at the same centre), or not at all; so Newton from it runs with a small budget
(:class:`~brainbulge.solver.options.WarmStartOptions`: ``max_iterations`` Newton and
``krylov_iterations`` GMRES iterations per linear solve). If that does not converge, the
state is reset and the load ramped as without a start.
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Callable

from brainbulge.solver.driver import fallback
from brainbulge.solver.mixed import MixedForm
from brainbulge.solver.options import Solution, SolverOptions

log = logging.getLogger("brainbulge")


def warm_start_options(options: SolverOptions) -> SolverOptions:
    """``options`` for Newton from a start state (module docstring; the exact tangent is
    :func:`solve_from_start`'s own)."""
    warm = options.warm_start
    return dataclasses.replace(
        options, newton=dataclasses.replace(options.newton, max_iterations=warm.max_iterations),
        krylov=dataclasses.replace(options.krylov, max_iterations=warm.krylov_iterations))


def solve_from_start(form: MixedForm, options: SolverOptions,
                     start: Callable[[MixedForm], bool]) -> Solution:
    """``start(form)`` puts a start state into ``form`` and says whether it did; Newton from
    there, else (or without a start) the load ramp. ``Solution.started``: True when Newton
    converged from the start, False when it did not, None when there was none. The linear
    solver's memory is released."""
    from brainbulge.solver.ramp import NewtonSolver

    started = None

    def from_start() -> Solution | None:
        nonlocal started
        if not start(form):
            return None
        # (Krylov: a start whose tangent GMRES cannot solve ramps at once)
        solver = NewtonSolver(form, warm_start_options(options))
        sol = solver.equilibrate()
        started = sol.converged
        solver.release_linear_solver()
        if not sol.converged:
            log.info("  no convergence from the start state (%s): ramping the load",
                     sol.message)
            solver.state.reset()
        return sol

    def ramp() -> Solution:
        solver = NewtonSolver(form, options)
        sol = solver.solve()
        solver.release_linear_solver()
        return sol

    sol = fallback(from_start, ramp)
    sol.started = started
    return sol

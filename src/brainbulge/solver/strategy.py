"""Which way a solve goes to full load, chosen by the solver from the problem and what the
caller offers: :meth:`Strategy.from_problem`, then :func:`solve`.

A caller (a study) describes; it does not wire solvers. It gives the problem, the options
and the means it has: how to remesh the deformed domain (:class:`Rezoning`, 2D), a start
state (another flap's solution).
The strategy picks the path:

- a restart file of the options' ``checkpoint`` exists: the load ramp goes on from it
  (a start state is not used);
- a start state: Newton from it with the warm start's options
  (:class:`~brainbulge.solver.options.WarmStartOptions`), else the ramp from ``Js = 1``;
- a rezoning: the ramp with 2D rezoning (:mod:`brainbulge.solver.remesh.rezoning`);
- otherwise the load ramp (:mod:`brainbulge.solver.ramp`).

The :class:`~brainbulge.solver.options.Solution` says which route ran (``route``) and
whether a start state converged (``started``).
"""

from __future__ import annotations

import dataclasses
import enum
import gc
import logging
from collections.abc import Callable
from pathlib import Path

from brainbulge.heap import release_free_memory
from brainbulge.model.problem import Problem
from brainbulge.solver.mixed import MixedForm
from brainbulge.solver.options import Solution, SolverOptions
from brainbulge.solver.remesh.rezoning import Rezoning, solve_with_rezoning
from brainbulge.solver.warm_start import solve_from_start

__all__ = ["Rezoning", "Route", "Strategy", "solve"]

log = logging.getLogger("brainbulge")

#: a start state: ``start(form) -> bool`` puts one into ``form`` (at full load) and says
#: whether it did
Start = Callable[[MixedForm], bool]


class Route(enum.Enum):
    """The path a solve takes to full load."""

    RAMP = "ramp"
    REZONING = "rezoning"
    WARM_START = "warm start"


@dataclasses.dataclass(frozen=True)
class Strategy:
    """How :func:`solve` reaches full load: the ``route``, the options, the element and the
    means the route needs (``rezoning``, the ``start`` state)."""

    route: Route
    options: SolverOptions
    element: str = "taylor-hood"
    compile_energy: bool = False
    rezoning: Rezoning | None = None
    start: Start | None = None

    @classmethod
    def from_problem(
        cls,
        problem: Problem,
        options: SolverOptions | None = None,
        *,
        element: str = "taylor-hood",
        compile_energy: bool = False,
        rezoning: Rezoning | None = None,
        start: Start | None = None,
    ) -> Strategy:
        """The route for ``problem`` (module docstring)."""
        options = options or SolverOptions()
        base = {"options": options, "element": element, "compile_energy": compile_energy}
        checkpoint = options.checkpoint
        if checkpoint is not None and Path(checkpoint).is_file():
            return cls(Route.RAMP, **base)  # an interrupted ramp goes on where it stopped
        if start is not None:
            return cls(Route.WARM_START, start=start, **base)
        if rezoning is not None:
            return cls(Route.REZONING, rezoning=rezoning, **base)
        return cls(Route.RAMP, **base)

    def run(self, problem: Problem) -> Solution:
        """Solve ``problem`` along the route; the solution's form holds the final state.
        The linear solvers' work memory is released."""
        from brainbulge.solver.ramp import NewtonSolver

        opt = self.options
        if self.route is Route.REZONING:
            assert self.rezoning is not None
            return _routed(solve_with_rezoning(problem, self.rezoning, self.element, opt),
                           self.route)
        form = MixedForm(problem, element=self.element, compile_energy=self.compile_energy)
        if self.route is Route.WARM_START:
            assert self.start is not None
            return _routed(solve_from_start(form, opt, self.start), self.route)
        solver = NewtonSolver(form, opt)
        sol = solver.solve()
        solver.release_linear_solver()
        return _routed(sol, self.route)


def _routed(sol: Solution, route: Route) -> Solution:
    sol.route = route.value
    return sol


def solve(
    problem: Problem,
    strategy: Strategy | str | None = None,
    options: SolverOptions | None = None,
    compile_energy: bool = False,
    element: str = "taylor-hood",
) -> Solution:
    """Solve ``problem`` with ``strategy`` (:meth:`Strategy.from_problem`); without one (or
    given an element's name in its place), with the route chosen for ``problem`` alone:
    the load ramp of ``options``."""
    if not isinstance(strategy, Strategy):
        strategy = Strategy.from_problem(problem, options, element=strategy or element,
                                         compile_energy=compile_energy)
    sol = strategy.run(problem)
    free_solver_memory()
    return sol


def free_solver_memory() -> None:
    """Free what the finished solve's solvers still hold, before the caller's outputs.

    A Newton solver's equations sit in reference cycles (their sparse plans' closures), so
    they outlive the solve until Python's cycle collector runs, which the outputs, making
    few Python objects, may not start: the 1.40M-tet brain's closed-form tangent set-up
    (1.2 GB) stayed under its outputs' peak. Collected here, and the heap's free pages
    returned to the system (:func:`brainbulge.heap.release_free_memory`)."""
    gc.collect()
    release_free_memory()

"""One continuation driver: a parameter walked from a start to a target with one step control.

Every way of reaching a hard equilibrium by a path walks one parameter ``s`` from a start to
a target: the load factor ``t`` of the swelling (:class:`~brainbulge.solver.ramp.LoadRamp`,
also on rezoned meshes: :class:`~brainbulge.solver.remesh.rezoning.RezoningRamp`). :func:`walk`
owns the step control, the same for all (:class:`StepControl`):

- a step ``ds`` (at most what is left to the target) is tried from the last accepted state
  (the path may predict the new state from it);
- a step that fails is cut, ``ds <- cut ds``, and tried again from the last accepted state,
  until ``ds`` would fall below ``min_step``: then the path fails there;
- a step that converged within ``fast_iterations`` Newton iterations lets the next one grow,
  ``ds <- grow ds``; or, where the path measures how far a step moved, the next is sized
  to move ``slide`` (:meth:`StepControl.next_step`);
- after every accepted step the path may write its checkpoint and may stop (its hooks);
- after an accepted or a failed step the path may change its discretisation (the transfer
  of 2D rezoning): the walk goes on from its new state with the step it gives.

What differs between paths is a small class (:class:`Continuation`): its start, one step's
solve, what it records of an accepted or a failed step, its transfer, and its end.
:func:`fallback` tries one route and, when it does not converge, the next.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

from brainbulge.solver.options import Solution

log = logging.getLogger("brainbulge")


@dataclass(frozen=True)
class StepControl:
    """How :func:`walk` changes the step ``ds`` [parameter units]: ``cut`` after a failed
    step [-], ``grow`` after one that converged within ``fast_iterations`` Newton iterations
    [-], and the smallest step ``min_step`` before the path fails; with ``slide`` [-] the
    next step is sized by how far the accepted one moved (:meth:`next_step`)."""

    cut: float
    grow: float
    fast_iterations: int
    min_step: float
    slide: float = 0.0

    def next_step(self, ds: float, tried: Tried) -> float:
        """The step after an accepted one of ``ds``: sized by its ``motion`` (``ds slide /
        motion`` clipped to ``[cut, grow] ds``) when the path measured one and ``slide`` is
        set, else grown after an easy step."""
        if self.slide > 0 and tried.motion is not None:
            ratio = self.slide / max(tried.motion, 1e-300)
            return ds * min(max(ratio, self.cut), self.grow)
        return ds * self.grow if tried.iterations <= self.fast_iterations else ds


@dataclass(frozen=True)
class Tried:
    """One step's try: converged or not, the Newton iterations of all its attempts, the
    last attempt's result (:class:`~brainbulge.solver.newton.NewtonResult`, or None) and,
    where the path measures it, how far the converged step moved (``motion``, in the units
    of :attr:`StepControl.slide`)."""

    converged: bool
    iterations: int
    result: Any = None
    motion: float | None = None


class Continuation(Protocol):
    """A path for :func:`walk`: the parameter's ``target``, the ``control`` of its steps,
    and the hooks the walk calls."""

    target: float
    control: StepControl

    def begin(self) -> tuple[float, float, Solution]:
        """The start: ``(s, ds, sol)``, ``sol`` the record the walk fills in."""
        ...

    def snapshot(self) -> Any:
        """The current state, to go back to."""
        ...

    def restore(self, snap: Any) -> None:
        """Back to ``snap``."""
        ...

    def attempt(self, s: float, ds: float, last: Any) -> Tried:
        """Solve at ``s``, a step ``ds`` on from the accepted state ``last``."""
        ...

    def accept(self, s: float, ds: float, last: Any, tried: Tried, sol: Solution) -> None:
        """Record the accepted step to ``s`` (``last``: the state before it)."""
        ...

    def rejected(self, s: float, ds: float, tried: Tried, sol: Solution) -> bool:
        """A step to ``s + ds`` failed (the state is back at ``s``); True stops the walk."""
        ...

    def failed(self, s: float, ds: float, tried: Tried, sol: Solution) -> None:
        """The step ``ds`` from ``s`` failed and a smaller one is not allowed."""
        ...

    def settled(self, s: float, ds: float, sol: Solution) -> bool:
        """After an accepted step to ``s`` (next step ``ds``): checkpoint; True stops."""
        ...

    def transfer(self, s: float, sol: Solution, failed: bool) -> float | None:
        """At ``s``, after an accepted step or (``failed``) a failed one, the path may change
        its discretisation (a rezoned mesh): then it returns the next step ``ds`` and the
        walk goes on from its new state; None: nothing changed."""
        ...

    def end(self, last: Any, s: float, sol: Solution) -> Solution:
        """The walk is over at ``s`` (``last``: the last accepted state): the result."""
        ...


#: a parameter at least this fraction of its target has reached it
REACHED = 1 - 1e-12


def walk(path: Continuation) -> Solution:
    """Walk ``path`` from its start to its target (module docstring); the result of its
    :meth:`~Continuation.end` (``converged`` when the target was reached)."""
    control = path.control
    s, ds, sol = path.begin()
    last = path.snapshot()  # the last accepted state
    try:
        while s < path.target * REACHED:
            ds = min(ds, path.target - s)
            tried = path.attempt(s + ds, ds, last)
            if not tried.converged:
                sol.rejected_steps += 1
                path.restore(last)
                if (fresh := path.transfer(s, sol, failed=True)) is not None:
                    ds, last = fresh, path.snapshot()
                    continue
                if path.rejected(s, ds, tried, sol):
                    break
                step, ds = ds, ds * control.cut
                if ds < control.min_step:
                    path.failed(s, step, tried, sol)
                    break
                continue
            path.accept(s + ds, ds, last, tried, sol)
            s += ds
            last = path.snapshot()
            ds = control.next_step(ds, tried)
            if path.settled(s, ds, sol):
                break
            if (fresh := path.transfer(s, sol, failed=False)) is not None:
                ds, last = fresh, path.snapshot()
        else:
            sol.converged = True
    finally:
        sol = path.end(last, s, sol)
    return sol


def fallback(*routes: Callable[[], Solution | None]) -> Solution:
    """The first route's solution that converged, trying each in turn; a route returns None
    when it does not apply. Otherwise the last route's solution."""
    sol = None
    for route in routes:
        sol = route()
        if sol is not None and sol.converged:
            return sol
    if sol is None:
        raise ValueError("fallback: the last route gave no solution")
    return sol

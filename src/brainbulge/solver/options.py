"""What a solve is asked to do (:class:`SolverOptions`) and what it returns (:class:`Solution`).

The load factor ``t`` in [0, 1] ramps the swelling, ``Js(t) = 1 + t (Js - 1)`` (docs/model.md
section 1); a :class:`Solution` is the last converged state, the load it reached, and, when
the ramp stopped short of ``t = 1``, a structured :class:`Failure`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from brainbulge.errors import ConvergenceError, InputError

if TYPE_CHECKING:
    from brainbulge.solver.mixed import MixedForm

#: the advice that ends the message of a load ramp that diverged (a caller that knows better,
#: e.g. a hemidisk stopped on the skull's rounded cut edge, gives its own to
#: :meth:`Solution.describe`)
DIVERGENCE_ADVICE = "Try more --steps, a finer mesh, or check the boundary conditions"

LINEAR_SOLVERS = ("pardiso", "krylov")


@dataclass
class SolverOptions:
    """Load stepping and Newton controls.

    Attributes:
        steps: initial number of equal load steps from ``Js = 1`` to the target.
        min_step: smallest load increment ``dt`` before the ramp gives up [-].
        max_iterations: Newton iterations per attempt at one load.
        tolerance: on the scaled residual at full load (force / (mu L^(d-1)),
            volume / |Omega|; :meth:`NewtonSolver.scaled_norm`).
        linear_solver: "pardiso" (direct) or "krylov" (GMRES with AMG blocks, inexact Newton).
        progress: show a progress bar over the load.
        checkpoint: restart file written after each accepted load step and read at the
            start when it holds the same problem (:mod:`brainbulge.solver.restart`).
        checkpoint_key: identifies the problem in the restart file (e.g. the inputs as
            JSON); a file with another key is ignored and overwritten.
        start_load: load factor of the form's current state, where the ramp starts
            (a state carried over from another mesh by rezoning).
        stop_when: asked after each accepted load step below full load; ``True`` stops the
            ramp there (the state is kept, ``converged`` is false, ``stopped_early`` true).
        stop_on_failure: asked with the last converged load when a load step fails,
            before it is cut; ``True`` stops the ramp there as ``stop_when`` does.
    """

    steps: int = 5
    min_step: float = 1e-3
    max_iterations: int = 20
    tolerance: float = 1e-9
    linear_solver: str = "pardiso"
    progress: bool = False
    checkpoint: str | Path | None = None
    checkpoint_key: str = ""
    start_load: float = 0.0
    stop_when: Callable[[], bool] | None = None
    stop_on_failure: Callable[[float], bool] | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.steps, int) or self.steps < 1:
            raise InputError(f"steps = {self.steps!r} must be a positive integer")
        if not (0 < self.min_step <= 1):
            raise InputError(f"min_step = {self.min_step!r} must lie in (0, 1]")
        if not self.tolerance > 0:
            raise InputError(f"tolerance = {self.tolerance!r} must be positive")
        if not (0 <= self.start_load < 1):
            raise InputError(f"start_load = {self.start_load!r} must lie in [0, 1)")
        if self.linear_solver not in LINEAR_SOLVERS:
            raise InputError(f"unknown linear solver {self.linear_solver!r}; choose one of "
                             f"{', '.join(LINEAR_SOLVERS)}")


@dataclass
class StepRecord:
    """One accepted load step: its load ``t``, Newton iterations, contact augmentations
    (always 0: the active set is exact; kept for the restart file's layout), scaled residual
    and largest penetration [length]."""

    load: float
    newton_iterations: int
    augmentations: int
    residual: float
    max_penetration: float


@dataclass
class Failure:
    """Why a load ramp stopped short of full load: Newton diverged at ``load`` even with a
    load increment of ``step``; the converged state at ``kept`` is the solution's."""

    load: float
    step: float
    kept: float
    #: deformed position [length] of the vertex with the largest unbalanced force when the
    #: last Newton attempt gave up (None: its residual was not finite)
    site: np.ndarray | None = None

    def describe(self, advice: str = DIVERGENCE_ADVICE) -> str:
        """One line for the user, ending in ``advice``."""
        where = ""
        if self.site is not None:
            at = ", ".join(f"{c:.4g}" for c in self.site)
            where = f"; the last attempt's largest unbalanced force was at ({at})"
        return (f"Newton diverged at load {self.load:.4f} of 1 (swelling ramp) even with a "
                f"load step of {self.step:.2g}; the last converged state (load "
                f"{self.kept:.4f}) is kept{where}. {advice}")


@dataclass
class Solution:
    """The last converged state, and how it was reached.

    ``load`` is the load factor reached; ``swelling_reached`` the largest target swelling
    ramped to it, ``1 + load (Js - 1)``; ``max_penetration`` the contact points' largest
    penetration ``max(-g, 0)`` [length] at the end of the solve.
    """

    form: MixedForm
    load: float
    converged: bool
    steps: list[StepRecord] = field(default_factory=list)
    rejected_steps: int = 0
    wall_time_s: float = 0.0
    assembly_time_s: float = 0.0
    solve_time_s: float = 0.0
    linear_iterations: int = 0  # Krylov iterations in all (0 with a direct solver)
    stopped_early: bool = False  # by ``SolverOptions.stop_when``, not by a failure
    rezones: int = 0  # mesh exchanges (see :mod:`brainbulge.solver.remesh.rezoning`)
    resumed_from: float = 0.0  # load of the restart file the ramp went on from (0: none)
    max_penetration: float = 0.0
    target_swelling: float = 1.0  # the largest |Js - 1| of the problem's regions, as Js
    failure: Failure | None = None  # set when Newton diverged at the smallest load step
    note: str = ""  # why the ramp stopped otherwise (stop hooks, an equilibration)
    context: str = ""  # appended in parentheses (e.g. a rezoning that failed)

    @property
    def swelling_reached(self) -> float:
        """``Js(t) = 1 + t (Js - 1)`` at the load reached, for the largest target ``Js``."""
        return 1 + self.load * (self.target_swelling - 1)

    @property
    def newton_iterations(self) -> int:
        return sum(s.newton_iterations for s in self.steps)

    @property
    def failure_site(self) -> np.ndarray | None:
        return None if self.failure is None else self.failure.site

    def describe(self, advice: str = DIVERGENCE_ADVICE) -> str:
        """Why the ramp stopped ('' when it did not): the failure's text with ``advice``,
        or the note, then the context."""
        text = self.failure.describe(advice) if self.failure is not None else self.note
        return text + (f" ({self.context})" if self.context else "")

    @property
    def message(self) -> str:
        return self.describe()

    def raise_if_failed(self) -> None:
        if not self.converged:
            raise ConvergenceError(self.message)

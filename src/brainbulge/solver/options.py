"""What a solve is asked to do (:class:`SolverOptions`) and what it returns (:class:`Solution`).

Every tunable of a solve is a field of a frozen group of :class:`SolverOptions` (the
options tree, :mod:`brainbulge.solver.option_groups`: ``ramp``, ``newton``, ``linear``,
``krylov``, ``hotspot``, ``rezoning``, ``warm_start``), declared
once with :func:`~brainbulge.model.options.option`: default, unit, range and the reason for
the default; a group checks its ranges when built.

The load factor ``t`` in [0, 1] ramps the swelling, ``Js(t) = 1 + t (Js - 1)`` (docs/model.md
section 1); a :class:`Solution` is the last converged state, the load it reached, and, when
the ramp stopped short of ``t = 1``, a structured :class:`Failure`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import MISSING, dataclass, field, fields, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from brainbulge.errors import ConvergenceError, InputError
from brainbulge.solver.option_groups import (
    LINEAR_SOLVERS,
    RATIO,
    HotspotOptions,
    KrylovOptions,
    LinearOptions,
    NewtonOptions,
    OptionGroup,
    RampOptions,
    RezoningOptions,
    WarmStartOptions,
)

__all__ = ["DIVERGENCE_ADVICE", "LINEAR_SOLVERS", "RATIO", "SHORTHAND",
           "Costs", "Failure", "HotspotOptions", "KrylovOptions", "LinearOptions",
           "NewtonOptions", "OptionGroup", "RampOptions", "RezoningOptions",
           "Solution", "SolverOptions", "StepRecord", "WarmStartOptions"]

if TYPE_CHECKING:
    from brainbulge.solver.mixed import MixedForm

#: the advice that ends the message of a load ramp that diverged (a caller that knows better,
#: e.g. a hemidisk stopped on the skull's rounded cut edge, gives its own to
#: :meth:`Solution.describe`)
DIVERGENCE_ADVICE = "Try more --steps, a finer mesh, or check the boundary conditions"

#: the keywords ``SolverOptions(...)`` also takes for a field of a group, by the names these
#: fields had before the groups (``SolverOptions(steps=2)`` is ``SolverOptions(ramp=
#: RampOptions(steps=2))``): name -> (group, field)
SHORTHAND = {
    "steps": ("ramp", "steps"),
    "min_step": ("ramp", "min_step"),
    "intermediate_tolerance": ("ramp", "intermediate_tolerance"),
    "max_iterations": ("newton", "max_iterations"),
    "tolerance": ("newton", "tolerance"),
    "slow_newton_s": ("newton", "slow_newton_s"),
    "closed_form": ("newton", "closed_form"),
    "hotspot_relaxation": ("newton", "hotspot_relaxation"),
    "linear_solver": ("linear", "solver"),
    "eta_max": ("linear", "eta_max"),
}


@dataclass(init=False)
class SolverOptions:
    """What a solve is asked to do: the options tree's groups
    (:mod:`brainbulge.solver.option_groups`: every tunable, declared once), and what is not a
    tunable: where the ramp starts, the stop hooks, the restart file and the progress bar. A
    solver takes them at construction; for other values build another one
    (``dataclasses.replace(options, ...)``; a group: ``dataclasses.replace(options.newton,
    ...)``). The keywords of :data:`SHORTHAND` set a group's field by its old flat name."""

    # --- the options tree (frozen groups) ------------------------------------------------
    ramp: RampOptions = field(default_factory=RampOptions)
    newton: NewtonOptions = field(default_factory=NewtonOptions)
    linear: LinearOptions = field(default_factory=LinearOptions)
    krylov: KrylovOptions = field(default_factory=KrylovOptions)
    hotspot: HotspotOptions = field(default_factory=HotspotOptions)
    rezoning: RezoningOptions = field(default_factory=RezoningOptions)
    warm_start: WarmStartOptions = field(default_factory=WarmStartOptions)

    # --- not tunables: set by the code paths and the caller's I/O ------------------------
    #: load factor [-] of the form's current state, where the ramp starts
    start_load: float = 0.0
    #: asked after each accepted load step below full load; ``True`` stops the ramp there
    #: (the state is kept, ``converged`` is false, ``stopped_early`` true)
    stop_when: Callable[[], bool] | None = None
    #: asked with the last converged load when a load step fails, before it is cut; ``True``
    #: stops the ramp there as ``stop_when`` does
    stop_on_failure: Callable[[float], bool] | None = None
    #: restart file written after each accepted load step and read at the start when it
    #: holds the same problem (:mod:`brainbulge.solver.restart`)
    checkpoint: str | Path | None = None
    #: identifies the problem in the restart file (e.g. the inputs as JSON); a file with
    #: another key is ignored and overwritten
    checkpoint_key: str = ""
    #: show a progress bar over the load
    progress: bool = False

    def __init__(self, **values: Any) -> None:
        shorthand = {k: values.pop(k) for k in list(values) if k in SHORTHAND}
        for f in fields(self):
            if f.name in values:
                value = values.pop(f.name)
            elif f.default_factory is not MISSING:
                value = f.default_factory()
            else:
                value = f.default
            setattr(self, f.name, value)
        if values:
            raise TypeError(f"SolverOptions: unknown option(s) {', '.join(sorted(values))}")
        by_group: dict[str, dict[str, Any]] = {}
        for name, value in shorthand.items():
            group, key = SHORTHAND[name]
            by_group.setdefault(group, {})[key] = value
        for group, changes in by_group.items():
            setattr(self, group, replace(getattr(self, group), **changes))
        if not (0 <= self.start_load < 1):
            raise InputError(f"start_load = {self.start_load!r} must lie in [0, 1)")


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
    #: the last Newton attempt's scaled residual [-] and iterations when it gave up
    residual: float = float("nan")
    iterations: int = 0
    #: why that attempt gave up (e.g. "max_iterations = 20 reached")
    reason: str = ""

    def describe(self, advice: str = DIVERGENCE_ADVICE) -> str:
        """One line for the user, ending in ``advice``."""
        why = ""
        if self.reason:
            n = self.iterations
            why = (f" (the last attempt: |R| = {self.residual:.2e} after {n} Newton "
                   f"iteration{'' if n == 1 else 's'}, {self.reason})")
        where = ""
        if self.site is not None:
            at = ", ".join(f"{c:.4g}" for c in self.site)
            where = f"; the last attempt's largest unbalanced force was at ({at})"
        return (f"Newton diverged at load {self.load:.4f} of 1 (swelling ramp) even with a "
                f"load step of {self.step:.2g}{why}; the last converged state (load "
                f"{self.kept:.4f}) is kept{where}. {advice}")


@dataclass
class Costs:
    """What solves cost, added up: assembly and linear-solve time [s] and Krylov iterations
    (0 with a direct solver). The one place where the costs of several solves (the meshes of
    rezoning) are summed."""

    assembly_time_s: float = 0.0
    solve_time_s: float = 0.0
    linear_iterations: int = 0

    def add(self, sol: Solution | Costs) -> Costs:
        """``self`` plus the costs of ``sol``."""
        self.assembly_time_s += sol.assembly_time_s
        self.solve_time_s += sol.solve_time_s
        self.linear_iterations += sol.linear_iterations
        return self

    def into(self, sol: Solution) -> Solution:
        """``sol`` with these costs."""
        sol.assembly_time_s = self.assembly_time_s
        sol.solve_time_s = self.solve_time_s
        sol.linear_iterations = self.linear_iterations
        return sol


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
    #: the route the solve took (:class:`~brainbulge.solver.strategy.Route`'s value)
    route: str = "ramp"
    #: from a start state: True when Newton converged from it, False when the load was
    #: ramped instead; None without a start state
    started: bool | None = None
    #: every Newton solve of this solve, in order (:class:`~brainbulge.solver.newton.NewtonResult`)
    newton_results: list[Any] = field(default_factory=list)

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

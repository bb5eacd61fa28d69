"""What a solve is asked to do (:class:`SolverOptions`) and what it returns (:class:`Solution`).

The continuations', the Krylov solver's and the hotspot relaxation's tunables are frozen
groups of :class:`SolverOptions` (``options.contrast``, ``options.sequencing``,
``options.rezoning``, ``options.warm_start``, ``options.krylov``, ``options.hotspot``), each
field declared
once with :func:`~brainbulge.model.options.option`: default, unit, range and the reason for
the default; a group checks its ranges when built.

The load factor ``t`` in [0, 1] ramps the swelling, ``Js(t) = 1 + t (Js - 1)`` (docs/model.md
section 1); a :class:`Solution` is the last converged state, the load it reached, and, when
the ramp stopped short of ``t = 1``, a structured :class:`Failure`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from brainbulge.errors import ConvergenceError, InputError
from brainbulge.model.options import check_ranges, option
from brainbulge.solver.inexact import ETA_MIN

if TYPE_CHECKING:
    from brainbulge.solver.mixed import MixedForm

#: the advice that ends the message of a load ramp that diverged (a caller that knows better,
#: e.g. a hemidisk stopped on the skull's rounded cut edge, gives its own to
#: :meth:`Solution.describe`)
DIVERGENCE_ADVICE = "Try more --steps, a finer mesh, or check the boundary conditions"

LINEAR_SOLVERS = ("pardiso", "krylov")

#: the unit of a dimensionless field
RATIO = " [-]"


class OptionGroup:
    """A frozen group of options, its fields declared with
    :func:`~brainbulge.model.options.option`: built only with every value in its range."""

    def __post_init__(self) -> None:
        check_ranges(self)


@dataclass(frozen=True)
class ContrastOptions(OptionGroup):
    """The stiffness-contrast path of a fine stage (:mod:`brainbulge.solver.contrast`)."""

    start: float = option(
        2.0, "the contrast mu_max / mu_min the path starts from (at most the model's): white "
        "over gray matter (666 / 333 kPa), the parenchyma's own, where the 100k-tet "
        "template's fine stage converges from the 25k-tet state (4 Newton iterations with a "
        "2 or 8 mm edge); the upper bound: the model's contrast alone, no path",
        unit=RATIO, range=(1.0, 1e6))
    factor: float = option(
        math.sqrt(10.0), "growth of the contrast per step (2 -> 6.3 -> 20 for the brain's "
        "CSF)", unit=RATIO, range=(1.01, 1e3))
    progress_iterations: int = option(
        3, "each step's Newton solve gives up when its scaled residual is not below "
        "progress_factor times its first after this many iterations (the converged steps "
        "logged on the 100k- and 1.40M-tet templates fell 40-18,000x in 3)",
        unit=" iterations", range=(1, 100))
    progress_factor: float = option(
        0.1, "the fall of the scaled residual each step requires within progress_iterations "
        "(the converged steps fell to 2e-3-3e-2 of their first)", unit=RATIO,
        range=(0.0, 1.0))


@dataclass(frozen=True)
class SequencingOptions(OptionGroup):
    """Mesh sequencing, coarse mesh to fine (:mod:`brainbulge.solver.remesh.sequencing`)."""

    coarse_tolerance: float = option(
        1e-4, "the coarse stage's Newton tolerance on the scaled residual (never tighter "
        "than the solve's): its state is only where the fine mesh starts, whose carried-over "
        "residual is ~1e-2 (1.7e-2 at 1.40M from 111k tets, the same to four digits from a "
        "coarse state at 1e-7); the 111k coarse ramp takes 6 Newton iterations instead of 9",
        unit=RATIO, range=(1e-14, 1e-1))
    fold_ratio: float = option(
        0.2, "a contact point moved onto the obstacle goes back if an element of it is left "
        "with less than this fraction of its reference measure (and less than before the "
        "move): 18 folded tets at 1.40M under the skull's 2 mm rounded cut edge without it",
        unit=RATIO, range=(0.0, 1.0))


@dataclass(frozen=True)
class RezoningOptions(OptionGroup):
    """2D rezoning during the load ramp (:mod:`brainbulge.solver.remesh.rezoning`)."""

    q_min: float = option(
        0.2, "rezone when the smallest deformed triangle quality 4 sqrt(3) A / sum l^2 falls "
        "below this (above 1: after every accepted step)", unit=RATIO, range=(0.0, 2.0))
    equilibration_iterations: int = option(
        8, "Newton iterations allowed to equilibrate a carried-over state on the new mesh "
        "before the rezoning counts as failed: in the sector study each rezoning that "
        "succeeded converged in 4, each that failed stood at 3e-4-1e-2 after 14-20",
        unit=" iterations", range=(1, 1000))
    max_rezones: int = option(
        50, "mesh exchanges in one solve before the ramp goes on without rezoning",
        unit=" rezonings", range=(0, 10_000))


@dataclass(frozen=True)
class WarmStartOptions(OptionGroup):
    """Newton from a given start state (another flap's solution) before the load is ramped
    instead (:func:`brainbulge.studies.craniectomy.solve_brain`'s ``start``)."""

    max_iterations: int = option(
        8, "Newton iterations from the start state: about what a cold ramp of a large flap "
        "takes (21k tets, 120 mm: 8, the same from the 100 mm flap's state, with the exact "
        "tangent), so a start that does not help costs at most a ramp",
        unit=" iterations", range=(1, 1000))
    krylov_iterations: int = option(
        200, "GMRES iterations of one linear solve from the start state: a larger flap's "
        "start frees the tissue under the newly opened ring at full pressure; on the "
        "111k-tet template (80 -> 100 mm) GMRES stood at 6e-3 after 1,000 iterations, twice, "
        "150 s before the ramp; converging solves there take <= ~170",
        unit=" iterations", range=(1, 100_000))


@dataclass(frozen=True)
class HotspotOptions(OptionGroup):
    """The hotspot relaxation between Newton iterations
    (:mod:`brainbulge.solver.fast.hotspot`; on or off: ``hotspot_relaxation``)."""

    share: float = option(
        0.5, "the hotspot: the fewest vertices holding this share of the scaled |R|^2 (at "
        "1.40M tets 90-100 % sat at three CSF vertices of the flap rim)", unit=RATIO,
        range=(0.01, 1.0))
    max_vertices: int = option(
        16, "a hotspot of more vertices is left to Newton (a residual spread over the body "
        "is Newton's job); no other value measured", unit=" vertices", range=(1, 100_000))
    rings: int = option(
        2, "rings of neighbours solved with the hotspot (with them 4 fine iterations instead "
        "of 7 at 1.40M tets; no other value measured)", unit=" rings", range=(0, 10))
    max_iterations: int = option(
        30, "Newton iterations of one local solve (a cap: the result is kept only when the "
        "global residual falls); no other value measured", unit=" iterations",
        range=(1, 1000))


@dataclass(frozen=True)
class KrylovOptions(OptionGroup):
    """GMRES with AMG blocks (:class:`~brainbulge.solver.linear.krylov.BlockKrylovSolver`)."""

    max_iterations: int = option(
        1000, "GMRES iterations per linear solve, all restarts included (converging solves on "
        "the 111k-tet template take <= ~170)", unit=" iterations", range=(1, 1_000_000))
    restart: int = option(
        200, "GMRES restart length (basis vectors kept: 1.7 GB at 1.08M unknowns); with 100 "
        "the 1.40M-tet brain's fine-stage tangent stalled at 5.6e-2 after 200 iterations, it "
        "converges in 157 without a restart", unit=" vectors", range=(1, 100_000))
    refresh_factor: float = option(
        1.5, "rebuild the AMG hierarchies when a solve takes more than this times the "
        "iterations of the first solve after the last set-up; no other value measured",
        unit=RATIO, range=(1.0, 1e3))


@dataclass
class SolverOptions:
    """Everything a caller may tune in a solve: the load ramp's, Newton's and the linear
    solver's controls, each with its default and why (:mod:`brainbulge.solver.ramp`,
    :mod:`brainbulge.solver.newton`). A solver takes them at construction; for other
    values build another one (``dataclasses.replace(options, ...)``)."""

    # --- the load ramp -------------------------------------------------------------------
    #: initial number of equal load steps from ``Js = 1`` to the target
    steps: int = 5
    #: smallest load increment ``dt`` [-] before the ramp gives up with a :class:`Failure`
    min_step: float = 1e-3
    #: load factor [-] of the form's current state, where the ramp starts (a state carried
    #: over from another mesh by rezoning)
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

    # --- Newton --------------------------------------------------------------------------
    #: Newton iterations per attempt at one load
    max_iterations: int = 20
    #: on the scaled residual at full load [-] (force / (mu L^(d-1)), volume / |Omega|;
    #: :meth:`~brainbulge.solver.equations.MixedEquations.scaled_norm`)
    tolerance: float = 1e-9
    #: Newton's tolerance below full load [-] (never tighter than ``tolerance``). The
    #: material is hyperelastic, so an intermediate state is only the start of the next
    #: step (its extrapolation starts ~1e-3 away): converging it further buys nothing.
    #: Saves about one Newton iteration per intermediate load step (2D headline: 20 -> 18).
    intermediate_tolerance: float = 1e-6
    #: Newton from a carried-over state (``NewtonSolver.equilibrate``: mesh sequencing,
    #: another flap's solution) leaves the point contacts' curvature term out of the tangent
    #: until the scaled residual is at most this [-] (a modified Newton method far from the
    #: solution, the exact tangent for the end game; ``inf``: always in). At a state carried
    #: over from a coarse mesh the flap rim's contact points press with up to ~350 kPa on the
    #: skull's convex rounded cut edge, where the term ``-A lambda grad^2 g`` makes sliding
    #: along the edge nearly free: the exact Newton direction slid points by 5-8 mm and
    #: folded elements (line-search steps of 1/8; 1.54M tets, 10 Newton iterations); without
    #: the term the first step is a full one (1.7e-2 -> 8.7e-4) and the stage takes 6.
    carried_curvature_tolerance: float = 1e-3
    #: an attempt stops early, as failed, after this many Newton iterations in a row whose
    #: line search accepted at most 1/64 of the step and that together lowered the residual
    #: by less than 5 % (0: never). Where the load path folds, the 2D alpha 80 / beta 30
    #: runs spent all 20 iterations on 0.1-0.4 % steps, attempt after attempt.
    stagnation: int = 4
    #: ``(k, f)``: a Newton solve whose scaled residual is not below ``f`` times its first
    #: after ``k`` iterations gives up (None: no such requirement)
    required_progress: tuple[int, float] | None = None
    #: a Newton solve running longer than this [s] logs each iteration at INFO (else DEBUG),
    #: so that a long fine-mesh solve shows its progress in the log
    slow_newton_s: float = 30.0
    #: the closed-form MINI residual and tangent where they apply
    #: (:mod:`brainbulge.solver.fast.mini_tangent`, ``mini_plane``; False: NGSolve's, the
    #: same to round-off, slower)
    closed_form: bool = True
    #: local solves at residual hotspots between Newton iterations (MINI, where it applies:
    #: :mod:`brainbulge.solver.fast.hotspot`; False: the plain path)
    hotspot_relaxation: bool = True

    # --- the linear solver ---------------------------------------------------------------
    #: "pardiso" (direct) or "krylov" (GMRES with AMG blocks, inexact Newton)
    linear_solver: str = "pardiso"
    #: loosest relative tolerance ``eta`` of an inexact Newton's Krylov solve [-]
    #: (:func:`brainbulge.solver.inexact.forcing_term`)
    eta_max: float = 1e-4
    #: a failed Krylov solve is retried once, tighter, with a fresh preconditioner (False:
    #: the Newton solve fails at once, e.g. from a start state that a ramp can replace)
    retry_linear: bool = True
    #: the Krylov solver's budget, restart and AMG refresh (frozen group)
    krylov: KrylovOptions = field(default_factory=KrylovOptions)
    #: the hotspot relaxation's hotspot, patch and local Newton (frozen group)
    hotspot: HotspotOptions = field(default_factory=HotspotOptions)

    # --- the continuations (frozen groups: ``dataclasses.replace`` a group to change it) --
    contrast: ContrastOptions = field(default_factory=ContrastOptions)
    sequencing: SequencingOptions = field(default_factory=SequencingOptions)
    rezoning: RezoningOptions = field(default_factory=RezoningOptions)
    warm_start: WarmStartOptions = field(default_factory=WarmStartOptions)

    def __post_init__(self) -> None:
        if not isinstance(self.steps, int) or self.steps < 1:
            raise InputError(f"steps = {self.steps!r} must be a positive integer")
        if not (0 < self.min_step <= 1):
            raise InputError(f"min_step = {self.min_step!r} must lie in (0, 1]")
        for name in ("tolerance", "intermediate_tolerance", "carried_curvature_tolerance"):
            if not getattr(self, name) > 0:
                raise InputError(f"{name} = {getattr(self, name)!r} must be positive")
        if not (0 <= self.start_load < 1):
            raise InputError(f"start_load = {self.start_load!r} must lie in [0, 1)")
        if not isinstance(self.stagnation, int) or self.stagnation < 0:
            raise InputError(f"stagnation = {self.stagnation!r} must be a non-negative "
                             "integer (0: off)")
        if not (ETA_MIN <= self.eta_max < 1):
            raise InputError(f"eta_max = {self.eta_max!r} must lie in [{ETA_MIN:g}, 1)")
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
    #: the last Newton attempt's scaled residual [-] and iterations when it gave up
    residual: float = float("nan")
    iterations: int = 0
    #: why that attempt gave up (e.g. "stagnated: ...", "max_iterations = 20 reached")
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
    (0 with a direct solver). The one place where the costs of several solves (the stages of
    mesh sequencing, the steps of the contrast path, the meshes of rezoning) are summed."""

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
    #: mesh sequencing's coarse stage (:class:`~brainbulge.solver.remesh.sequencing.Sequenced`;
    #: None without)
    sequenced: Any = None
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

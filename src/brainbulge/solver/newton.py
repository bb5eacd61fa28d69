"""Newton's method on the mixed equations at one load.

At a fixed load factor ``t`` the state ``x = (u, p)`` (with the contact pressures
``lambda``) solves ``R(x) = 0``, the stationarity of the Lagrangian of docs/model.md section 2 plus
the contact forces. Newton's iteration is::

    K(x_k) dx = R(x_k),        x_{k+1} = x_k - s dx,        lambda_{k+1} = lambda_k - s dlam

with the contact constraints of the active set (:mod:`brainbulge.solver.contact`), and
``s = 1``: the whole update (scaled by an optional step limit), halved only while the
residual is not finite. (A backtracking line search on the scaled residual
:meth:`MixedEquations.scaled_norm <brainbulge.solver.equations.MixedEquations.scaled_norm>`
cost iterations in every case measured: docs/design.md, "Convergence mechanisms".) With the
Krylov solver the linear solve is inexact, to the relative tolerance of
:func:`brainbulge.solver.inexact.forcing_term`. A solve gives up, with its :class:`Reason`,
after ``max_iterations``, at a non-finite residual, when the linear solve fails or when no
update gives a finite residual (:class:`SolverOptions`).

:func:`newton` is a function of the equations (:class:`MixedEquations`) and their state: it
keeps nothing between solves and returns a :class:`NewtonResult`. What is shown of a solve
(the log, the slow-solve watch) is an observer (:class:`NewtonObserver`). The load ramp that
calls it (predictor, cut-back, restart) is :mod:`brainbulge.solver.ramp`.
"""

from __future__ import annotations

import enum
import logging
import time
from collections.abc import Callable, Sequence
from contextlib import nullcontext
from dataclasses import dataclass, field

import ngsolve as ngs
import numpy as np

from brainbulge.errors import ConvergenceError
from brainbulge.solver.equations import MixedEquations
from brainbulge.solver.inexact import forcing_term
from brainbulge.solver.options import SolverOptions
from brainbulge.solver.state import Snapshot
from brainbulge.solver.threads import serial_openblas

log = logging.getLogger("brainbulge")

#: ``limit_step(x, dx) -> f``: a factor ``f`` in (0, 1] that scales the whole update
#: ``(dx, dlam)`` before it is taken (e.g. a cap on the displacement increment)
StepLimit = Callable[[ngs.BaseVector, ngs.BaseVector], float]


class Reason(enum.Enum):
    """Why a Newton solve ended."""

    CONVERGED = "converged"
    NOT_FINITE = "not finite"
    MAX_ITERATIONS = "max iterations"
    LINEAR_FAILED = "linear solve failed"
    NO_STEP = "no step"


@dataclass(frozen=True)
class NewtonResult:
    """One Newton solve: whether it converged, its iterations, the scaled residual [-] of
    each iterate (the first is the start's), the Krylov iterations (0 with a direct solver),
    why it ended (``reason`` and ``detail``, one phrase for the user) and, on failure, the
    deformed position [length] of the vertex with the largest unbalanced force (None: not
    finite)."""

    converged: bool
    iterations: int
    residuals: tuple[float, ...]
    linear_iterations: int
    reason: Reason
    detail: str = ""
    site: np.ndarray | None = None

    @property
    def norm(self) -> float:
        """The last iterate's scaled residual [-]."""
        return self.residuals[-1]


class NewtonObserver:
    """What is shown of a Newton solve; the base shows nothing."""

    def iteration(self, it: int, norm: float) -> None:
        """Iterate ``it`` has scaled residual ``norm``."""

    def step(self, s: float, eq: MixedEquations, eta: float | None) -> None:
        """An update scaled by ``s`` was accepted (``eta``: the Krylov tolerance, or None)."""


class NewtonLog(NewtonObserver):
    """The log of a solve: each iteration at DEBUG, at INFO once it has run longer than
    ``slow_s`` [s] (a long fine-mesh solve shows its progress)."""

    def __init__(self, slow_s: float) -> None:
        self.slow_s = slow_s
        self.started = time.perf_counter()

    def iteration(self, it: int, norm: float) -> None:
        elapsed = time.perf_counter() - self.started
        log.log(logging.INFO if elapsed > self.slow_s else logging.DEBUG,
                "    newton %d: |R| = %.3e (%.0f s)", it, norm, elapsed)

    def step(self, s: float, eq: MixedEquations, eta: float | None) -> None:
        pcs = eq.contact.contacts
        log.debug("    step %.3g, %d active contact points (%d pulling)%s", s,
                  sum(int(a.sum()) for a in eq.contact.last_active),
                  sum(int((pc.lam < 0).sum()) for pc in pcs),
                  "" if eta is None else f", Krylov rtol {eta:.1e}")


@dataclass
class _Inexact:
    """One solve's inexact-Newton controls: the Krylov tolerance ``eta`` (None with a
    direct solver) and each iterate's scaled residual."""

    eta: float | None
    residuals: list[float] = field(default_factory=list)


def newton(eq: MixedEquations, options: SolverOptions, tolerance: float | None = None,
           limit_step: StepLimit | None = None,
           observers: Sequence[NewtonObserver] | None = None,
           relax: Callable[[ngs.BaseVector, float], float] | None = None) -> NewtonResult:
    """Solve ``R(x) = 0`` at the form's load from its current state (changed in place, with
    the contact pressures) to ``tolerance`` (default: ``options.newton.tolerance``).

    ``limit_step``: a factor in (0, 1] applied to each Newton update.
    ``observers``: default a :class:`NewtonLog`. ``relax(x, |R|) -> |R|``: a local solve
    after each accepted step (:mod:`brainbulge.solver.fast.hotspot`)."""
    tol = options.newton.tolerance if tolerance is None else tolerance
    watch = [NewtonLog(options.newton.slow_newton_s)] if observers is None else observers
    linear_before = sum(eq.linear.stats.iterations)
    # one OpenBLAS thread beside PARDISO (brainbulge.solver.threads); the Krylov path's
    # long vectors keep theirs (111k-tet brain: 10 % slower on one)
    with nullcontext() if eq.inexact else serial_openblas():
        run = _Inexact(options.linear.eta_max if eq.inexact else None)
        ok, its, reason, detail = _iterate(eq, options, tol, limit_step, watch, relax, run)
    return NewtonResult(ok, its, tuple(run.residuals),
                        int(sum(eq.linear.stats.iterations) - linear_before), reason, detail,
                        None if ok else eq.residual_site(eq.state.x))


def _iterate(eq: MixedEquations, opt: SolverOptions, tol: float,
             limit_step: StepLimit | None, watch: Sequence[NewtonObserver],
             relax: Callable[[ngs.BaseVector, float], float] | None, run: _Inexact
             ) -> tuple[bool, int, Reason, str]:
    """:func:`newton`'s loop: (converged, iterations, reason, detail)."""
    state, nw = eq.state, opt.newton
    eq.linear.new_load_step()
    norm = eq.scaled_norm(eq.residual(state.x))
    for it in range(nw.max_iterations + 1):
        run.residuals.append(norm)
        for o in watch:
            o.iteration(it, norm)
        if norm <= tol:
            return True, it, Reason.CONVERGED, ""
        if not np.isfinite(norm):
            return False, it, Reason.NOT_FINITE, "the residual is not finite"
        if it == nw.max_iterations:
            return False, it, Reason.MAX_ITERATIONS, f"max_iterations = {it} reached"
        try:
            s, trial = _step(eq, opt, state.snapshot(), limit_step, run)
        except ConvergenceError as exc:
            return False, it, Reason.LINEAR_FAILED, f"the linear solve failed ({exc})"
        if s is None:
            return False, it, Reason.NO_STEP, "no update gave a finite residual"
        for o in watch:
            o.step(s, eq, run.eta)
        # (a full step that does not halve the residual is not the Krylov tolerance's doing
        # here: from one 1.54M-tet state, GMRES at 1e-7 instead of 1e-4 gave the same
        # Newton residuals to four digits; tightening after such steps only doubled the
        # GMRES iterations)
        if run.eta is not None:
            run.eta = min(opt.linear.eta_max, forcing_term(
                run.eta, trial / norm, trial, tol, opt.linear.eta_max, opt.linear.eta_min))
        norm = trial
        if relax is not None and norm > tol:
            norm = relax(state.x, norm)
    raise AssertionError("unreachable: the loop returns at its last iteration")


def _step(eq: MixedEquations, opt: SolverOptions, x0: Snapshot, limit_step: StepLimit | None,
          run: _Inexact) -> tuple[float | None, float]:
    """One Newton iteration from ``x0`` (the state): the direction, scaled by ``limit_step``,
    taken whole and halved only while the residual is not finite (an inverted element).
    Returns ``(s, |R(trial)|)`` of the accepted update (the state is the trial); ``s = None``
    when no ``s >= min_line_step`` gives a finite residual (the state back at ``x0``)."""
    state, nw = eq.state, opt.newton
    dx, dlams = eq.newton_direction(state.x, eq.tangent(state.x), run.eta)
    if limit_step is not None:
        f = limit_step(state.x, dx)
        if f < 1:
            dx.data = f * dx
            dlams = [f * d for d in dlams]
    s = 1.0
    while True:
        state.x.data = x0.x - s * dx
        state.set_multipliers([l0 - s * dl for l0, dl in zip(x0.lam, dlams, strict=True)])
        trial = eq.scaled_norm(eq.residual(state.x))
        if np.isfinite(trial):
            return s, trial
        s *= nw.backtrack
        if s < nw.min_line_step:
            state.restore(x0)
            return None, trial

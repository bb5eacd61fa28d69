"""The load ramp: the swelling ``Js(t) = 1 + t (Js - 1)`` raised step by step to ``t = 1``.

:class:`LoadRamp` is the path the continuation driver walks
(:func:`~brainbulge.solver.driver.walk`, which owns the step control), each step one Newton
solve (:func:`~brainbulge.solver.newton.newton`) at the new load. Each load step raises the
load factor by ``dt``, predicts the new state by extrapolating the last increment,

    x_pred = x_prev + (dt / dt_last) (x_prev - x_before),

and solves from it (without ``predictor``: from the last converged state). A step that
fails is cut, ``dt <- cut dt``, and retried from the last converged state; a step that
converged within ``fast_iterations`` lets the next grow, ``dt <- grow dt`` (``options.ramp``:
0.5, 4 and 1.5), or, with ``slide``, the next step is sized by how far the last one moved
the vertices in their element sizes (:class:`~brainbulge.solver.step_bounds.Slide`). The
ramp stops with a :class:`Failure` (the load, the step, the last Newton
attempt's residual, iterations and reason, and where its force residual peaked) when the
step would fall below ``min_step``, and early when a stop hook of :class:`SolverOptions` says
so. Below full load Newton converges only to ``intermediate_tolerance``. After every accepted
step the state can go to a restart file (:mod:`brainbulge.solver.restart`), from which a
stopped run resumes. :class:`NewtonSolver` holds a form's equations and offers the ramp
(:meth:`NewtonSolver.solve`), Newton at one load (:meth:`NewtonSolver.equilibrate`) and one
Newton solve.
"""

from __future__ import annotations

import logging
import time
from pathlib import Path

import ngsolve as ngs
from tqdm.auto import tqdm

from brainbulge.errors import InfeasibleError
from brainbulge.solver import restart
from brainbulge.solver.driver import REACHED, StepControl, Tried, walk
from brainbulge.solver.equations import MixedEquations
from brainbulge.solver.fast.hotspot import HotspotRelaxation
from brainbulge.solver.mixed import MixedForm
from brainbulge.solver.newton import NewtonResult, StepLimit, newton
from brainbulge.solver.options import Costs, Failure, Solution, SolverOptions, StepRecord
from brainbulge.solver.state import Snapshot
from brainbulge.solver.step_bounds import Slide, StepCap

log = logging.getLogger("brainbulge")


#: the predictor: the last accepted increment of ``x`` and its load step ``dt``
Predictor = tuple[ngs.BaseVector, float]


class NewtonSolver:
    """A :class:`MixedForm`'s equations (:class:`MixedEquations`), solved with the
    :class:`SolverOptions` it is built with: :meth:`solve` ramps the load to 1,
    :meth:`equilibrate` solves at the form's current load, :meth:`newton` is one Newton
    solve (:func:`brainbulge.solver.newton.newton`)."""

    def __init__(self, form: MixedForm, options: SolverOptions | None = None) -> None:
        self.form = form
        self.opt = options or SolverOptions()
        self.equations = MixedEquations(form, self.opt)
        self.state = self.equations.state
        #: local solves at residual hotspots (MINI; option ``hotspot_relaxation``)
        self.relaxation = (HotspotRelaxation(self.equations, self.opt.hotspot)
                           if self.opt.newton.hotspot_relaxation and HotspotRelaxation.applies(form)
                           else None)
        cap = self.opt.newton.step_cap
        #: the trust region on each update (option ``newton.step_cap``)
        self.step_cap = StepCap(form, cap) if cap > 0 else None

    def newton(self, tolerance: float | None = None,
               limit_step: StepLimit | None = None) -> NewtonResult:
        """One Newton solve at the form's load from its state (:func:`newton`), each update
        within the options' step cap unless ``limit_step`` is given."""
        relax = None if self.relaxation is None else self.relaxation.relax
        return newton(self.equations, self.opt, tolerance, limit_step or self.step_cap,
                      relax=relax)

    def release_linear_solver(self) -> None:
        """Free the linear solver's work memory (:meth:`MixedEquations.release_linear_solver`)."""
        self.equations.release_linear_solver()

    def solve(self) -> Solution:
        """Ramp the load from ``start_load`` (or a restart file's load) to 1
        (:class:`LoadRamp` walked by :func:`~brainbulge.solver.driver.walk`); return the
        last converged state (the form holds it, at its load)."""
        check_feasible(self.equations)
        start = time.perf_counter()
        sol = walk(LoadRamp(self))
        return finished(self.equations, sol, start)

    def equilibrate(self) -> Solution:
        """Newton at the form's current load from its current state (another flap's
        solution), to the final tolerance, without load steps. On failure the state is
        restored and ``converged`` is false."""
        form, state = self.form, self.state
        start = time.perf_counter()
        t = state.load
        sol = Solution(form=form, load=t, converged=False)
        before = state.snapshot()
        res = self.newton()
        sol.newton_results.append(res)
        if res.converged:
            pen = self.equations.max_penetration() if form.contacts_present else 0.0
            sol.steps.append(StepRecord(t, res.iterations, 0, res.norm, pen))
            sol.converged = True
        else:
            state.restore(before)
            sol.rejected_steps = 1
            sol.note = (f"Newton did not converge at load {t:.4f} from the given state "
                        f"(|R| = {res.norm:.2e} after {res.iterations} iterations: "
                        f"{res.detail})")
        return finished(self.equations, sol, start)


class LoadBar:
    """The progress bar over the load (shown with ``options.progress``), in percent."""

    def __init__(self, show: bool, t: float) -> None:
        self.bar = tqdm(total=100, disable=not show, desc="load", unit="%", leave=False)
        self.at(t)

    def at(self, t: float) -> None:
        """The load reached is ``t`` [-]."""
        self.bar.update(round(100 * t) - self.bar.n)

    def close(self) -> None:
        self.bar.close()


class LoadRamp:
    """The load ramp as a path of :func:`~brainbulge.solver.driver.walk`: the parameter is
    the load factor ``t`` from ``start_load`` (or a restart file's load) to 1, each step
    Newton from the predicted state (module docstring), the restart file written after every
    accepted step, the stop hooks of :class:`SolverOptions` asked."""

    target = 1.0

    def __init__(self, solver: NewtonSolver) -> None:
        self.solver = solver
        self.form, self.opt, self.state = solver.form, solver.opt, solver.state
        ramp = self.opt.ramp
        self.control = StepControl(cut=ramp.cut, grow=ramp.grow,
                                   fast_iterations=ramp.fast_iterations,
                                   min_step=ramp.min_step, slide=ramp.slide)
        self.predictor: Predictor | None = None
        self.bar: LoadBar | None = None
        #: the motion that sizes the steps (option ``ramp.slide``)
        self.slide = Slide(self.form) if ramp.slide > 0 else None

    def switch(self, solver: NewtonSolver) -> None:
        """Go on with ``solver`` (another form: a rezoned mesh), without a predictor."""
        self.solver = solver
        self.form, self.state = solver.form, solver.state
        self.predictor = None
        if self.slide is not None:
            self.slide = Slide(self.form)

    def begin(self) -> tuple[float, float, Solution]:
        """``(t, dt, sol)`` from ``start_load`` and ``steps``, or from the restart file
        (which also fills ``sol``'s steps and sets the predictor)."""
        opt = self.opt
        sol = self.sol = Solution(form=self.form, load=0.0, converged=False)
        t, dt = opt.start_load, 1.0 / opt.ramp.steps
        if opt.checkpoint is not None:
            resumed = restart.read(Path(opt.checkpoint), opt.checkpoint_key, self.form, sol)
            if resumed is not None:
                t, dt, increment, last_dt = resumed
                sol.resumed_from = t
                self.predictor = (increment, last_dt)
        self.bar = LoadBar(opt.progress, t)
        return t, dt, sol

    def snapshot(self) -> Snapshot:
        return self.state.snapshot()

    def restore(self, snap: Snapshot) -> None:
        self.state.restore(snap)

    def attempt(self, t: float, dt: float, last: Snapshot) -> Tried:
        """Newton at load ``t`` (a step ``dt`` on) from the predicted state, extrapolating
        the last increment, ``x_pred = x_last + (dt / dt_last) increment`` (``last``: the
        last converged state)."""
        form, opt, state = self.form, self.opt, self.state
        sol_results = self.sol.newton_results
        form.set_load(t)
        if self.predictor is not None and opt.ramp.predictor:
            increment, last_dt = self.predictor
            state.x.data = last.x + (dt / last_dt) * increment
            form.set_load(t)  # exact prescribed values over the predictor
        newton_tol = opt.newton.tolerance
        tol = newton_tol if t >= REACHED else max(newton_tol, opt.ramp.intermediate_tolerance)
        res = self.solver.newton(tol)
        sol_results.append(res)
        motion = None
        if res.converged and self.slide is not None:
            motion = self.slide(last.x.FV().NumPy(), state.x.FV().NumPy())
        return Tried(res.converged, res.iterations, res, motion)

    def accept(self, t: float, dt: float, last: Snapshot, tried: Tried,
               sol: Solution) -> None:
        """Record the step to ``t``; the increment from ``last`` is the next predictor."""
        state = self.state
        pen = self.solver.equations.max_penetration() if self.form.contacts_present else 0.0
        increment = state.x.CreateVector()
        increment.data = state.x - last.x
        self.predictor = (increment, dt)
        self.bar.at(t)
        sol.steps.append(StepRecord(t, tried.iterations, 0, tried.result.norm, pen))
        log.info("  load %.4f: %d Newton iterations, |R| = %.2e%s", t, tried.iterations,
                 tried.result.norm, "" if tried.motion is None
                 else f", moved {tried.motion:.2f} element sizes")

    def rejected(self, t: float, dt: float, tried: Tried, sol: Solution) -> bool:
        """The step to ``t + dt`` failed: the hook ``stop_on_failure`` may stop here."""
        opt = self.opt
        if opt.stop_on_failure is not None and opt.stop_on_failure(t):
            sol.stopped_early = True
            sol.note = f"stopped at load {t:.4f} (stop_on_failure)"
            return True
        res = tried.result
        log.info("  load %.4f: not converged (|R| = %.2e, %s), cutting step", t + dt,
                 res.norm, res.detail)
        return False

    def failed(self, t: float, dt: float, tried: Tried, sol: Solution) -> None:
        res = tried.result
        sol.failure = Failure(load=t + dt, step=dt, kept=t, site=res.site, residual=res.norm,
                              iterations=res.iterations, reason=res.detail)

    def settled(self, t: float, dt: float, sol: Solution) -> bool:
        """The restart file; the hook ``stop_when`` may stop here."""
        opt = self.opt
        if opt.checkpoint is not None:
            increment, last_dt = self.predictor
            restart.write(Path(opt.checkpoint), opt.checkpoint_key, self.form, self.state.x,
                          t, dt, increment, last_dt, sol)
        if opt.stop_when is not None and t < REACHED and opt.stop_when():
            sol.stopped_early = True
            sol.note = f"stopped at load {t:.4f} (stop_when)"
            return True
        return False

    def transfer(self, s: float, sol: Solution, failed: bool) -> float | None:
        return None  # one discretisation throughout

    def end(self, last: Snapshot, t: float, sol: Solution) -> Solution:
        """The form at the last converged state and its load ``t``."""
        self.bar.close()
        self.state.restore(last)
        self.form.load.Set(t)
        sol.load = t
        return sol


def check_feasible(eq: MixedEquations) -> None:
    """A body with no traction-free boundary cannot swell (the skull is rigid): contact
    boundaries count as free where they are off the skull at rest (an opening)."""
    form = eq.form
    solver = eq
    problem = form.problem
    if problem.traction_free_boundaries():
        return
    free_contact = sum(pc.free_measure(0.01 * form.h)
                       for pc in [*form.point_contacts, *form.penalty_contacts])
    if free_contact > 1e-9 * solver.length ** (problem.dim - 1):
        return
    added = float(ngs.Integrate(form.Js - 1, problem.mesh))
    if added > 1e-12 * solver.volume:
        raise InfeasibleError(
            f"infeasible: swelling adds {added:.4g} (volume units) but every boundary is "
            "clamped or against the rigid skull, a closed domain; open part of the "
            "boundary (a craniectomy opening)"
        )


def finished(solver: MixedEquations, sol: Solution, start: float) -> Solution:
    """``sol`` with the penetration and swelling reached, the wall, assembly and
    linear-solve times and the Krylov iterations."""
    form = solver.form
    sol.max_penetration = solver.max_penetration()
    swelling = [float(v) for v in form.problem.swelling.values()]
    sol.target_swelling = max(swelling, key=lambda js: abs(js - 1), default=1.0)
    sol.wall_time_s = time.perf_counter() - start
    return costs_of(solver).into(sol)


def costs_of(eq: MixedEquations) -> Costs:
    """What ``eq``'s solves cost so far: assembly and linear-solve times [s], Krylov
    iterations."""
    return Costs(eq.t_assembly, eq.t_solve, int(sum(eq.linear.stats.iterations)))

"""Continuation in the stiffness contrast between regions: Newton at full load from a
carried-over state, through stiffer soft regions first.

Newton's tangent on a fine brain mesh loses definiteness where the ultrasoft CSF (``mu`` 33 kPa
against 333-666 kPa in the parenchyma, docs/model.md section 2) is pressed onto the skull's
rounded cut edge: the contacts' curvature term ``A_i lambda_i / r`` outweighs the CSF's
stiffness, and from a state carried over from a coarse mesh Newton stagnates at the flap's rim
(docs/known-limits.md). With the CSF as stiff as gray matter the same fine stage converges in a
few iterations. So the fine stage walks a path in the materials' parameters instead, as the
load ramp walks one in ``Js``: each region's shear modulus is raised to at least ``mu_max /
kappa``,

    mu_r(kappa) = max(mu_r, mu_max / kappa)       (c1, c2 or c_i scaled alike: c1/c2 kept),

starting from ``kappa_0 = ContrastOptions.start`` (the parenchyma's own contrast, white over
gray) and multiplying ``kappa`` by ``ContrastOptions.factor`` up to the model's contrast
``kappa_model = mu_max / mu_min``; every step is Newton at full load from the last
equilibrium, which must lower the scaled residual by ``ContrastOptions.progress_factor``
within ``progress_iterations`` (10x within 3 iterations by default): a healthy step
converges quadratically, while the 1.40M-tet template's last step fell 1.7x in 3 iterations
of ~3 minutes each and then stagnated. A step that fails ends the path and the caller falls
back (mesh sequencing: to the load ramp).
The last step is the model itself: the state reached is its equilibrium to the solver's
tolerance, the intermediate materials are only the way there. A problem whose contrast is
at most ``ContrastOptions.start`` takes one step, the plain Newton solve.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from collections.abc import Callable

from brainbulge.solver.driver import StepControl, Tried, walk
from brainbulge.solver.mixed import MixedForm
from brainbulge.solver.options import (
    ContrastOptions,
    Costs,
    Solution,
    SolverOptions,
    StepRecord,
)
from brainbulge.solver.ramp import NewtonSolver
from brainbulge.solver.state import State

log = logging.getLogger("brainbulge")


def contrast(materials: dict) -> float:
    """``mu_max / mu_min`` over the regions' materials."""
    mu = [m.shear_modulus for m in materials.values()]
    return max(mu) / min(mu)


def capped_materials(materials: dict, kappa: float) -> dict:
    """The materials with every shear modulus raised to at least ``mu_max / kappa`` (each
    material scaled as a whole, :meth:`scaled`); unchanged where it already is."""
    mu_max = max(m.shear_modulus for m in materials.values())
    floor = mu_max / kappa
    return {r: m if m.shear_modulus >= floor else m.scaled(floor / m.shear_modulus)
            for r, m in materials.items()}


def contrast_path(materials: dict, path_options: ContrastOptions) -> list[float]:
    """The contrasts of the path's steps: ``start`` times powers of ``factor``
    (``path_options``), ending at the model's (one step when that is not larger)."""
    target = contrast(materials)
    path = [min(path_options.start, target)]
    while path[-1] < target * (1 - 1e-12):
        path.append(min(path[-1] * path_options.factor, target))
    return path


class ContrastPath:
    """The contrast path as a path of :func:`~brainbulge.solver.driver.walk`: the parameter
    is the position on :func:`contrast_path` (step ``k`` solves at its ``k``-th contrast,
    the last at the model itself), each step Newton at ``form``'s load from the last step's
    equilibrium (the first from ``start``) on a form of the capped materials. A step that
    fails ends the path (no cut, no growth): the caller falls back."""

    #: one step per contrast, never cut nor grown
    control = StepControl(cut=0.0, grow=1.0, fast_iterations=0, min_step=1.0)

    def __init__(self, form: MixedForm, options: SolverOptions,
                 start: Callable[[MixedForm], None]) -> None:
        self.form, self.start = form, start
        self.path = contrast_path(form.problem.materials, options.contrast)
        self.target = float(len(self.path))
        progress = (options.contrast.progress_iterations, options.contrast.progress_factor)
        self.options = (dataclasses.replace(options, required_progress=progress)
                        if len(self.path) > 1 else options)
        self.previous: MixedForm | None = None
        self.step_form: MixedForm | None = None
        self.last_sol: Solution | None = None
        self.records: list[StepRecord] = []
        self.costs = Costs()
        #: the scaled residual of the start state on the first step's form [-]
        self.first: float | None = None

    def begin(self) -> tuple[float, float, Solution]:
        self.t0 = time.perf_counter()
        return 0.0, 1.0, Solution(form=self.form, load=float(self.form.load.Get()),
                                  converged=False)

    def snapshot(self) -> None:
        return None  # a failed step ends the path; its Newton solve restored its own state

    def restore(self, snap: None) -> None:
        pass

    def attempt(self, s: float, ds: float, last: None) -> Tried:
        """Newton at the contrast of position ``s`` (the model's at the last)."""
        problem, form = self.form.problem, self.form
        kappa = self.path[round(s) - 1]
        step_form = form if s >= self.target else MixedForm(
            dataclasses.replace(problem, materials=capped_materials(problem.materials, kappa)),
            element=form.element, compile_energy=form.compile_energy)
        if self.previous is None:
            self.start(step_form)
        else:
            _copy_state(self.previous, step_form)
        solver = NewtonSolver(step_form, self.options)
        sol = solver.equilibrate()
        solver.release_linear_solver()
        if self.first is None and sol.newton_results:
            self.first = sol.newton_results[0].residuals[0]
        self.records += sol.steps
        self.costs.add(sol)
        if len(self.path) > 1:
            log.info("  contrast %.3g of %.3g: %s in %d Newton iterations", kappa,
                     self.path[-1], "converged" if sol.converged else "not converged",
                     sol.newton_iterations)
        self.step_form, self.last_sol = step_form, sol
        return Tried(sol.converged, sol.newton_iterations, sol)

    def accept(self, s: float, ds: float, last: None, tried: Tried, sol: Solution) -> None:
        self.previous = self.step_form

    def rejected(self, s: float, ds: float, tried: Tried, sol: Solution) -> bool:
        return False

    def failed(self, s: float, ds: float, tried: Tried, sol: Solution) -> None:
        kappa = self.path[round(s + ds) - 1]
        tried.result.note += f" (contrast path stopped at {kappa:.3g} of {self.path[-1]:.3g})"

    def settled(self, s: float, ds: float, sol: Solution) -> bool:
        return False

    def transfer(self, s: float, sol: Solution, failed: bool) -> float | None:
        return None  # one discretisation throughout

    def end(self, last: None, s: float, sol: Solution) -> Solution:
        """The last step's solution, with the Newton iterations of the whole path in one
        record at the form's load (the path's steps are not load steps) and its costs."""
        final = self.last_sol
        if final is None:
            return sol
        if final.converged:
            final.steps = [dataclasses.replace(
                final.steps[-1], newton_iterations=sum(r.newton_iterations
                                                       for r in self.records))]
        self.costs.into(final)
        final.wall_time_s = time.perf_counter() - self.t0
        return final


def equilibrate_through_contrast(form: MixedForm, options: SolverOptions,
                                 start: Callable[[MixedForm], None]
                                 ) -> tuple[Solution, float | None]:
    """Newton at ``form``'s load through the contrast path (module docstring;
    :class:`ContrastPath` walked by :func:`~brainbulge.solver.driver.walk`); ``start(f)``
    puts the start state into a form ``f`` on ``form``'s mesh (e.g. carries a coarse state
    over). Returns the solution on ``form`` (Newton and Krylov iterations and times of the
    whole path, in one :class:`StepRecord` at the form's load; ``converged`` false if the path
    gave up, and ``form``'s state is then not an equilibrium) and the scaled residual of the
    start state on the first step's form. The linear solvers' memory is released."""
    path = ContrastPath(form, options, start)
    sol = walk(path)
    return sol, path.first


def _copy_state(source: MixedForm, target: MixedForm) -> None:
    """``target`` (same mesh and spaces) at ``source``'s state, load and contact pressures."""
    State(target).restore(State(source).snapshot())
    target.set_load(float(source.load.Get()))
    x = target.gfu.vec.FV().NumPy()
    for pc in target.point_contacts:
        pc.update(x)

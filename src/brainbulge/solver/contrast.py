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

from brainbulge.solver.mixed import MixedForm
from brainbulge.solver.options import ContrastOptions, Costs, Solution, SolverOptions
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


def equilibrate_through_contrast(form: MixedForm, options: SolverOptions,
                                 start: Callable[[MixedForm], None]
                                 ) -> tuple[Solution, float | None]:
    """Newton at ``form``'s load through the contrast path (module docstring); ``start(f)``
    puts the start state into a form ``f`` on ``form``'s mesh (e.g. carries a coarse state
    over). Returns the solution on ``form`` (Newton and Krylov iterations and times of the
    whole path, in one :class:`StepRecord` at the form's load; ``converged`` false if the path
    gave up, and ``form``'s state is then not an equilibrium) and the scaled residual of the start
    state on the first step's form. The linear solvers' memory is released."""
    t0 = time.perf_counter()
    problem = form.problem
    path = contrast_path(problem.materials, options.contrast)
    target = path[-1]
    kappa = path[0]
    previous: MixedForm | None = None
    progress = (options.contrast.progress_iterations, options.contrast.progress_factor)
    step_options = (dataclasses.replace(options, required_progress=progress)
                    if len(path) > 1 else options)
    records, costs = [], Costs()
    first: float | None = None
    while True:
        step_form = form if kappa >= target else MixedForm(
            dataclasses.replace(problem, materials=capped_materials(problem.materials, kappa)),
            element=form.element, compile_energy=form.compile_energy)
        if previous is None:
            start(step_form)
        else:
            _copy_state(previous, step_form)
        solver = NewtonSolver(step_form, step_options)
        sol = solver.equilibrate()
        solver.release_linear_solver()
        if first is None and sol.newton_results:
            first = sol.newton_results[0].residuals[0]
        records += sol.steps
        costs.add(sol)
        if len(path) > 1:
            log.info("  contrast %.3g of %.3g: %s in %d Newton iterations", kappa, target,
                     "converged" if sol.converged else "not converged",
                     sol.newton_iterations)
        if not sol.converged:
            sol.note += f" (contrast path stopped at {kappa:.3g} of {target:.3g})"
            break
        if step_form is form:
            break
        previous, kappa = step_form, min(kappa * options.contrast.factor, target)
    if sol.converged:  # one record at full load: the path's steps are not load steps
        sol.steps = [dataclasses.replace(
            sol.steps[-1], newton_iterations=sum(r.newton_iterations for r in records))]
    costs.into(sol)
    sol.wall_time_s = time.perf_counter() - t0
    return sol, first


def _copy_state(source: MixedForm, target: MixedForm) -> None:
    """``target`` (same mesh and spaces) at ``source``'s state, load and contact pressures."""
    State(target).restore(State(source).snapshot())
    target.set_load(float(source.load.Get()))
    x = target.gfu.vec.FV().NumPy()
    for pc in target.point_contacts:
        pc.update(x)

"""Load stepping with rezoning (2D): the mesh is exchanged when its image degenerates.

The load ramp (:class:`~brainbulge.solver.ramp.LoadRamp`) walks the load on one mesh;
:class:`RezoningRamp` holds it and adds the continuation's transfer between steps: after an
accepted load step below full load whose deformed triangles' smallest shape quality ``q = 4
sqrt(3) A / sum l^2`` has fallen below ``q_min`` (or after a step that failed on a mesh that
has deformed since it was made), the deformed domain is meshed afresh and pulled back to the
reference configuration (:func:`brainbulge.geometry.rezone.rezone`), the state ``(u, p,
lambda)`` is carried over, and the ramp goes on from the same load. The material is
hyperelastic, so the converged state at a load does not depend on the mesh history: rezoning
changes the discretisation, not the problem. The carried-over state is first equilibrated at
the same load (in at most ``equilibration_iterations`` Newton iterations); if that (or the
remeshing) fails, the old mesh keeps its converged state and the ramp goes on there without
rezoning. That old mesh may itself be a rezoned one, so a run can end earlier than the plain
ramp on the first mesh would: sliding alpha 80 / beta 30 reaches load 0.62 with rezoning and
0.77 without it (docs/known-limits.md); after ``max_rezones`` rezonings it goes on without
them too. ``q_min``, ``equilibration_iterations`` and ``max_rezones`` are
``SolverOptions.rezoning`` (:class:`~brainbulge.solver.options.RezoningOptions`).
"""

from __future__ import annotations

import dataclasses
import logging
import time
from collections.abc import Callable, Sequence

import ngsolve as ngs
import numpy as np
from netgen.libngpy._meshing import NgException
from scipy.spatial import cKDTree

from brainbulge.errors import ConvergenceError
from brainbulge.geometry.rezone import (
    Projector,
    Rezoned,
    deformed_quality,
    rezone,
    vertex_values,
)
from brainbulge.model.problem import Problem
from brainbulge.solver.contact.points import edge_bubble_midpoint_value
from brainbulge.solver.driver import REACHED, Tried, walk
from brainbulge.solver.mixed import MixedForm
from brainbulge.solver.options import Costs, Solution, SolverOptions
from brainbulge.solver.ramp import LoadRamp, NewtonSolver, check_feasible, costs_of, finished
from brainbulge.solver.state import Snapshot

log = logging.getLogger("brainbulge")


@dataclasses.dataclass
class Rezoning:
    """How to remesh: ``problem_on(mesh)`` rebuilds the problem on a new reference mesh,
    ``project(label, X)`` moves points onto the reference curve ``label``; sizes [length]
    and the reference singular points ``corners`` (refined to ``h_corner``), and reference
    points ``rim_points`` (n, 2) refined to ``h_rim``."""

    problem_on: Callable[[ngs.Mesh], Problem]
    project: Projector
    h: float
    h_corner: float
    corners: Sequence[tuple[float, float]]
    rim_points: np.ndarray | None = None
    h_rim: float | None = None


def solve_with_rezoning(
    problem: Problem,
    rezoning: Rezoning,
    element: str = "taylor-hood",
    options: SolverOptions | None = None,
) -> Solution:
    """Ramp the swelling to full load, rezoning as needed (:class:`RezoningRamp` walked by
    :func:`~brainbulge.solver.driver.walk`); the solution's form holds the final mesh and
    state. ``Solution.rezones`` counts the mesh exchanges."""
    start = time.perf_counter()
    path = RezoningRamp(problem, rezoning, element, options or SolverOptions())
    check_feasible(path.ramp.solver.equations)
    return path.finish(walk(path), start)


class RezoningRamp:
    """The load ramp (:class:`~brainbulge.solver.ramp.LoadRamp`, which it holds) with a
    transfer between steps: after an accepted step below full load whose deformed mesh has
    degenerated (``q < q_min``), or after a failed step on a mesh that has deformed since it
    was made, the mesh is exchanged (:meth:`transfer`, module docstring) and the ramp goes
    on from the same load with its first step and no predictor. After a rezoning that fails,
    or ``max_rezones`` of them, the ramp goes on without rezoning."""

    target = 1.0

    def __init__(self, problem: Problem, rezoning: Rezoning, element: str,
                 options: SolverOptions) -> None:
        self.rezoning, self.element, self.options = rezoning, element, options
        self.ramp = LoadRamp(NewtonSolver(MixedForm(problem, element=element), options))
        self.control = self.ramp.control
        self.t_mesh = options.start_load  # the load at which the current mesh was made
        self.rezones = 0
        self.gave_up = ""  # why the last rezoning failed: then the ramp goes on without it
        self.costs = Costs()  # of the solvers of the meshes left behind

    def begin(self) -> tuple[float, float, Solution]:
        return self.ramp.begin()

    def snapshot(self) -> Snapshot:
        return self.ramp.snapshot()

    def restore(self, snap: Snapshot) -> None:
        self.ramp.restore(snap)

    def attempt(self, t: float, dt: float, last: Snapshot) -> Tried:
        return self.ramp.attempt(t, dt, last)

    def accept(self, t: float, dt: float, last: Snapshot, tried: Tried,
               sol: Solution) -> None:
        self.ramp.accept(t, dt, last, tried, sol)

    def rejected(self, t: float, dt: float, tried: Tried, sol: Solution) -> bool:
        return self.ramp.rejected(t, dt, tried, sol)

    def failed(self, t: float, dt: float, tried: Tried, sol: Solution) -> None:
        self.ramp.failed(t, dt, tried, sol)

    def settled(self, t: float, dt: float, sol: Solution) -> bool:
        return self.ramp.settled(t, dt, sol)

    def end(self, last: Snapshot, t: float, sol: Solution) -> Solution:
        return self.ramp.end(last, t, sol)

    def transfer(self, t: float, sol: Solution, failed: bool) -> float | None:
        """At load ``t`` after an accepted (``failed`` false) or a failed step: the mesh
        exchanged if it is due, and the ramp's next step (None: not due, go on)."""
        form, opt = self.ramp.form, self.options
        if self.gave_up or self.rezones >= opt.rezoning.max_rezones:
            return None
        if failed:
            due = t > self.t_mesh  # a failure on a mesh that has deformed since
        else:
            due = (t < REACHED
                   and float(deformed_quality(form.mesh, form.u).min()) < opt.rezoning.q_min)
        if not due:
            return None
        q = float(deformed_quality(form.mesh, form.u).min())
        log.info("  rezoning at load %.4f (smallest deformed quality %.3f)", t, q)
        try:
            new, its = self._rezoned(form, t)
        except (ConvergenceError, RuntimeError, NgException) as exc:
            # the old mesh keeps the last converged state; go on there without rezoning
            self.gave_up = f"rezoning at load {t:.4f} failed: {exc}"
            log.warning("  %s; going on without rezoning", self.gave_up)
            new = form
        else:
            sol.steps[-1].newton_iterations += its
            self.rezones += 1
        self.costs.add(costs_of(self.ramp.solver.equations))
        self.ramp.switch(NewtonSolver(new, opt))  # a solver per mesh (its costs summed)
        self.t_mesh = t
        return 1.0 / opt.ramp.steps

    def _rezoned(self, form: MixedForm, t: float) -> tuple[MixedForm, int]:
        """The deformed domain meshed afresh, the state carried over and equilibrated at
        load ``t``: the new form and the equilibration's Newton iterations."""
        rz_ = self.rezoning
        rz = rezone(form.mesh, form.u, rz_.project, rz_.h, rz_.h_corner, rz_.corners,
                    rz_.rim_points, rz_.h_rim)
        new = MixedForm(rz_.problem_on(rz.mesh), element=self.element)
        transfer_state(form, new, rz)
        new_solver = NewtonSolver(new, dataclasses.replace(
            self.options, max_iterations=self.options.rezoning.equilibration_iterations))
        new.set_load(t)
        # equilibrate the carried-over state on the new mesh before the ramp goes on
        res = new_solver.newton()
        its = res.iterations
        log.info("  rezoned mesh at load %.4f: |R| %.2e -> %.2e in %d Newton iterations",
                 t, res.residuals[0], res.norm, its)
        if not res.converged:
            raise ConvergenceError(f"the carried-over state did not equilibrate "
                                   f"(|R| = {res.norm:.2e} after {its} iterations: "
                                   f"{res.detail})")
        return new, its

    def finish(self, sol: Solution, start: float) -> Solution:
        """The walk's solution on the last mesh, with the costs of every mesh's solver."""
        sol = finished(self.ramp.solver.equations, sol, start)
        self.costs.add(sol).into(sol)
        sol.form = self.ramp.form
        sol.stopped_early = False
        sol.rezones = self.rezones
        if not sol.converged and not sol.message:
            sol.note = f"stopped at load {sol.load:.4f}"
        if self.gave_up and not sol.converged:
            sol.context = self.gave_up
        return sol


def transfer_state(old: MixedForm, new: MixedForm, rz: Rezoned) -> None:
    """Carry ``u``, ``p`` and the point-contact pressures from ``old`` to ``new``'s mesh:
    ``u`` at vertices from the pull-back, at P2 edge midpoints evaluated on the old mesh,
    ``p`` per pressure zone at the vertices (evaluated just inside each zone's elements), and
    each contact point's pressure from the nearest old contact point (deformed positions)."""
    mesh = new.mesh
    V = new.fes.components[0]
    uvec = new.u.vec.FV().NumPy()
    uvec[:] = 0
    for v in range(mesh.nv):
        for i, dof in enumerate(V.GetDofNrs(ngs.NodeId(ngs.VERTEX, v))[: mesh.dim]):
            uvec[dof] = rz.u_vertices[v, i]
    X = np.array([p.point for p in mesh.vertices])[:, : mesh.dim]
    if V.globalorder >= 2:
        beta = edge_bubble_midpoint_value(mesh, V)
        ends = np.array([[v.nr for v in e.vertices] for e in mesh.edges])
        mid = 0.5 * (X[ends[:, 0]] + X[ends[:, 1]])
        inward = mid.copy()  # the centroid of a triangle at each edge
        for el in mesh.Elements(ngs.VOL):
            c = X[[v.nr for v in el.vertices]].mean(axis=0)
            for e in el.edges:
                inward[e.nr] = c
        u_mid = vertex_values(old.mesh, old.u, mid, inward=inward)
        bubble = (u_mid - 0.5 * (rz.u_vertices[ends[:, 0]] + rz.u_vertices[ends[:, 1]])) / beta
        bubble[~np.isfinite(bubble)] = 0.0
        for e in range(len(ends)):
            for i, dof in enumerate(V.GetDofNrs(ngs.NodeId(ngs.EDGE, e))[: mesh.dim]):
                uvec[dof] = bubble[e, i]
    for k, zone in enumerate(new.pressure_zones):
        Q = new.fes.components[1 + k]
        old_p = old.gfu.components[1 + k]
        pvec = new.gfu.components[1 + k].vec.FV().NumPy()
        in_zone = mesh.Materials(zone).Mask()
        tris = np.array([[v.nr for v in el.vertices] for el in mesh.Elements(ngs.VOL)
                         if in_zone[el.index]])
        inner = X[tris] + 1e-3 * (X[tris].mean(axis=1, keepdims=True) - X[tris])
        vals = vertex_values(old.mesh, old_p, inner.reshape(-1, mesh.dim))[:, 0]
        for v, val in zip(tris.ravel(), vals, strict=True):
            if np.isfinite(val):
                pvec[Q.GetDofNrs(ngs.NodeId(ngs.VERTEX, int(v)))[0]] = val
    new.set_load(old.load.Get())
    carry_contact_pressures(old, new)


def carry_contact_pressures(old: MixedForm, new: MixedForm) -> None:
    """Each of ``new``'s contact points takes the pressure of ``old``'s nearest one (at the
    deformed positions of both states)."""
    for pc_old, pc_new in zip(old.point_contacts, new.point_contacts, strict=True):
        pc_old.update(old.gfu.vec.FV().NumPy())
        pc_new.update(new.gfu.vec.FV().NumPy())
        _, idx = cKDTree(pc_old.x).query(pc_new.x)
        pc_new.lam = pc_old.lam[idx].copy()

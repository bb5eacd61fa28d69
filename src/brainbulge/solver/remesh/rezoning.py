"""Load stepping with rezoning (2D): the mesh is exchanged when its image degenerates.

:class:`NewtonSolver` ramps the load on one mesh. Here the ramp stops after an accepted load
step when the deformed triangles' smallest shape quality ``q = 4 sqrt(3) A / sum l^2`` falls
below ``q_min`` (or when a step fails on a mesh that has deformed since the last rezoning),
the deformed domain is meshed afresh and pulled back to the reference configuration
(:func:`brainbulge.geometry.rezone.rezone`), the state ``(u, p, lambda)`` is carried over,
and the ramp goes on from the same load. The material is hyperelastic, so the converged
state at a load does not depend on the mesh history: rezoning changes the discretisation,
not the problem. The carried-over state is first equilibrated at the same load (in at most
``equilibration_iterations`` Newton iterations); if that (or the
remeshing) fails, the old mesh keeps its converged state and the ramp goes on there without
rezoning. That old mesh may itself be a rezoned one, so a run can end earlier than the plain
ramp on the first mesh would: sliding alpha 80 / beta 30 reaches load 0.62 with rezoning and
0.77 without it (docs/known-limits.md). ``q_min``, ``equilibration_iterations`` and
``max_rezones`` are ``SolverOptions.rezoning``
(:class:`~brainbulge.solver.options.RezoningOptions`).
"""

from __future__ import annotations

import dataclasses
import logging
import time
from collections.abc import Callable, Sequence

import ngsolve as ngs
import numpy as np
from netgen.libngpy._meshing import NgException

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
from brainbulge.solver.mixed import MixedForm
from brainbulge.solver.options import Costs, Solution, SolverOptions
from brainbulge.solver.ramp import NewtonSolver
from brainbulge.solver.remesh.sequencing import carry_contact_pressures

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
    """Ramp the swelling to full load, rezoning as needed; the solution's form holds the
    final mesh and state. ``Solution.rezones`` counts the mesh exchanges."""
    options = options or SolverOptions()
    start = time.perf_counter()
    form = MixedForm(problem, element=element)
    total: Solution | None = None
    t, rezones = options.start_load, 0
    failed = ""  # why the last rezoning failed: then the ramp goes on without it
    while True:
        def degenerate(f: MixedForm = form) -> bool:
            return float(deformed_quality(f.mesh, f.u).min()) < options.rezoning.q_min

        def moved(t_now: float, t_mesh: float = t) -> bool:
            return t_now > t_mesh + 1e-9  # a failure on a mesh that has deformed since

        hooks = {} if failed else {"stop_when": degenerate, "stop_on_failure": moved}
        # a solver per segment (its times too: summed by _merged)
        solver = NewtonSolver(form, dataclasses.replace(options, start_load=t, **hooks))
        sol = solver.solve()
        total = sol if total is None else _merged(total, sol)
        if sol.converged or rezones >= options.rezoning.max_rezones:
            break
        if not sol.stopped_early:
            break  # failed on a fresh mesh: rezoning cannot help
        q = float(deformed_quality(form.mesh, form.u).min())
        log.info("  rezoning at load %.4f (smallest deformed quality %.3f)", sol.load, q)
        try:
            rz = rezone(form.mesh, form.u, rezoning.project, rezoning.h, rezoning.h_corner,
                        rezoning.corners, rezoning.rim_points, rezoning.h_rim)
            new = MixedForm(rezoning.problem_on(rz.mesh), element=element)
            transfer_state(form, new, rz)
            new_solver = NewtonSolver(
                new, dataclasses.replace(
                    options, max_iterations=options.rezoning.equilibration_iterations))
            new.set_load(sol.load)
            # equilibrate the carried-over state on the new mesh before the ramp goes on
            res = new_solver.newton()
            its = res.iterations
            log.info("  rezoned mesh at load %.4f: |R| %.2e -> %.2e in %d Newton iterations",
                     sol.load, res.residuals[0], res.norm, its)
            if not res.converged:
                raise ConvergenceError(f"the carried-over state did not equilibrate "
                                       f"(|R| = {res.norm:.2e} after {its} iterations: "
                                       f"{res.detail})")
        except (ConvergenceError, RuntimeError, NgException) as exc:
            # the old mesh keeps the last converged state; go on there without rezoning
            failed = f"rezoning at load {sol.load:.4f} failed: {exc}"
            log.warning("  %s; going on without rezoning", failed)
            t = sol.load
            continue
        form, t = new, sol.load
        total.steps[-1].newton_iterations += its
        rezones += 1
    total.form = form
    total.converged = sol.converged
    total.stopped_early = False
    total.rezones = rezones
    total.wall_time_s = time.perf_counter() - start
    if not sol.converged and not sol.message:
        total.note = f"stopped at load {sol.load:.4f}"
    if failed and not sol.converged:
        total.context = failed
    return total


def _straighten_folded(form: MixedForm) -> None:
    """Zero the edge bubbles of elements where ``det F <= 0`` somewhere: the old map
    interpolated over a new element may fold it, the straight deformed triangle (netgen's
    own, positively oriented) never does."""
    mesh = form.mesh
    V = form.fes.components[0]
    uvec = form.u.vec.FV().NumPy()
    folded_cf = ngs.IfPos(1e-6 - ngs.Det(form.F()), 1.0, 0.0)
    for _ in range(3):
        folded = np.asarray(ngs.Integrate(folded_cf, mesh, order=4, element_wise=True))
        bad = np.flatnonzero(folded > 0)
        if not len(bad):
            return
        log.debug("  rezoning: straightening %d folded elements", len(bad))
        for k in bad:
            for e in mesh[ngs.ElementId(ngs.VOL, int(k))].edges:
                uvec[list(V.GetDofNrs(ngs.NodeId(ngs.EDGE, e.nr)))] = 0.0


def _merged(a: Solution, b: Solution) -> Solution:
    """``b`` continuing ``a`` (steps, counts and times added)."""
    b.steps = a.steps + b.steps
    b.rejected_steps += a.rejected_steps
    b.newton_results = a.newton_results + b.newton_results
    return Costs().add(b).add(a).into(b)


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
        _straighten_folded(new)
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


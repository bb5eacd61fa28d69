"""Mesh sequencing (nested iteration): a coarse solution as the fine mesh's Newton start.

On a fine mesh the load ramp spends its Newton iterations on the path, not on the resolution:
the 1.54M-tet brain needs 15 iterations over three load steps at ~2 minutes each. The
hyperelastic state at full load does not depend on the path, so it can be approached from
a cheaper start: solve the same problem on a coarse mesh of the same domain (all load
steps, seconds per iteration), carry the converged state ``(u, p, lambda)`` over to the
fine mesh, and let Newton finish there at full load. How far that start is from the fine
solution is set by the coarse mesh's discretisation error, not by the load increment.
Measured at 1.54M tets from 111k: 9 fine Newton iterations instead of 15, solve time -30 %.
Frictionless contact on a curved skull may have more than one equilibrium: the state
reached can differ slightly from the ramp's (at 111k tets by <= 0.11 mm at a vertex, with
the lower strain energy; docs/design.md, "Mesh sequencing (3D)").

The carried-over state (:func:`interpolate_state`):

- ``u`` at each fine vertex: the coarse ``u`` evaluated there (linear interpolation; a vertex
  outside the coarse mesh, where the two meshes' curved boundaries differ, is moved towards
  the centroid of one of its elements until it is found, else takes the nearest found value);
- ``p`` per pressure zone at each vertex of the zone: the coarse ``p_z`` where the coarse
  element found there belongs to the same zone, else 0 (the pressure jumps across zones, and
  the two meshes' zone interfaces differ). Not the nearest coarse vertex of the zone: in the
  brain's CSF, one coarse element thick, 58 % of the 1.40M-tet mesh's CSF vertices took
  their pressure that way, and the fine tangent there was out of the preconditioner's reach
  (GMRES at 2.4e-3 after 300 iterations, rtol 1e-4; nor the pressure of the coarse zone
  found there: 4.1e-3 after 200); with those values 0, 44 iterations;
- each contact point's pressure from the nearest coarse contact point (deformed positions),
  and the points that carry pressure are moved along the obstacle's normal onto it,
  ``u_i <- u_i - g_i n_i / |n_i|^2``, three times (the two meshes' boundaries differ by up
  to ~3 mm on the brain; with ``u_i - g_i n_i`` alone, where the sampled skull's
  ``|grad g|`` is 1.13, 212 of the 1.54M-tet brain's contact points were left > 0.1 mm
  inside the skull, up to 0.70 mm), except where that would fold an element
  (:func:`press_onto_obstacles`).

Newton on the fine mesh walks from that start through the regions' stiffness contrast
(:mod:`brainbulge.solver.contrast`: the soft CSF first as stiff as gray matter, then its own
stiffness in steps). If that does not converge, the fine mesh ramps the load from ``Js = 1``
as without sequencing: sequencing never ends a run that the plain ramp would finish.

P1-based displacements (MINI) only: the vertex values are all the state there is (the
bubbles are condensed). Written by hand: NGSolve interpolates between meshes only of one
refinement hierarchy, and neither meshio nor pyvista carries a mixed state.
"""

from __future__ import annotations

import dataclasses
import logging
import time

import numpy as np
from scipy.spatial import cKDTree

from brainbulge.errors import InputError
from brainbulge.geometry.ngsolve_arrays import element_vertices, vertex_coordinates, vertex_dofs
from brainbulge.geometry.rezone import vertex_values
from brainbulge.solver.contrast import equilibrate_through_contrast
from brainbulge.solver.driver import fallback
from brainbulge.solver.mixed import MixedForm
from brainbulge.solver.options import Costs, Solution, SolverOptions
from brainbulge.solver.ramp import NewtonSolver

log = logging.getLogger("brainbulge")


@dataclasses.dataclass
class Sequenced:
    """What the coarse stage did (for the summary and the benchmark)."""

    coarse_elements: int
    coarse_converged: bool
    coarse_newton_iterations: int
    coarse_wall_time_s: float
    transfer_time_s: float
    initial_residual: float | None  # scaled |R| of the carried-over state (fine mesh)
    fine_converged: bool  # Newton from the carried-over state (else the plain ramp ran)


def interpolate_state(old: MixedForm, new: MixedForm, fold_ratio: float) -> None:
    """Carry ``(u, p, lambda)`` and the load of ``old`` over to ``new``, a mesh of the same
    reference domain (see the module docstring); ``fold_ratio``: that of
    :func:`press_onto_obstacles`."""
    if new.element != "mini" or old.element != "mini":
        raise InputError("mesh sequencing needs the MINI element (P1 + bubble / P1)")
    if old.pressure_zones != new.pressure_zones:
        raise InputError("mesh sequencing needs the same regions on both meshes "
                         f"(zones {old.pressure_zones} and {new.pressure_zones})")
    mesh, dim = new.mesh, new.dim
    X = vertex_coordinates(mesh)
    els, mat = element_vertices(mesh)
    centroid = X[els].mean(axis=1)
    inward = np.empty_like(X)
    inward[els.ravel()] = np.repeat(centroid, dim + 1, axis=0)  # one element's centroid
    u = vertex_values(old.mesh, old.u, X, inward=inward)
    lost = ~np.isfinite(u[:, 0])
    if lost.all():
        raise InputError("the coarse and the fine mesh do not overlap")
    if lost.any():
        found = np.flatnonzero(~lost)
        _, j = cKDTree(X[found]).query(X[lost])
        u[lost] = u[found[j]]
    gvec = new.gfu.vec.FV().NumPy()
    gvec[:] = 0.0
    V = new.fes.components[0]
    uvec = new.u.vec.FV().NumPy()
    uvec[vertex_dofs(V, mesh)] = u
    els_old, mat_old = element_vertices(old.mesh)
    located = old.mesh(*X.T)  # every fine vertex in the coarse mesh, once for all zones
    for k, zone in enumerate(new.pressure_zones):
        in_zone = np.array(mesh.Materials(zone).Mask(), dtype=bool)[mat]
        in_zone_old = np.array(old.mesh.Materials(zone).Mask(), dtype=bool)[mat_old]
        verts = np.unique(els[in_zone])
        p_old = old.gfu.components[1 + k]
        mips = located[verts]
        nr = mips["nr"]
        same = (nr >= 0) & in_zone_old[np.maximum(nr, 0)]
        p = np.zeros(len(verts))
        if same.any():
            p[same] = np.asarray(p_old(mips[same]), dtype=float).ravel()
        pvec = new.gfu.components[1 + k].vec.FV().NumPy()
        pvec[vertex_dofs(new.fes.components[1 + k], mesh, in_zone)[verts, 0]] = p
    carry_contact_pressures(old, new)
    press_onto_obstacles(new, X, els, fold_ratio)
    new.set_load(old.load.Get())  # prescribed values exact again


def press_onto_obstacles(form: MixedForm, X: np.ndarray, els: np.ndarray,
                         fold_ratio: float) -> None:
    """Move the points of ``form``'s state that carry contact pressure onto their obstacle
    (three projections along the normal), then take back the moves that fold an element.

    A fold guard is needed where the obstacle has a corner smaller than the coarse mesh's
    elements (the skull's 2 mm rounded cut edge under 3.5 mm elements of a 100k-tet brain):
    the fine mesh's points there lie up to 1.6 mm inside the rounding, close to where its
    signed distance's gradient jumps, so neighbours are pushed apart in different directions
    (18 folded tets at 1.40M). An element whose measure ratio ``J`` falls below
    ``fold_ratio`` (:class:`~brainbulge.solver.options.SequencingOptions`; and below its
    value before the move) gets its vertices' moves undone,
    repeatedly until none does; those points start inside the obstacle and Newton's active
    set closes the gap.
    """
    gvec = form.gfu.vec.FV().NumPy()
    before = gvec.copy()
    for pc in form.point_contacts:
        pressed = pc.lam > 0
        for _ in range(3):
            pc.update(gvec)
            pc.move_onto_obstacle(gvec, pressed)
    vd = vertex_dofs(form.fes.components[0], form.mesh)
    J0 = measure_ratio(X, els, before[vd])
    undone = 0
    while True:
        J = measure_ratio(X, els, gvec[vd])
        verts = np.unique(els[(J < fold_ratio) & (J < J0)])
        moved = verts[np.any(gvec[vd[verts]] != before[vd[verts]], axis=1)]
        if not len(moved):
            break
        gvec[vd[moved]] = before[vd[moved]]
        undone += len(moved)
    if undone:
        log.info("  %d contact points left where interpolated (moving them would fold "
                 "elements)", undone)
    for pc in form.point_contacts:
        pc.update(gvec)


def measure_ratio(X: np.ndarray, els: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Each simplex's deformed over reference measure (``J`` of the P1 map ``X -> X + u``)."""
    def measure(Y: np.ndarray) -> np.ndarray:
        return np.linalg.det(Y[els[:, 1:]] - Y[els[:, :1]])
    return measure(X + u) / measure(X)


def carry_contact_pressures(old: MixedForm, new: MixedForm) -> None:
    """Each of ``new``'s contact points takes the pressure of ``old``'s nearest one (at the
    deformed positions of both states)."""
    for pc_old, pc_new in zip(old.point_contacts, new.point_contacts, strict=True):
        pc_old.update(old.gfu.vec.FV().NumPy())
        pc_new.update(new.gfu.vec.FV().NumPy())
        _, idx = cKDTree(pc_old.x).query(pc_new.x)
        pc_new.lam = pc_old.lam[idx].copy()


def solve_sequenced(
    coarse: MixedForm, fine: MixedForm, options: SolverOptions,
    coarse_solution: Solution | None = None,
) -> tuple[Solution, Sequenced]:
    """Ramp the load on ``coarse``, carry its state to ``fine`` and converge there at full
    load through the stiffness contrast (:func:`equilibrate_through_contrast`); if that
    fails, ramp on ``fine`` from ``Js = 1``. Returns the fine solution (its times and Krylov
    iterations include the coarse stage, its Newton iterations are the fine mesh's, all
    contrast steps in one record) and the coarse stage's record; the linear solvers' memory
    is released.
    ``options`` apply to both meshes (the coarse one without restart file or progress bar,
    and to ``options.sequencing.coarse_tolerance``). ``coarse_solution``: ``coarse`` already
    holds this solution (e.g. the previous member of a mesh family), so it is not solved
    again."""
    t0 = time.perf_counter()
    if coarse_solution is None:
        coarse_opt = dataclasses.replace(options, checkpoint=None, progress=False,
                                         tolerance=max(options.newton.tolerance,
                                                       options.sequencing.coarse_tolerance))
        coarse_solver = NewtonSolver(coarse, coarse_opt)
        csol = coarse_solver.solve()
        coarse_solver.release_linear_solver()
    else:
        csol = coarse_solution
    log.info("  coarse mesh (%d elements): load %.4f in %d Newton iterations, %.1f s",
             coarse.mesh.ne, csol.load, csol.newton_iterations, csol.wall_time_s)
    record = Sequenced(coarse.mesh.ne, csol.converged, csol.newton_iterations,
                       time.perf_counter() - t0, 0.0, None, False)

    def through_contrast() -> Solution | None:
        """The coarse state carried to ``fine``, then the contrast path (None: the coarse
        stage did not converge)."""
        if not csol.converged:
            log.warning("  the coarse mesh stopped at load %.4f (%s); ramping the load on "
                        "the fine mesh from Js = 1", csol.load, csol.message)
            return None

        def carry(form: MixedForm) -> None:
            t1 = time.perf_counter()
            interpolate_state(coarse, form, options.sequencing.fold_ratio)
            record.transfer_time_s = time.perf_counter() - t1

        sol, record.initial_residual = equilibrate_through_contrast(fine, options, carry)
        record.fine_converged = sol.converged
        if not sol.converged:
            log.warning("  the coarse solution did not converge on the fine mesh (%s); "
                        "ramping the load there from Js = 1", sol.message)
        return sol

    sol = fallback(through_contrast, lambda: ramp_from_rest(fine, options))
    return _with_coarse_costs(sol, csol, t0), record


def ramp_from_rest(form: MixedForm, options: SolverOptions) -> Solution:
    """The load ramp on ``form`` from ``Js = 1`` (its state reset first); the linear solver's
    memory is released."""
    solver = NewtonSolver(form, options)
    solver.state.reset()
    sol = solver.solve()
    solver.release_linear_solver()
    return sol


def _with_coarse_costs(sol: Solution, coarse: Solution, t0: float) -> Solution:
    """``sol`` with the wall time since ``t0`` and the coarse stage's assembly, linear-solve
    and Krylov counts added (its Newton iterations stay the fine mesh's own)."""
    sol.wall_time_s = time.perf_counter() - t0
    return Costs().add(sol).add(coarse).into(sol)

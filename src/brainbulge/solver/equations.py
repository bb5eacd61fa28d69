"""The discrete equations Newton solves at one load: residual, its norm, tangent, direction.

The state ``x = (u, p)`` on the free DOFs, with the contact pressures ``lambda``, solves
``R(x) = 0``: the stationarity of docs/model.md s.2's Lagrangian (NGSolve's ``Variation``,
or the closed forms of :mod:`brainbulge.solver.fast.mini_tangent` and, in 2D,
:mod:`brainbulge.solver.fast.mini_plane`) plus the contact forces
``-B^T lambda`` and the complementarity of the active set (:mod:`brainbulge.solver.contact`).
MINI's bubbles are condensed statically: the direction is solved on the vertex DOFs and
extended into the bubbles.
"""

from __future__ import annotations

import logging
import time

import ngsolve as ngs
import numpy as np
import scipy.sparse as sp

from brainbulge.heap import release_free_memory
from brainbulge.solver.contact.active_set import ActiveSet
from brainbulge.solver.linear import LinearSolver, make_linear_solver
from brainbulge.solver.linear.sparse_reuse import PatternAdd, PatternGather, PatternProject
from brainbulge.solver.mixed import MixedForm
from brainbulge.solver.options import SolverOptions
from brainbulge.solver.state import State

log = logging.getLogger("brainbulge")


class MixedEquations:
    """``R(x)``, ``|R|``, ``K(x)`` and the Newton direction of a :class:`MixedForm` on its
    free DOFs, solved by the linear solver of ``options`` (:class:`SolverOptions`: also
    whether the closed-form MINI tangent is used where it applies)."""

    def __init__(self, form: MixedForm, options: SolverOptions | None = None) -> None:
        options = options or SolverOptions()
        self.form = form
        self.state = State(form)  # x, lambda, t: what a solve changes
        self.linear: LinearSolver = make_linear_solver(options.linear.solver, form,
                                                       options.krylov)
        fes = form.fes
        self.free = np.flatnonzero(np.array(list(fes.FreeDofs(form.condense)), dtype=bool))
        self.closed = None  # the closed-form residual and tangent, where they apply
        if form.element == "mini" and options.newton.closed_form:
            # (Numba, ~0.5 s: imported only where it may apply)
            from brainbulge.solver.fast import mini_plane, mini_tangent

            kind, closed = ((mini_tangent, mini_tangent.MiniTangent) if form.dim == 3
                            else (mini_plane, mini_plane.PlaneMiniTangent))
            if kind.applies(form):
                try:
                    self.closed = closed(form, self.free)  # its tangent on the free DOFs
                except ValueError as exc:  # a numbering or element it does not know
                    log.warning("closed-form tangent not used (%s); NGSolve's instead", exc)
        is_u = np.zeros(fes.ndof, dtype=bool)
        r = fes.Range(0)
        is_u[r.start : r.stop] = True
        self.is_u_free = is_u[self.free]
        self._free_index = np.full(fes.ndof, -1, dtype=np.int64)  # full -> free numbering
        self._free_index[self.free] = np.arange(len(self.free))
        mesh = form.mesh
        self.volume = float(ngs.Integrate(ngs.CF(1), mesh))  # |Omega|
        self.length = self.volume ** (1 / mesh.dim)  # L
        self.force_scale = form.mu_max * self.length ** (mesh.dim - 1)  # mu L^(d-1)
        self.res = form.gfu.vec.CreateVector()  # R at the last evaluated state
        self.t_assembly = 0.0
        self.t_solve = 0.0
        self.contact = ActiveSet(form, self.free, fes.ndof)
        # inexact Newton (Eisenstat-Walker): an iterative linear solve to a relative tolerance
        self.inexact = options.linear.solver == "krylov"
        self._vertex_dofs: tuple[np.ndarray, np.ndarray] | None = None
        self._new_plans()

    def release_linear_solver(self) -> None:
        """Free the linear solver's work memory (AMG hierarchies, factorisations) after the
        last solve, before the outputs are evaluated: the 3D output stage otherwise stacks
        its memory on top of the solver's (a later solve rebuilds them). The heap's free
        pages go back to the system too (:func:`brainbulge.heap.release_free_memory`)."""
        self.linear.release()
        self._new_plans()
        release_free_memory()

    def _new_plans(self) -> None:
        """The tangent's pattern is the same at every iteration: it is sliced and added to
        by plans (:mod:`brainbulge.solver.linear.sparse_reuse`), made at the first tangent
        (the free part: NGSolve's tangent only; the closed form assembles on the free DOFs)."""
        self._free_part = PatternGather(lambda K: K[self.free][:, self.free])
        self._add_curvature = PatternAdd()
        self._project_elimination = PatternProject()

    def _restrict_free(self, M: sp.spmatrix) -> sp.coo_matrix:
        """``M[free][:, free]`` of a matrix with few entries (no slicing over all DOFs)."""
        coo = M.tocoo()
        i, j = self._free_index[coo.row], self._free_index[coo.col]
        keep = (i >= 0) & (j >= 0)
        n = len(self.free)
        return sp.coo_matrix((coo.data[keep], (i[keep], j[keep])), shape=(n, n))

    def residual(self, x: ngs.BaseVector) -> np.ndarray:
        """``R(x)`` (full DOF numbering) with the contact forces ``-B^T lambda`` at the
        current multipliers; also their complementarity residuals for :meth:`scaled_norm`."""
        t0 = time.perf_counter()
        if self.closed is not None:
            self.res.FV().NumPy()[:] = self.closed.residual(x.FV().NumPy())
        else:
            with ngs.TaskManager():
                self.form.a.Apply(x, self.res)
        R = self.res.FV().NumPy()
        self.contact.add_forces(x.FV().NumPy(), R)
        self.t_assembly += time.perf_counter() - t0
        return R.copy()

    def scaled_norm(self, r: np.ndarray) -> float:
        """``|R| = hypot(|R_u| / (mu L^(d-1)), |R_p, C| / |Omega|)`` on the free DOFs: forces
        and volumes (the pressure equations, the contact complementarity) made
        dimensionless; ``inf`` if not finite."""
        rf = r[self.free]
        ru = np.linalg.norm(rf[self.is_u_free]) / self.force_scale
        rp = np.linalg.norm(rf[~self.is_u_free]) / self.volume
        if self.contact.complementarity:
            rp = np.hypot(rp, np.linalg.norm(np.concatenate(self.contact.complementarity))
                          / self.volume)
        val = float(np.hypot(ru, rp))
        return val if np.isfinite(val) else np.inf

    def tangent(self, x: ngs.BaseVector) -> sp.csr_matrix:
        """``K = dR/dx`` (condensed) on the free DOFs, with the contacts' curvature terms."""
        t0 = time.perf_counter()
        if self.closed is not None:  # assembled on the free DOFs' pattern
            K = self.closed.assemble(x.FV().NumPy())
        else:
            with ngs.TaskManager():  # threads for assembly only: idle NGSolve threads slow MKL
                self.form.a.AssembleLinearization(x)
            mat = self.form.a.mat  # (the width: unused last DOFs leave trailing empty columns)
            data, indices, indptr = mat.CSR()
            # a view of NGSolve's matrix, only read: the free part is gathered out of it
            K = sp.csr_matrix((np.asarray(data), indices, indptr),
                              shape=(mat.height, mat.width))
            K = self._free_part(K)
        for C in self.contact.curvatures(x.FV().NumPy()):
            K = self._add_curvature(K, self._restrict_free(C))
        self.t_assembly += time.perf_counter() - t0
        return K

    def newton_direction(
        self, x: ngs.BaseVector, K: sp.csr_matrix | None = None, rtol: float | None = None,
    ) -> tuple[ngs.BaseVector, list[np.ndarray]]:
        """Newton step ``(dx, dlam)`` for ``x <- x - s dx``, ``lam <- lam - s dlam``.

        ``self.res`` must hold ``R(x)``, as in :func:`~brainbulge.solver.newton.newton`.
        Static condensation (MINI's bubbles) extends the right-hand side before and the
        solution after the solve; the contact rows come from :meth:`ActiveSet.linearize`.
        ``rtol``: the relative tolerance of an iterative linear solver.
        """
        if K is None:
            K = self.tangent(x)
        a = self.form.a
        rhs = x.CreateVector()
        rhs.data = self.res  # residual at x: newton() always evaluates x last
        step = self.contact.linearize(rhs.FV().NumPy())
        if self.closed is not None:
            rhs.FV().NumPy()[:] += self.closed.extend_trans(rhs.FV().NumPy())
        elif self.form.condense:
            rhs.data += a.harmonic_extension_trans * rhs
        b = rhs.FV().NumPy()[self.free]
        K, b = step.system(K, b, self.free, self.is_u_free, self._project_elimination)
        t0 = time.perf_counter()
        sol = self.linear.solve(K, b, rtol=rtol if self.inexact else None)
        self.t_solve += time.perf_counter() - t0
        dx_free, dlams = step.recover(sol, len(self.free))
        dx = x.CreateVector()
        dx[:] = 0
        dx.FV().NumPy()[self.free] = dx_free
        if self.closed is not None:
            d = dx.FV().NumPy()
            d += self.closed.extend(d) + self.closed.inner_solve(rhs.FV().NumPy())
        elif self.form.condense:
            dx.data += a.harmonic_extension * dx
            dx.data += a.inner_solve * rhs
        return dx, dlams

    def residual_site(self, x: ngs.BaseVector) -> np.ndarray | None:
        """Deformed position ``X + u`` [length] of the vertex whose free displacement DOFs
        carry the largest force residual ``|R_v|`` at ``x`` (where a failed Newton solve left
        its imbalance: the place to look at, or to refine); None if ``R`` is not finite."""
        from brainbulge.geometry.ngsolve_arrays import vertex_coordinates, vertex_dofs

        R = self.residual(x)
        if self._vertex_dofs is None:
            form = self.form
            dofs = vertex_dofs(form.fes.components[0], form.mesh)
            dofs = np.where(dofs >= 0, dofs + form.fes.Range(0).start, -1)
            self._vertex_dofs = (dofs, vertex_coordinates(form.mesh))
        dofs, X = self._vertex_dofs
        free = np.zeros(len(R), dtype=bool)
        free[self.free] = True
        on = (dofs >= 0) & free[np.maximum(dofs, 0)]
        force = np.linalg.norm(np.where(on, R[np.maximum(dofs, 0)], 0.0), axis=1)
        if not np.all(np.isfinite(force)) or not force.any():
            return None
        v = int(np.argmax(force))
        u = np.where(dofs[v] >= 0, x.FV().NumPy()[np.maximum(dofs[v], 0)], 0.0)
        return X[v] + u

    def max_penetration(self) -> float:
        """Largest penetration ``max(-g, 0)`` of the moving contact points and of the
        penalty contacts' Gauss points [length]."""
        return max([self.contact.max_penetration(),
                    *(pc.max_penetration() for pc in self.form.penalty_contacts)])


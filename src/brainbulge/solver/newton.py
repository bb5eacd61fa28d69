"""Newton's method with a line search, and load stepping on the swelling ``Js``.

Each load step raises the load factor ``t`` (``Js(t) = 1 + t (Js - 1)``), predicts the new
state by extrapolating the last increment, and solves the mixed equations by Newton's method:
``K(x_k) dx = R(x_k)``, ``x_{k+1} = x_k - s dx`` with a backtracking line search on the scaled
residual norm. A step that fails (divergence, non-finite values from inverted elements, too
many iterations) is cut in half and retried from the last converged state; the solve stops with
a clear message when the step would fall below ``min_step``. Contact multipliers are
augmented (Uzawa) after each converged step until the penetration is below tolerance.

With ``SolverOptions.checkpoint`` the state after every accepted load step is written to an
``.npz`` restart file; a solve that finds a file of the same problem there (``key`` and the
number of DOFs) resumes from it instead of starting at ``t = 0`` (as Abaqus' restart): a
long 3D run that is stopped loses at most one load step.
"""

from __future__ import annotations

import logging
import os
import time
from collections.abc import Callable
from contextlib import nullcontext
from dataclasses import dataclass, field
from pathlib import Path

import ngsolve as ngs
import numpy as np
import scipy.sparse as sp
from tqdm.auto import tqdm

from brainbulge.errors import ConvergenceError, InfeasibleError, InputError
from brainbulge.heap import release_free_memory
from brainbulge.model.problem import Problem
from brainbulge.solver.hotspot import HotspotRelaxation
from brainbulge.solver.linear import LinearSolver, make_linear_solver
from brainbulge.solver.mixed import MixedForm
from brainbulge.solver.sparse_reuse import PatternAdd, PatternGather, PatternProject
from brainbulge.solver.threads import serial_openblas

log = logging.getLogger("brainbulge")


#: the advice that ends the message of a load ramp that stopped (a case that knows better,
#: e.g. a hemidisk stopped on the skull's rounded cut edge, replaces it)
DIVERGENCE_ADVICE = "Try more --steps, a finer mesh, or check the boundary conditions"


@dataclass
class SolverOptions:
    """Load stepping and Newton controls.

    Attributes:
        steps: initial number of equal load steps from ``Js = 1`` to the target.
        min_step: smallest load increment before giving up [-].
        max_step: largest load increment after growth [-].
        max_iterations: Newton iterations per attempt.
        stagnation: an attempt stops early, as failed, after this many Newton iterations in
            a row whose line search accepted at most 1/64 of the step and that together
            lowered the residual by less than 5 % (where the load path folds, the 2D
            alpha 80 / beta 30 runs spent all 20 iterations on 0.1-0.4 % steps, attempt
            after attempt); 0 never stops early.
        tolerance: on the scaled residual (force / (mu L^(d-1)), volume / |Omega|).
        intermediate_tolerance: the same below full load (never tighter than
            ``tolerance``). The material is hyperelastic, so
            an intermediate state is only the start of the next step (its extrapolation
            starts ~1e-3 away): converging it further than this buys nothing. Saves about
            one Newton iteration per intermediate load step (2D headline: 20 -> 18).
        penetration_tol: contact penetration tolerance relative to the body size [-].
        max_augmentations: Uzawa updates per load step.
        linear_solver: "pardiso", "scipy" or "krylov" (GMRES with AMG blocks).
        progress: show a progress bar over the load.
        checkpoint: restart file written after each accepted load step and read at the
            start when it holds the same problem (see the module docstring).
        checkpoint_key: identifies the problem in the restart file (e.g. the inputs as
            JSON); a file with another key is ignored and overwritten.
        start_load: load factor of the form's current state, where the ramp starts
            (a state carried over from another mesh by rezoning).
        stop_when: asked after each accepted load step below full load; ``True`` stops the
            ramp there (the state is kept, ``converged`` is false, ``stopped_early`` true).
        stop_on_failure: asked with the last converged load when a load step fails,
            before it is cut; ``True`` stops the ramp there as ``stop_when`` does.
        carried_curvature_tolerance: Newton from a state carried over from another mesh
            (:meth:`NewtonSolver.equilibrate`, mesh sequencing) leaves the point contacts'
            curvature term out of the tangent until the scaled residual is at most this
            (a modified Newton method far from the solution, the exact tangent for the
            end game). At the carried-over state the flap rim's contact points press with
            up to ~350 kPa on the skull's convex rounded cut edge, where the term
            ``-A lambda grad^2 g`` makes sliding along the edge nearly free: the exact
            Newton direction slid points by 5-8 mm and folded elements (line-search steps
            of 1/8; 1.54M tets, 10 Newton iterations); without the term the first step is
            a full one (1.7e-2 -> 8.7e-4) and the stage takes 6. ``inf`` keeps the exact
            tangent throughout.
        hotspot_relaxation: after an accepted Newton step whose residual sits at a few
            vertices (MINI), solve their equations locally first (nonlinear elimination,
            :mod:`brainbulge.solver.hotspot`), kept only when the residual falls.
        closed_form_tangent: assemble the tangent of a 3D MINI Mooney-Rivlin form from the
            closed-form Hessian in compiled loops (:mod:`brainbulge.solver.mini_tangent`;
            the same matrix as NGSolve's AD to round-off, 4-5x faster); other forms, or
            ``False``, use NGSolve's ``AssembleLinearization``. The default is ``True``
            unless the environment sets ``BRAINBULGE_CLOSED_TANGENT=0`` (for comparisons).
    """

    steps: int = 5
    min_step: float = 1e-3
    max_step: float = 1.0
    max_iterations: int = 20
    stagnation: int = 4
    tolerance: float = 1e-9
    intermediate_tolerance: float = 1e-6
    penetration_tol: float = 1e-5
    max_augmentations: int = 10
    linear_solver: str = "pardiso"
    progress: bool = False
    checkpoint: str | Path | None = None
    checkpoint_key: str = ""
    start_load: float = 0.0
    stop_when: Callable[[], bool] | None = None
    stop_on_failure: Callable[[float], bool] | None = None
    carried_curvature_tolerance: float = 1e-3
    hotspot_relaxation: bool = True
    closed_form_tangent: bool = field(
        default_factory=lambda: os.environ.get("BRAINBULGE_CLOSED_TANGENT", "1") != "0")

    def __post_init__(self) -> None:
        if not isinstance(self.steps, int) or self.steps < 1:
            raise InputError(f"steps = {self.steps!r} must be a positive integer")
        if not (0 < self.min_step <= 1):
            raise InputError(f"min_step = {self.min_step!r} must lie in (0, 1]")
        if not (self.tolerance > 0 and self.intermediate_tolerance > 0):
            raise InputError(f"tolerances {self.tolerance!r} (final) and "
                             f"{self.intermediate_tolerance!r} (intermediate) must be positive")
        if not (0 <= self.start_load < 1):
            raise InputError(f"start_load = {self.start_load!r} must lie in [0, 1)")
        if not self.carried_curvature_tolerance > 0:
            raise InputError(f"carried_curvature_tolerance = "
                             f"{self.carried_curvature_tolerance!r} must be positive")
        if not isinstance(self.stagnation, int) or self.stagnation < 0:
            raise InputError(f"stagnation = {self.stagnation!r} must be an integer >= 0")


@dataclass
class StepRecord:
    """One accepted load step."""

    load: float
    newton_iterations: int
    augmentations: int
    residual: float
    max_penetration: float


@dataclass
class Solution:
    """The last converged state, and how it was reached."""

    form: MixedForm
    load: float
    converged: bool
    steps: list[StepRecord] = field(default_factory=list)
    rejected_steps: int = 0
    message: str = ""
    wall_time_s: float = 0.0
    assembly_time_s: float = 0.0
    solve_time_s: float = 0.0
    linear_iterations: int = 0  # Krylov iterations in all (0 with a direct solver)
    stopped_early: bool = False  # by ``SolverOptions.stop_when``, not by a failure
    rezones: int = 0  # mesh exchanges (see :mod:`brainbulge.solver.rezoning`)
    resumed_from: float = 0.0  # load of the restart file the ramp went on from (0: none)
    #: deformed position [length] of the vertex with the largest unbalanced force when the
    #: last Newton attempt gave up (None: none gave up, or its residual was not finite)
    failure_site: np.ndarray | None = None

    @property
    def newton_iterations(self) -> int:
        return sum(s.newton_iterations for s in self.steps)

    def raise_if_failed(self) -> None:
        if not self.converged:
            raise ConvergenceError(self.message)


class NewtonSolver:
    """Newton + load stepping for a :class:`MixedForm`."""

    def __init__(self, form: MixedForm, options: SolverOptions | None = None) -> None:
        self.form = form
        self.opt = options or SolverOptions()
        if self.opt.linear_solver == "krylov":  # block-preconditioned GMRES
            from brainbulge.solver.krylov import BlockKrylovSolver

            self.linear: LinearSolver = BlockKrylovSolver.from_form(form)
        else:
            self.linear = make_linear_solver(self.opt.linear_solver)
        self.closed = None  # the closed-form tangent, where it applies
        if self.opt.closed_form_tangent and form.element == "mini" and form.dim == 3:
            from brainbulge.solver import mini_tangent  # (Numba, ~0.5 s: only where it may apply)

            if mini_tangent.applies(form):
                try:
                    self.closed = mini_tangent.MiniTangent(form)
                except ValueError as exc:  # a numbering or element it does not know
                    log.warning("closed-form tangent not used (%s); NGSolve's instead", exc)
        fes = form.fes
        self.free = np.flatnonzero(np.array(list(fes.FreeDofs(form.condense)), dtype=bool))
        is_u = np.zeros(fes.ndof, dtype=bool)
        r = fes.Range(0)
        is_u[r.start : r.stop] = True
        self.is_u_free = is_u[self.free]
        self._free_index = np.full(fes.ndof, -1, dtype=np.int64)  # full -> free numbering
        self._free_index[self.free] = np.arange(len(self.free))
        mesh = form.mesh
        self.volume = float(ngs.Integrate(ngs.CF(1), mesh))
        self.length = self.volume ** (1 / mesh.dim)
        self.force_scale = form.mu_max * self.length ** (mesh.dim - 1)
        self.res = form.gfu.vec.CreateVector()
        self.t_assembly = 0.0
        self.t_solve = 0.0
        self.history: list[list[float]] = []  # scaled residual norms of each Newton solve
        self.tolerance = self.opt.tolerance  # of the next Newton solve (see solve())
        self.with_curvature = True  # the contacts' curvature term in the next tangent
        # point contacts: weight of gap against pressure in the active set [stress/length],
        # and which points have a free DOF (a point on a clamped edge takes no constraint)
        self.c_active = form.mu_max / form.h
        free_mask = np.zeros(fes.ndof, dtype=bool)
        free_mask[self.free] = True
        self._pc_free = {
            id(pc): np.asarray(
                (abs(pc.P) @ free_mask.astype(float)).reshape(pc.n_points, -1).sum(axis=1) > 0
            )
            for pc in form.point_contacts
        }
        self._compl: list[np.ndarray] = []
        self._forced: list[np.ndarray] = [np.zeros(pc.n_points, bool) for pc in form.point_contacts]
        self._last_active: list[np.ndarray] = []
        # inexact Newton (Eisenstat-Walker): relative tolerance of an iterative linear solve
        self.inexact = self.opt.linear_solver == "krylov"
        self.eta = self.eta_cap = ETA_MAX
        self.tightened_solves = 0  # directions solved again tighter after a failed line search
        self.last_linear_solution: np.ndarray | None = None
        self.failure_site: np.ndarray | None = None  # see residual_site
        self._vertex_dofs: tuple[np.ndarray, np.ndarray] | None = None
        self._new_plans()
        self.relaxation = (HotspotRelaxation(self) if self.opt.hotspot_relaxation
                           and HotspotRelaxation.applies(form) else None)

    def release_linear_solver(self) -> None:
        """Free the linear solver's work memory (AMG hierarchies, factorisations) after the
        last solve, before the outputs are evaluated: the 3D output stage otherwise stacks
        its memory on top of the solver's (a later solve rebuilds them). The heap's free
        pages go back to the system too (:func:`brainbulge.heap.release_free_memory`)."""
        release = getattr(self.linear, "release", None)
        if release is not None:
            release()
        self.last_linear_solution = None
        self._new_plans()
        release_free_memory()

    def _new_plans(self) -> None:
        """The tangent's pattern is the same at every iteration: it is sliced and added to
        by plans (:mod:`brainbulge.solver.sparse_reuse`), made at the first tangent."""
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

    # --- residual and tangent ----------------------------------------------------------
    def residual(self, x: ngs.BaseVector) -> np.ndarray:
        """``R(x)`` (full DOF numbering) with the point contacts' forces at their current
        multipliers; also evaluates their complementarity residuals for :meth:`scaled_norm`."""
        t0 = time.perf_counter()
        with ngs.TaskManager():
            self.form.a.Apply(x, self.res)
        R = self.res.FV().NumPy()
        self._compl = []
        for pc in self.form.point_contacts:
            pc.update(x.FV().NumPy())
            pc.add_forces(R)
            self._compl.append(pc.complementarity(self.c_active)[pc_free(pc, self)])
        self.t_assembly += time.perf_counter() - t0
        return R.copy()

    def scaled_norm(self, r: np.ndarray) -> float:
        """Residual norm with forces and volumes made dimensionless (contact
        complementarity, a volume, counts with the pressure equations)."""
        rf = r[self.free]
        ru = np.linalg.norm(rf[self.is_u_free]) / self.force_scale
        rp = np.linalg.norm(rf[~self.is_u_free]) / self.volume
        if self._compl:
            rp = np.hypot(rp, np.linalg.norm(np.concatenate(self._compl)) / self.volume)
        val = float(np.hypot(ru, rp))
        return val if np.isfinite(val) else np.inf

    def tangent(self, x: ngs.BaseVector) -> sp.csr_matrix:
        """The assembled (condensed) tangent restricted to the free DOFs, with the point
        contacts' curvature terms."""
        t0 = time.perf_counter()
        if self.closed is not None:
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
        for pc in self.form.point_contacts:
            pc.update(x.FV().NumPy())
            if self.with_curvature:
                K = self._add_curvature(K, self._restrict_free(-pc.curvature()))
        self.t_assembly += time.perf_counter() - t0
        return K

    def newton_direction(
        self, x: ngs.BaseVector, K: sp.csr_matrix | None = None, guess: np.ndarray | None = None
    ) -> tuple[ngs.BaseVector, list[np.ndarray]]:
        """Newton step ``(dx, dlam)`` for ``x <- x - s dx``, ``lam <- lam - s dlam``.

        ``self.res`` must hold ``R(x)``, as in :meth:`newton`. Without point contacts
        ``K dx = R``. With them (primal-dual active set, see :mod:`point_contact`) inactive
        multipliers go to zero (``dlam_I = lam_I``) and ``(dx, dlam_A)`` solves
        ``[[K, -B_A^T], [-B_A, 0]] [dx, dlam_A] = [R + B_I^T lam_I, -A g_A]``, with the
        constraints eliminated at their nodes (:class:`NodalElimination`) when each acts on
        one node, else in augmented form (:func:`_augmented`). The augmented system keeps a
        row for every moving contact point, ``dlam_i = lam_i`` for the inactive ones, so its
        size and sparsity do not change with the active set (the direct solver then redoes
        only the numeric factorisation).

        ``guess``: the linear system's solution of a retry at the same state (another
        active set, or a tighter tolerance), an initial guess for an iterative solver; the
        system's solution is kept in ``self.last_linear_solution`` for that purpose.
        """
        if K is None:  # a retry at the same state (new active set) reuses the tangent
            K = self.tangent(x)
        a = self.form.a
        rhs = x.CreateVector()
        rhs.data = self.res  # residual at x: newton() always evaluates x last
        dlams: list[np.ndarray] = []
        rows_B = []  # (contact, its moving points, which of them are active)
        self._last_active = []
        for pc, forced in zip(self.form.point_contacts, self._forced, strict=True):
            act = (pc.active(self.c_active) | forced) & pc_free(pc, self)
            self._last_active.append(act)
            pc.add_forces(rhs.FV().NumPy(), -np.where(act, 0.0, pc.lam))  # + B_I^T lam_I
            dlams.append(pc.lam.copy())  # inactive: to zero
            moving = np.flatnonzero(pc_free(pc, self))
            rows_B.append((pc, moving, act[moving]))
        if self.closed is not None:
            rhs.FV().NumPy()[:] += self.closed.extend_trans(rhs.FV().NumPy())
        elif self.form.condense:
            rhs.data += a.harmonic_extension_trans * rhs
        b = rhs.FV().NumPy()[self.free]
        elimination = None
        solved: list[np.ndarray] = []  # the points whose dlam the linear system gives
        if rows_B:
            B_all = sp.vstack([pc.B(pts) for pc, pts, _ in rows_B]).tocsr()[:, self.free]
            on = np.concatenate([o for _, _, o in rows_B])
            B = B_all[on]
            c = np.concatenate([-pc.weights[pts[on]] * pc.g[pts[on]] for pc, pts, on in rows_B])
            n = K.shape[0]
            if NodalElimination.applies(B_all):  # each point's row on a node of its own
                solved = [pts[on] for _, pts, on in rows_B]  # (none active: empty)
                if B.shape[0]:
                    elimination = NodalElimination(K, B, c, self.is_u_free,
                                                   project=self._project_elimination)
                    K, b = elimination.system(b)
                    if guess is not None and len(guess) == len(b):
                        # y has no normal part at the constrained nodes (N^T y = 0); a guess
                        # from another active set does, which the d N N^T rows magnify
                        guess = elimination.project(guess)
            else:
                if B.shape[0]:
                    K, b = _augmented(K, b, B, c, self.is_u_free)
                # a row per moving point: -B_i dx = c_i if active, -s dlam_i = -s lam_i if not
                solved = [pts for _, pts, _ in rows_B]
                B_all = sp.diags(on.astype(float)) @ B_all
                lam = np.concatenate([pc.lam[pts] for pc, pts, _ in rows_B])
                s_idle = float(np.mean(np.abs(K.diagonal()[: len(self.is_u_free)]
                                              [self.is_u_free])))
                D = sp.diags(np.where(on, 0.0, -s_idle))
                c_all = -s_idle * lam
                c_all[on] = c
                nB = len(on)
                K = _coo_sum(
                    [K.tocoo(), (-B_all).T.tocoo(), (-B_all).tocoo(), D.tocoo()],
                    (n + nB, n + nB),
                    offsets=[(0, 0), (0, n), (n, 0), (n, n)],
                    diagonal=True,
                )
                b = np.concatenate([b, c_all])
        t0 = time.perf_counter()
        if self.inexact:
            sol = self.linear.solve(K, b, rtol=self.eta, x0=guess)
            self.last_linear_solution = sol
        else:
            sol = self.linear.solve(K, b)
        self.t_solve += time.perf_counter() - t0
        if elimination is not None:
            sol = elimination.recover(sol)
        dx = x.CreateVector()
        dx[:] = 0
        dx.FV().NumPy()[self.free] = sol[: len(self.free)]
        k = len(self.free)
        for pts, dlam in zip(solved, dlams, strict=True):
            dlam[pts] = sol[k : k + len(pts)]
            k += len(pts)
        if self.closed is not None:
            d = dx.FV().NumPy()
            d += self.closed.extend(d) + self.closed.inner_solve(rhs.FV().NumPy())
        elif self.form.condense:
            dx.data += a.harmonic_extension * dx
            dx.data += a.inner_solve * rhs
        return dx, dlams

    def newton(self, x: ngs.BaseVector, curvature_below: float = np.inf
               ) -> tuple[bool, int, float]:
        """Solve at the current load from the guess ``x`` (updated in place, with the
        point contacts' multipliers); returns (converged, iterations, scaled residual).

        ``curvature_below``: the contacts' curvature term enters the tangent only at
        iterates whose scaled residual is at most this (see
        :attr:`SolverOptions.carried_curvature_tolerance`); by default always."""
        # one OpenBLAS thread beside PARDISO (brainbulge.solver.threads); the Krylov path's
        # long vectors keep theirs (111k-tet brain: 10 % slower on one)
        try:
            with nullcontext() if self.inexact else serial_openblas():
                ok, its, norm = self._newton(x, curvature_below)
            if not ok:
                self.failure_site = self.residual_site(x)
            return ok, its, norm
        finally:
            self.with_curvature = True

    def residual_site(self, x: ngs.BaseVector) -> np.ndarray | None:
        """Deformed position ``X + u`` [length] of the vertex whose free displacement DOFs
        carry the largest force residual ``|R_v|`` at ``x`` (where a failed Newton solve left
        its imbalance: the place to look at, or to refine); None if ``R`` is not finite."""
        from brainbulge.geometry.ngsolve_arrays import vertex_coordinates, vertex_dofs

        R = self.residual(x)
        if self._vertex_dofs is None:
            mesh = self.form.mesh
            dofs = vertex_dofs(self.form.fes.components[0], mesh)
            dofs = np.where(dofs >= 0, dofs + self.form.fes.Range(0).start, -1)
            self._vertex_dofs = (dofs, vertex_coordinates(mesh))
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

    def _newton(self, x: ngs.BaseVector, curvature_below: float) -> tuple[bool, int, float]:
        pcs = self.form.point_contacts
        # points forced into the active set for this solve: inactive points that a full
        # Newton step pushed into the skull (left alone, such a weakly active point makes
        # the active set cycle and the line search halve every step)
        self._forced = [np.zeros(pc.n_points, dtype=bool) for pc in pcs]
        self.eta = self.eta_cap = ETA_MAX
        renew_schur = getattr(self.linear, "renew_schur", None)
        if renew_schur is not None:  # the Krylov preconditioner's S~: once per load step
            renew_schur()
        norm = self.scaled_norm(self.residual(x))
        self.history.append([])
        short_steps, norm_before_short = 0, norm  # the run of short line-search steps
        for it in range(self.opt.max_iterations + 1):
            self.history[-1].append(norm)
            log.debug("    newton %d: |R| = %.3e", it, norm)
            if norm <= self.tolerance:
                return True, it, norm
            if not np.isfinite(norm) or it == self.opt.max_iterations:
                return False, it, norm
            K_x = None  # the tangent at x0, shared by the retries of this iteration
            self.last_linear_solution = None  # and the last direction, their Krylov guess
            x0 = x.CreateVector()
            x0.data = x
            lam0 = [pc.lam.copy() for pc in pcs]
            tightened = False
            for attempt in range(4):
                try:
                    if K_x is None:
                        self.with_curvature = norm <= curvature_below
                        K_x = self.tangent(x)
                    dx, dlams = self.newton_direction(x, K_x, self.last_linear_solution)
                except ConvergenceError:
                    if not self.inexact or self.eta <= ETA_MIN:
                        return False, it, norm
                    # a failed Krylov solve has asked for a fresh AMG: retry it, tighter
                    log.debug("    Krylov solve failed: retrying with a fresh preconditioner")
                    self.eta = ETA_MIN
                    try:
                        dx, dlams = self.newton_direction(x, K_x)
                    except ConvergenceError:
                        return False, it, norm
                s = 1.0
                while True:
                    x.data = x0 - s * dx
                    for pc, l0, dl in zip(pcs, lam0, dlams, strict=True):
                        pc.lam = l0 - s * dl
                    trial = self.scaled_norm(self.residual(x))
                    if trial < (1 - 1e-4 * s) * norm or trial <= self.tolerance:
                        break
                    if s == 1.0 and attempt < 3 and self._force_penetrating():
                        s = 0.0  # retry the direction with the newly forced points
                        break
                    s *= 0.5
                    if (s < 1 / 1024 and self.inexact and not tightened
                            and self.eta > ETA_MIN and attempt < 3):
                        # no step at all from a loose Krylov direction: before giving up
                        # (and cutting the load step) solve the direction 100x tighter.
                        # (Retrying at every short step instead cost a 1.54M-tet run an
                        # 812 s solve for the same 1/16 step: there the nonlinearity,
                        # not the direction, made the step short.)
                        tightened = True
                        self.tightened_solves += 1
                        self.eta = self.eta_cap = max(ETA_MIN, 1e-2 * self.eta)
                        log.debug("    line search failed at Krylov rtol %.1e: retrying "
                                  "tighter", 1e2 * self.eta)
                        s = 0.0
                        break
                    if s < 1 / 1024:
                        x.data = x0
                        for pc, l0 in zip(pcs, lam0, strict=True):
                            pc.lam = l0
                        return False, it, norm
                if s > 0:
                    log.debug("    step %.3g, %d active contact points (%d pulling)%s%s", s,
                              sum(int(a.sum()) for a in self._last_active),
                              sum(int((pc.lam < 0).sum()) for pc in pcs),
                              "" if self.with_curvature or not pcs else ", no curvature",
                              f", Krylov rtol {self.eta:.1e}" if self.inexact else "")
                    # (a full step that does not halve the residual is not the Krylov
                    # tolerance's doing here: from one 1.54M-tet state, GMRES at 1e-7
                    # instead of 1e-4 gave the same Newton residuals to four digits;
                    # tightening after such steps only doubled the GMRES iterations)
                    self.eta = min(self.eta_cap, forcing_term(self.eta, trial / norm, trial,
                                                              self.tolerance))
                    if s > 1 / 64:
                        short_steps, norm_before_short = 0, trial
                    else:
                        short_steps += 1
                    norm = trial
                    if self.relaxation is not None and norm > self.tolerance:
                        norm = self.relaxation.relax(x, norm)
                    break
                x.data = x0
                for pc, l0 in zip(pcs, lam0, strict=True):
                    pc.lam = l0
                self.residual(x)
            for forced, pc in zip(self._forced, pcs, strict=True):
                forced &= pc.lam >= 0  # a forced point that pulls is let go
            if (0 < self.opt.stagnation <= short_steps and norm > self.tolerance
                    and norm > 0.95 * norm_before_short):
                log.debug("    stagnated: %d short steps from |R| = %.3e", short_steps,
                          norm_before_short)
                return False, it + 1, norm
        return False, self.opt.max_iterations, norm

    def _force_penetrating(self) -> bool:
        """Force into the active set the inactive points that penetrate at the current
        (trial) state; True if there were any."""
        any_new = False
        tol = 1e-6 * self.form.h
        for pc, forced, act in zip(
            self.form.point_contacts, self._forced, self._last_active, strict=True
        ):
            new = ~act & (pc.g < -tol) & pc_free(pc, self)
            if new.any():
                forced |= new
                any_new = True
        return any_new

    # --- contact -----------------------------------------------------------------------
    def max_penetration(self) -> float:
        """Largest penetration ``max(-g, 0)`` at boundary integration points [length]; for
        point contacts at the points that move (a clamped point may overlap the obstacle at
        rest by the surface's geometric error: it is not in contact)."""
        pen = max((pc.max_penetration(pc_free(pc, self)) for pc in self.form.point_contacts),
                  default=0.0)
        if not self.form.contact_gaps:
            return pen
        from brainbulge.results.quadrature import quadrature_points

        q = quadrature_points(self.form.mesh, order=4, boundary=True)
        for g, mask in zip(self.form.contact_gaps, self.form.contact_masks, strict=True):
            on = q(mask) > 0.5
            if on.any():
                pen = max(pen, float(np.max(-q(g)[on])))
        return max(pen, 0.0)

    def augment(
        self, x: ngs.BaseVector, pen: float, pen_tol: float
    ) -> tuple[int, int, float, float]:
        """Uzawa updates of the contact pressure until the penetration is below ``pen_tol``.

        An update whose Newton solve fails is undone and the augmentation stops: the last
        converged state (and its penetration, reported) is kept.
        """
        form = self.form
        n_aug = its = 0
        norm = 0.0
        r0 = form.r.Get()
        continuation = True
        while pen > pen_tol and n_aug < self.opt.max_augmentations:
            saved_x = x.CreateVector()
            saved_x.data = x
            saved_lam = form.multiplier_state()
            saved_r = form.r.Get()
            raising = continuation and form.r.Get() < 1e3 * r0 and pen > 10 * pen_tol
            if raising:
                # penalty continuation: penetration ~ 1/r, Newton restarts from a close state
                form.r.Set(form.r.Get() * 3)
            else:
                form.update_contact_multipliers()
            ok, k, norm = self.newton(x)
            its += k
            if not ok:
                x.data = saved_x
                form.r.Set(saved_r)
                form.restore_multipliers(saved_lam)
                norm = self.scaled_norm(self.residual(x))
                if raising:  # the stiffer penalty failed: go on with Uzawa updates at this r
                    continuation = False
                    n_aug += 1
                    continue
                log.warning("contact augmentation stopped: penetration %.3g", pen)
                break
            n_aug += 1
            pen = self.max_penetration()
            log.info("  augmentation %d: penetration %.3e", n_aug, pen)
        return n_aug, its, norm, pen

    # --- load stepping -----------------------------------------------------------------
    def check_feasible(self) -> None:
        """A body with no traction-free boundary cannot swell (the skull is rigid)."""
        problem = self.form.problem
        if problem.traction_free_boundaries():
            return
        # contact boundaries that do not touch the obstacle at rest can move out (an opening)
        free_contact = sum(
            float(ngs.Integrate(ngs.IfPos(g - 0.01 * self.form.h, mask, 0), problem.mesh, ngs.BND))
            for g, mask in zip(self.form.contact_gaps, self.form.contact_masks, strict=True)
        )
        free_contact += sum(pc.free_measure(0.01 * self.form.h) for pc in self.form.point_contacts)
        if free_contact > 1e-9 * self.length ** (problem.dim - 1):
            return
        added = float(ngs.Integrate(self.form.Js - 1, problem.mesh))
        if added > 1e-12 * self.volume:
            raise InfeasibleError(
                f"infeasible: swelling adds {added:.4g} (volume units) but every boundary is "
                "clamped or against the rigid skull, a closed domain; open part of the "
                "boundary (a craniectomy opening)"
            )

    def solve(self) -> Solution:
        """Ramp the load from 0 to 1; return the last converged state."""
        self.check_feasible()
        form, opt = self.form, self.opt
        start = time.perf_counter()
        x = form.gfu.vec
        sol = Solution(form=form, load=0.0, converged=False)
        t, dt = opt.start_load, 1.0 / opt.steps
        x_prev = x.CreateVector()
        x_prev.data = x
        last_increment: ngs.BaseVector | None = None
        last_dt = 0.0
        if opt.checkpoint is not None:
            resumed = self._read_checkpoint(Path(opt.checkpoint), x, sol)
            if resumed is not None:
                t, dt, last_increment, last_dt = resumed
                sol.resumed_from = t
                x_prev.data = x
        bar = tqdm(total=100, disable=not opt.progress, desc="load", unit="%", leave=False)
        bar.update(round(100 * t))
        try:
            while t < 1 - 1e-12:
                dt = min(dt, 1 - t, opt.max_step)
                form.set_load(t + dt)
                lam_saved = form.multiplier_state()
                if last_increment is not None:  # predictor: extrapolate the last increment
                    x.data = x_prev + (dt / last_dt) * last_increment
                    form.set_load(t + dt)  # exact prescribed values over the predictor
                final = t + dt >= 1 - 1e-12
                self.tolerance = opt.tolerance if final else max(opt.tolerance,
                                                                 opt.intermediate_tolerance)
                ok, its, norm = self.newton(x)
                if not ok and last_increment is not None:  # retry without the predictor
                    x.data = x_prev
                    ok, its2, norm = self.newton(x)
                    its += its2
                n_aug, pen = 0, 0.0
                if ok:
                    n_aug, its2, norm, pen = self._penetration(x, norm, final)
                    its += its2
                if not ok:
                    sol.rejected_steps += 1
                    x.data = x_prev
                    form.restore_multipliers(lam_saved)
                    if opt.stop_on_failure is not None and opt.stop_on_failure(t):
                        sol.stopped_early = True
                        sol.message = f"stopped at load {t:.4f} (stop_on_failure)"
                        break
                    log.info("  load %.4f: not converged (|R| = %.2e), cutting step", t + dt, norm)
                    dt *= 0.5
                    if dt < opt.min_step:
                        sol.failure_site = self.failure_site
                        sol.message = (
                            f"Newton diverged at load {t + 2 * dt:.4f} of 1 (swelling "
                            f"ramp) even with a load step of {2 * dt:.2g}; the last converged "
                            f"state (load {t:.4f}) is kept{self._site_text()}. "
                            f"{DIVERGENCE_ADVICE}"
                        )
                        break
                    continue
                increment = x.CreateVector()
                increment.data = x - x_prev
                last_increment, last_dt = increment, dt
                x_prev.data = x
                t += dt
                bar.update(round(100 * t) - bar.n)
                sol.steps.append(StepRecord(t, its, n_aug, norm, pen))
                log.info("  load %.4f: %d Newton iterations, |R| = %.2e", t, its, norm)
                if its <= 4:
                    dt *= 1.5
                if opt.checkpoint is not None:
                    self._write_checkpoint(Path(opt.checkpoint), x, t, dt, last_increment,
                                           last_dt, sol)
                if opt.stop_when is not None and t < 1 - 1e-12 and opt.stop_when():
                    sol.stopped_early = True
                    sol.message = f"stopped at load {t:.4f} (stop_when)"
                    break
            else:
                sol.converged = True
        finally:
            bar.close()
            self.tolerance = opt.tolerance
            x.data = x_prev
            form.load.Set(t)
        sol.load = t
        return self._timed(sol, start)

    def _site_text(self) -> str:
        """``; the last attempt's ... at (x, y[, z])`` for failure messages (or nothing)."""
        if self.failure_site is None:
            return ""
        where = ", ".join(f"{c:.4g}" for c in self.failure_site)
        return f"; the last attempt's largest unbalanced force was at ({where})"

    def equilibrate(self) -> Solution:
        """Newton at the form's current load from its current state (one carried over from
        another mesh, :mod:`brainbulge.solver.sequencing`), to the final tolerance, without
        load steps. On failure the state is restored and ``converged`` is false."""
        form = self.form
        start = time.perf_counter()
        t = float(form.load.Get())
        sol = Solution(form=form, load=t, converged=False)
        x = form.gfu.vec
        x0 = x.CreateVector()
        x0.data = x
        lam0 = form.multiplier_state()
        self.tolerance = self.opt.tolerance
        ok, its, norm = self.newton(x, self.opt.carried_curvature_tolerance)
        if ok:
            n_aug, its2, norm, pen = self._penetration(x, norm, final=t >= 1 - 1e-12)
            sol.steps.append(StepRecord(t, its + its2, n_aug, norm, pen))
            sol.converged = True
        else:
            x.data = x0
            form.restore_multipliers(lam0)
            sol.rejected_steps = 1
            sol.message = (f"Newton did not converge at load {t:.4f} from the given state "
                           f"(|R| = {norm:.2e} after {its} iterations)")
        return self._timed(sol, start)

    def _penetration(self, x: ngs.BaseVector, norm: float, final: bool
                     ) -> tuple[int, int, float, float]:
        """After a converged Newton solve: the largest penetration, and at full load the
        augmentations of the symbolic contacts; returns (augmentations, their Newton
        iterations, residual, penetration)."""
        form = self.form
        if not form.contacts_present:
            return 0, 0, norm, 0.0
        pen = self.max_penetration()
        if final and form.contact_multipliers:
            return self.augment(x, pen, self.opt.penetration_tol * self.length)
        return 0, 0, norm, pen

    def _timed(self, sol: Solution, start: float) -> Solution:
        """``sol`` with the wall, assembly and linear-solve times and Krylov iterations."""
        sol.wall_time_s = time.perf_counter() - start
        sol.assembly_time_s = self.t_assembly
        sol.solve_time_s = self.t_solve
        stats = getattr(self.linear, "stats", None)
        sol.linear_iterations = int(sum(stats.iterations)) if stats is not None else 0
        return sol


    # --- restart file ----------------------------------------------------------------------
    def _write_checkpoint(self, path: Path, x: ngs.BaseVector, t: float, dt: float,
                          increment: ngs.BaseVector, last_dt: float, sol: Solution) -> None:
        """The converged state at load ``t`` and what the next step needs (atomic write)."""
        form = self.form
        steps = np.array([[s.load, s.newton_iterations, s.augmentations, s.residual,
                           s.max_penetration] for s in sol.steps])
        tmp = path.with_name(path.name + ".tmp.npz")
        path.parent.mkdir(parents=True, exist_ok=True)
        np.savez(tmp, key=self.opt.checkpoint_key, ndof=len(x), t=t, dt=dt, last_dt=last_dt,
                 x=x.FV().NumPy(), increment=increment.FV().NumPy(), r=form.r.Get(),
                 steps=steps, rejected=sol.rejected_steps,
                 **{f"lam{i}": v for i, v in enumerate(form.multiplier_state())})
        os.replace(tmp, path)

    def _read_checkpoint(
        self, path: Path, x: ngs.BaseVector, sol: Solution
    ) -> tuple[float, float, ngs.BaseVector, float] | None:
        """Restore the state of a restart file of this problem; ``None`` if there is none."""
        if not path.is_file():
            return None
        n_lam = len(self.form.multiplier_state())
        needed = ("key", "ndof", "t", "dt", "last_dt", "x", "increment", "r", "steps",
                  "rejected")
        try:  # a truncated or foreign file (BadZipFile, EOFError, zlib.error, ...) is skipped
            with np.load(path, allow_pickle=False) as f:
                data = {k: f[k] for k in f.files}
            if any(k not in data for k in needed):
                raise ValueError("arrays missing")
        except Exception as exc:  # noqa: BLE001
            log.warning("restart file %s unreadable (%s): starting from Js = 1", path,
                        " ".join(str(exc).split()) or type(exc).__name__)
            return None
        if (str(data["key"]) != self.opt.checkpoint_key or int(data["ndof"]) != len(x)
                or any(f"lam{i}" not in data for i in range(n_lam))):
            log.info("restart file %s is of another problem: starting from Js = 1", path)
            return None
        form = self.form
        t = float(data["t"])
        x.FV().NumPy()[:] = data["x"]
        increment = x.CreateVector()
        increment.FV().NumPy()[:] = data["increment"]
        form.r.Set(float(data["r"]))
        form.restore_multipliers([data[f"lam{i}"] for i in range(n_lam)])
        form.set_load(t)
        sol.steps = [StepRecord(float(a), int(b), int(c), float(d), float(e))
                     for a, b, c, d, e in data["steps"].reshape(-1, 5)]
        sol.rejected_steps = int(data["rejected"])
        log.info("resuming from %s at load %.4f", path, t)
        return t, float(data["dt"]), increment, float(data["last_dt"])


def pc_free(pc, solver: NewtonSolver) -> np.ndarray:
    """Mask of the contact points of ``pc`` that move (have a free DOF)."""
    return solver._pc_free[id(pc)]


def _coo_sum(
    parts: list[sp.coo_matrix],
    shape: tuple[int, int],
    offsets: list[tuple[int, int]] | None = None,
    diagonal: bool = False,
) -> sp.csr_matrix:
    """Sum of sparse blocks placed at ``offsets``, through COO: a CSR sum would drop the
    structural zeros of the pressure (and multiplier) diagonal, which the symmetric-indefinite
    factorisation needs; ``diagonal`` adds the whole diagonal structurally."""
    offsets = offsets or [(0, 0)] * len(parts)
    rows = [m.row + o[0] for m, o in zip(parts, offsets, strict=True)]
    cols = [m.col + o[1] for m, o in zip(parts, offsets, strict=True)]
    data = [m.data for m in parts]
    if diagonal:
        rows.append(np.arange(shape[0]))
        cols.append(np.arange(shape[0]))
        data.append(np.zeros(shape[0]))
    return sp.coo_matrix(
        (np.concatenate(data), (np.concatenate(rows), np.concatenate(cols))), shape=shape
    ).tocsr()


def _augmented(K: sp.csr_matrix, b: np.ndarray, B: sp.csr_matrix, c: np.ndarray,
               is_u: np.ndarray) -> tuple[sp.csr_matrix, np.ndarray]:
    """The active-set system ``[[K, -B^T], [-B, 0]] [dx, dlam] = [b, c]`` in augmented form
    ``K + r B^T B``, ``b - r B^T c`` (the same solution, as ``B dx = -c``).

    Used when constraint rows share DOFs (P2 contact points: an edge midpoint's row reaches
    its ends), where :class:`NodalElimination` does not apply. PARDISO's pivoting on the
    plain saddle point (zero block under thousands of contact rows) returned residuals of
    1e17 on the 111k-tet brain, where the augmented matrix solves to 1e-12. The AMG of the
    Krylov solver's displacement block sees the constraints as stiff normal springs, and the
    multipliers' Schur complement becomes ``~ -I / r``, which a diagonal approximates well
    (Krylov iterations halved). ``r`` makes
    ``r |B_i|^2`` ten times the typical diagonal stiffness of a displacement DOF.
    """
    d = np.abs(K.diagonal()[is_u])
    row_sq = np.asarray(B.multiply(B).sum(axis=1)).ravel()
    r = 10.0 * float(np.median(d[d > 0])) / float(np.median(row_sq[row_sq > 0]))
    return (K + r * (B.T @ B)).tocsr(), b - r * (B.T @ c)


class NodalElimination:
    """The active-set system ``[[K, -B^T], [-B, 0]] [dx, dlam] = [b, c]`` with the constraints
    eliminated, when each constraint row acts on one node alone (P1 contact points: a vertex's
    normal displacement).

    With ``N = B^T diag(1/beta)`` (``beta_i = |B_i|``; orthonormal columns as the rows have
    disjoint supports), the tangent projector ``Pi = I - N N^T`` and ``gbar = -c / beta``,
    ``dx = y + N gbar`` where ``y`` solves the system of the original size::

        (Pi K Pi + d N N^T) y = Pi (b - K N gbar),      dlam = N^T (K dx - b) / beta

    (``d``: the mean diagonal stiffness of a displacement DOF; ``N^T y = 0``). The contact
    normals become Dirichlet-like conditions: no multiplier rows, an SPD displacement block
    for the AMG (the augmented form's stiff ``r B^T B`` springs cost GMRES ~4x the
    iterations of a clamped skull) and no zero-diagonal contact rows for PARDISO's symmetric
    factorisation. Written by hand: no library we use eliminates such constraints.
    """

    def __init__(self, K: sp.csr_matrix, B: sp.csr_matrix, c: np.ndarray,
                 is_u: np.ndarray, project: PatternProject | None = None) -> None:
        self.K = K
        self._project = project or PatternProject()
        self.beta = np.sqrt(np.asarray(B.multiply(B).sum(axis=1)).ravel())
        self.N = (B.T @ sp.diags(1.0 / self.beta)).tocsc()
        self.gbar = -np.asarray(c) / self.beta
        diag = np.abs(K.diagonal()[is_u])
        self.d = float(np.mean(diag[diag > 0]))

    @staticmethod
    def applies(B: sp.csr_matrix) -> bool:
        """Whether no two constraint rows share a DOF (each acts on its own node)."""
        return bool(np.all(np.bincount(B.indices, minlength=B.shape[1]) <= 1))

    def project(self, v: np.ndarray) -> np.ndarray:
        """``Pi v = v - N N^T v``."""
        return v - self.N @ (self.N.T @ v)

    def system(self, b: np.ndarray) -> tuple[sp.csr_matrix, np.ndarray]:
        """``(Pi K Pi + d N N^T, Pi (b - K N gbar))``."""
        K, N = self.K, self.N
        self._b = b
        # on K's pattern (Pi K Pi + d P lies in the node blocks K couples), so that the
        # Krylov solver's block plans stay valid whatever the active set
        Kp = self._project(K, N, self.d)
        return Kp, self.project(b - K @ (N @ self.gbar))

    def recover(self, y: np.ndarray) -> np.ndarray:
        """``[dx, dlam]`` from the solution ``y`` of :meth:`system`."""
        dx = self.project(y) + self.N @ self.gbar
        dlam = (self.N.T @ (self.K @ dx - self._b)) / self.beta
        return np.concatenate([dx, dlam])


ETA_MAX = 1e-4  # loosest relative tolerance of an inexact Newton solve
ETA_MIN = 1e-10  # tightest


def forcing_term(eta: float, ratio: float, norm: float, tolerance: float) -> float:
    """Relative tolerance of the next inexact linear solve (Eisenstat & Walker 1996, choice 2).

    ``eta_k = 0.9 (|R_k| / |R_k-1|)^2``, kept above ``0.9 eta_k-1^2`` while that is above
    0.1 (no sudden over-solving), not below ``0.1 tol/|R_k|`` (a linear residual below
    what the Newton tolerance needs buys nothing), and capped at :data:`ETA_MAX`.
    The cap wins over that floor: GMRES measures its residual in another norm than
    Newton's scaled one. (With the floor winning, the 1.54M-tet brain's last iteration ran
    at 0.06 instead of 1e-4 and still converged, but a 1.19M-tet brain's Newton stalled at
    |R| 1.5e-7, tolerance 1e-9: three iterations at 6e-4 lowered it by 3 %.)
    """
    eta_new = 0.9 * ratio**2
    if 0.9 * eta**2 > 0.1:
        eta_new = max(eta_new, 0.9 * eta**2)
    eta_new = max(eta_new, 0.1 * tolerance / max(norm, 1e-300))
    return float(min(max(eta_new, ETA_MIN), ETA_MAX))


def solve(
    problem: Problem,
    element: str = "taylor-hood",
    options: SolverOptions | None = None,
    compile_energy: bool = False,
) -> Solution:
    """Build the mixed form of ``problem`` and ramp the swelling to its target."""
    form = MixedForm(problem, element=element, compile_energy=compile_energy)
    return NewtonSolver(form, options).solve()

"""Newton's method with a backtracking line search on the mixed equations at one load.

At a fixed load factor ``t`` the state ``x = (u, p)`` (with the contact pressures
``lambda``) solves ``R(x) = 0``, the stationarity of the Lagrangian of docs/model.md section 2 plus
the contact forces. Newton's iteration is::

    K(x_k) dx = R(x_k),        x_{k+1} = x_k - s dx,        lambda_{k+1} = lambda_k - s dlam

with the contact constraints of the active set (:mod:`brainbulge.solver.contact`), and ``s``
halved from 1 until the scaled residual :meth:`Newton.scaled_norm` falls by the
Armijo factor ``1 - 1e-4 s``. With the Krylov solver the linear solve is inexact, to the
relative tolerance of :func:`brainbulge.solver.inexact.forcing_term`. A solve gives up, with
its reason, after ``max_iterations``, at a non-finite residual, when the line search finds no
step, after ``stagnation`` short steps in a row, or when it falls short of
``required_progress`` (:class:`SolverOptions`).

This is one nonlinear solve at the form's current load; the load ramp that calls it
(predictor, cut-back, restart) is :mod:`brainbulge.solver.ramp`.
"""

from __future__ import annotations

import logging
import time
from contextlib import nullcontext

import ngsolve as ngs
import numpy as np

from brainbulge.errors import ConvergenceError
from brainbulge.solver.equations import MixedEquations
from brainbulge.solver.fast.hotspot import HotspotRelaxation
from brainbulge.solver.inexact import ETA_MIN, forcing_term
from brainbulge.solver.mixed import MixedForm
from brainbulge.solver.options import SolverOptions
from brainbulge.solver.threads import serial_openblas

log = logging.getLogger("brainbulge")


class Newton(MixedEquations):
    """Newton's method at one load for a :class:`MixedForm`, controlled by ``options``
    (:class:`SolverOptions`: tolerance, iterations, the linear solver and the accelerations).

    Two accelerations apply where they can, each the plain path's result to round-off:
    ``closed`` (the closed-form MINI tangent, :mod:`brainbulge.solver.fast.mini_tangent`;
    option ``closed_form``) and ``relaxation`` (local solves at residual hotspots,
    :mod:`brainbulge.solver.fast.hotspot`; option ``hotspot_relaxation``).
    """

    def __init__(self, form: MixedForm, options: SolverOptions | None = None) -> None:
        super().__init__(form, options)
        self.history: list[list[float]] = []  # scaled residual norms of each Newton solve
        self.tightened_solves = 0  # directions solved again tighter after a failed line search
        self.failure_site: np.ndarray | None = None  # of the last Newton solve that failed
        self.failure_reason = ""  # why the last Newton solve failed ("": it converged)
        self._vertex_dofs: tuple[np.ndarray, np.ndarray] | None = None
        self.relaxation = (HotspotRelaxation(self) if self.opt.hotspot_relaxation
                           and HotspotRelaxation.applies(form) else None)

    def newton(self, x: ngs.BaseVector, tolerance: float | None = None,
               curvature_below: float = np.inf) -> tuple[bool, int, float]:
        """Solve at the current load from the guess ``x`` (updated in place, with the
        contact multipliers) to ``tolerance`` (default: the options' final one); returns
        (converged, iterations, scaled residual). On failure ``self.failure_site`` is where
        the force residual peaks and ``self.failure_reason`` says why it gave up.

        ``curvature_below``: the contacts' curvature term enters the tangent only at
        iterates whose scaled residual is at most this (a modified Newton method far from
        the solution, option ``carried_curvature_tolerance``)."""
        tol = self.opt.tolerance if tolerance is None else tolerance
        # one OpenBLAS thread beside PARDISO (brainbulge.solver.threads); the Krylov path's
        # long vectors keep theirs (111k-tet brain: 10 % slower on one)
        try:
            with nullcontext() if self.inexact else serial_openblas():
                ok, its, norm, self.failure_reason = self._newton(x, tol, curvature_below)
            if not ok:
                self.failure_site = self.residual_site(x)
            return ok, its, norm
        finally:
            self.with_curvature = True

    def residual_site(self, x: ngs.BaseVector) -> np.ndarray | None:
        """Deformed position ``X + u`` [length] of the vertex whose free displacement DOFs carry
        the largest force residual ``|R_v|`` at ``x`` (where a failed Newton solve left its
        imbalance: the place to look at, or to refine); None if ``R`` is not finite."""
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

    def _newton(self, x: ngs.BaseVector, tol: float, curvature_below: float
                ) -> tuple[bool, int, float, str]:
        """:meth:`newton`'s iteration: (converged, iterations, scaled residual, why it
        gave up)."""
        opt = self.opt
        pcs = self.contact.contacts
        self.contact.start_solve()
        self.eta = self.eta_cap = opt.eta_max
        self.linear.new_load_step()
        norm = self.scaled_norm(self.residual(x))
        self.history.append([])
        short_steps, norm_before_short = 0, norm  # the run of short line-search steps
        started = time.perf_counter()
        for it in range(opt.max_iterations + 1):
            self.history[-1].append(norm)
            elapsed = time.perf_counter() - started
            log.log(logging.INFO if elapsed > opt.slow_newton_s else logging.DEBUG,
                    "    newton %d: |R| = %.3e (%.0f s)", it, norm, elapsed)
            if norm <= tol:
                return True, it, norm, ""
            if not np.isfinite(norm):
                return False, it, norm, "the residual is not finite"
            if it == opt.max_iterations:
                return False, it, norm, f"max_iterations = {it} reached"
            progress = opt.required_progress
            if (progress is not None and it == progress[0]
                    and norm > progress[1] * self.history[-1][0]):
                log.debug("    too slow: |R| %.3e after %d iterations from %.3e", norm, it,
                          self.history[-1][0])
                return False, it, norm, (f"too slow: |R| above {progress[1]:g} times its "
                                         f"first ({self.history[-1][0]:.2e})")
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
                except ConvergenceError as exc:
                    if not self.inexact or self.eta <= ETA_MIN or not opt.retry_linear:
                        return False, it, norm, f"the linear solve failed ({exc})"
                    # a failed Krylov solve has asked for a fresh AMG: retry it, tighter
                    log.debug("    Krylov solve failed: retrying with a fresh preconditioner")
                    self.eta = ETA_MIN
                    try:
                        dx, dlams = self.newton_direction(x, K_x)
                    except ConvergenceError as exc:
                        return False, it, norm, f"the linear solve failed ({exc})"
                s, trial, tightened = self._line_search(x, x0, lam0, dx, dlams, norm, tol,
                                                        retry=attempt < 3, tightened=tightened)
                if s is None:
                    return False, it, norm, "the line search found no step lowering |R|"
                if s > 0:
                    self._log_step(s)
                    # (a full step that does not halve the residual is not the Krylov
                    # tolerance's doing here: from one 1.54M-tet state, GMRES at 1e-7
                    # instead of 1e-4 gave the same Newton residuals to four digits;
                    # tightening after such steps only doubled the GMRES iterations)
                    self.eta = min(self.eta_cap, forcing_term(self.eta, trial / norm, trial,
                                                              tol, opt.eta_max))
                    if s > 1 / 64:
                        short_steps, norm_before_short = 0, trial
                    else:
                        short_steps += 1
                    norm = trial
                    if self.relaxation is not None and norm > tol:
                        norm = self.relaxation.relax(x, norm)
                    break
                self._restore(x, x0, lam0)  # retry the direction at x0
                self.residual(x)
            self.contact.let_pulling_go()
            if (0 < opt.stagnation <= short_steps and norm > tol
                    and norm > 0.95 * norm_before_short):
                log.debug("    stagnated: %d short steps from |R| = %.3e", short_steps,
                          norm_before_short)
                return False, it + 1, norm, (f"stagnated: {short_steps} line-search steps "
                                             "of at most 1/64 in a row")
        its = opt.max_iterations  # (not reached: the loop returns at its last iteration)
        return False, its, norm, f"max_iterations = {its} reached"

    def _line_search(self, x: ngs.BaseVector, x0: ngs.BaseVector, lam0: list[np.ndarray],
                     dx: ngs.BaseVector, dlams: list[np.ndarray], norm: float, tol: float,
                     retry: bool, tightened: bool) -> tuple[float | None, float, bool]:
        """Backtracking from ``s = 1``: the first ``s`` (halved each time) whose trial state
        ``x0 - s dx`` has ``|R| < (1 - 1e-4 s) |R_0|`` or meets the tolerance ``tol``.

        Returns ``(s, |R(trial)|, tightened)``: ``s > 0`` accepted (``x`` is the trial state);
        ``s = 0`` when the direction should be solved again (``retry`` allowed): newly
        penetrating points were forced active, or a loose Krylov direction gave no step and
        is solved 100x tighter (once per iteration: ``tightened``); ``s = None`` when no step
        of at least 1/1024 lowers the residual (``x`` back at ``x0``).
        """
        pcs = self.contact.contacts
        s = 1.0
        while True:
            x.data = x0 - s * dx
            for pc, l0, dl in zip(pcs, lam0, dlams, strict=True):
                pc.lam = l0 - s * dl
            trial = self.scaled_norm(self.residual(x))
            if trial < (1 - 1e-4 * s) * norm or trial <= tol:
                return s, trial, tightened
            if s == 1.0 and retry and self.contact.force_penetrating():
                return 0.0, trial, tightened
            s *= 0.5
            if (s < 1 / 1024 and self.inexact and not tightened and self.eta > ETA_MIN
                    and retry):
                # no step at all from a loose Krylov direction: before giving up (and
                # cutting the load step) solve the direction 100x tighter. (Retrying at
                # every short step instead cost a 1.54M-tet run an 812 s solve for the same
                # 1/16 step: there the nonlinearity, not the direction, made the step short.)
                self.tightened_solves += 1
                self.eta = self.eta_cap = max(ETA_MIN, 1e-2 * self.eta)
                log.debug("    line search failed at Krylov rtol %.1e: retrying tighter",
                          1e2 * self.eta)
                return 0.0, trial, True
            if s < 1 / 1024:
                self._restore(x, x0, lam0)
                return None, trial, tightened

    def _restore(self, x: ngs.BaseVector, x0: ngs.BaseVector, lam0: list[np.ndarray]) -> None:
        x.data = x0
        for pc, l0 in zip(self.contact.contacts, lam0, strict=True):
            pc.lam = l0

    def _log_step(self, s: float) -> None:
        pcs = self.contact.contacts
        log.debug("    step %.3g, %d active contact points (%d pulling)%s%s", s,
                  sum(int(a.sum()) for a in self.contact.last_active),
                  sum(int((pc.lam < 0).sum()) for pc in pcs),
                  "" if self.with_curvature or not pcs else ", no curvature",
                  f", Krylov rtol {self.eta:.1e}" if self.inexact else "")


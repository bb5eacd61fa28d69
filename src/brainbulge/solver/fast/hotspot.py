"""Nonlinear elimination of a residual hotspot: Newton on the few vertices that hold most of
the residual, with every other DOF fixed.

Where Newton's residual sits at a handful of vertices whose local problem is nearly
singular, the global iteration converges only linearly there: at 1.40M tets the fine stage's
residual fell 0.25-0.3x per iteration, 90-100 % of ``|R|^2`` at three CSF vertices of the
flap rim's free surface (Newton at a double root falls 1/4 per step), and every such
iteration costs a global tangent (~40 s then, ~10 s in closed form since) and a GMRES
solve. Nonlinear elimination (Lanzkron, Rose & Wilkes 1996; Cai & Keyes 2002) solves the
hotspot's own equations to convergence first, which costs element matrices of a few
hundred tets.

After an accepted Newton step, with ``r_v`` the scaled residual of the DOFs at vertex ``v``
(displacements / ``mu L^(d-1)``, pressures / ``|Omega|``, as the Newton norm scales them):

(``share``, ``max_vertices``, ``rings`` and the local Newton's ``max_iterations`` are
``SolverOptions.hotspot``, :class:`~brainbulge.solver.options.HotspotOptions`)

- hotspot ``H``: the fewest vertices with ``sum_H r_v^2 >= share sum_v r_v^2``, if at most
  ``max_vertices``; else nothing is done (a residual spread over the body is Newton's job);
- patch ``P``: ``H`` and ``rings`` rings of neighbours, without vertices held by the skull
  (an active contact point; Dirichlet DOFs stay fixed anyway);
- local problem: ``R_i(x_P, x_rest) = 0`` for the displacement and pressure DOFs of ``P``
  and the bubbles of the elements around ``P`` (their equations involve those elements
  only), solved by Newton with a backtracking line search, element matrices from NGSolve's
  integrators (``CalcLinearizedElementMatrix`` / ``ApplyElementMatrix``) or, where it
  applies, the closed form (:mod:`brainbulge.solver.fast.mini_tangent`, ``mini_plane``),
  the sparse local tangent factorised by SuperLU.

The result is kept only when the global residual norm falls and no contact point of the
patch has come to press on the skull; else the state is restored. Written by hand: no
library we use does nonlinear elimination on an NGSolve form. MINI only (the DOFs off the
vertices are element bubbles; Taylor-Hood's edge DOFs would couple the patch's border).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import ngsolve as ngs
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from brainbulge.geometry.ngsolve_arrays import element_vertices, vertex_dofs
from brainbulge.solver.options import HotspotOptions

log = logging.getLogger("brainbulge")

HEAP = 1_000_000  # bytes of NGSolve's local heap per element matrix


@dataclass
class RelaxationRecord:
    """One local solve: hotspot and patch sizes, local Newton iterations, the global
    scaled residual before and after, and whether the result was kept."""

    hotspot: int
    patch: int
    iterations: int
    before: float
    after: float
    kept: bool


class HotspotRelaxation:
    """Local Newton on the residual hotspot of a MINI form's equations
    (:class:`~brainbulge.solver.equations.MixedEquations`)."""

    def __init__(self, solver, options: HotspotOptions | None = None) -> None:
        options = options or HotspotOptions()
        self.solver = solver
        self.share = options.share
        self.max_vertices = options.max_vertices
        self.rings = options.rings
        self.max_iterations = options.max_iterations
        self.records: list[RelaxationRecord] = []
        self.last_patch = np.zeros(0, dtype=bool)  # the vertices of the last patch
        self.last_dofs = np.zeros(0, dtype=np.int64)  # and the DOFs of its local solve
        self._maps: tuple | None = None

    @staticmethod
    def applies(form) -> bool:
        return form.element == "mini"

    # --- where the residual is ---------------------------------------------------------
    def _build_maps(self) -> tuple:
        """Element vertices, the vertex of each DOF (-1 for bubbles), the vertex-element
        incidence and each point contact's point vertices (once per solver)."""
        form = self.solver.form
        mesh, fes = form.mesh, form.fes
        els, regions = element_vertices(mesh)
        dof_vertex = np.full(fes.ndof, -1, dtype=np.int64)
        spaces = list(fes.components)
        for i, space in enumerate(spaces):
            if i == 0:
                mask = None
            else:  # a pressure zone's space: its own elements only
                zone = mesh.Materials(form.pressure_zones[i - 1]).Mask()
                mask = np.array(list(zone), dtype=bool)[regions]
            vd = vertex_dofs(space, mesh, mask) if mask is None or mask.any() else None
            if vd is None:
                continue
            start = fes.Range(i).start
            v, c = np.nonzero(vd >= 0)
            dof_vertex[start + vd[v, c]] = v
        ne, nv = len(els), mesh.nv
        incidence = sp.csr_matrix(
            (np.ones(els.size, dtype=np.int8), (np.repeat(np.arange(ne), els.shape[1]),
                                                els.ravel())), shape=(ne, nv))
        point_vertex = []
        for pc in form.point_contacts:
            coo = pc.P.tocoo()
            pv = np.full(pc.n_points, -1, dtype=np.int64)
            pv[coo.row // form.dim] = dof_vertex[coo.col]
            point_vertex.append(pv)
        free_full = np.array(list(fes.FreeDofs(False)), dtype=bool)
        self._maps = (els, regions, dof_vertex, incidence, point_vertex, free_full)
        return self._maps

    def hotspot(self, r: np.ndarray) -> np.ndarray | None:
        """Vertices ``H`` holding ``share`` of the scaled ``|R|^2`` (at most
        ``max_vertices``), or ``None``."""
        s = self.solver
        _, _, dof_vertex, incidence, _, _ = self._maps or self._build_maps()
        rf = r[s.free]
        scaled = np.where(s.is_u_free, rf / s.force_scale, rf / s.volume)
        fv = dof_vertex[s.free]
        on = fv >= 0
        per_v = np.bincount(fv[on], weights=scaled[on] ** 2, minlength=incidence.shape[1])
        total = per_v.sum()
        if not total > 0:
            return None
        m = min(self.max_vertices, len(per_v))
        top = np.argpartition(per_v, len(per_v) - m)[-m:]  # the m largest, then in order
        top = top[np.argsort(per_v[top])[::-1]]
        k = int(np.searchsorted(np.cumsum(per_v[top]) / total, self.share)) + 1
        if k > len(top):
            return None
        return top[:k]

    # --- the local solve ------------------------------------------------------------------
    def active_points(self) -> list[np.ndarray]:
        """Per point contact: its points that keep ``g = 0`` in a local solve (active and on
        a vertex)."""
        s = self.solver
        point_vertex = (self._maps or self._build_maps())[4]
        return [pc.active(s.contact.c_active) & (pv >= 0)
                for pc, pv in zip(s.form.point_contacts, point_vertex, strict=True)]

    def local_problem(self, hot: np.ndarray, active: list[np.ndarray] | None = None
                      ) -> LocalProblem | None:
        """The local problem of the vertices ``hot`` and ``rings`` rings of elements around
        them; its contact points are the ``active`` ones (:meth:`active_points` by default)
        of the patch. A point releasing its pressure (``lambda != 0``, not active) holds its
        vertex fixed. ``None`` when no vertex of ``hot`` is left free."""
        els, regions, dof_vertex, incidence, point_vertex, free_full = (
            self._maps or self._build_maps())
        pcs = self.solver.form.point_contacts
        active = self.active_points() if active is None else active
        held = np.zeros(incidence.shape[1], dtype=bool)
        for pc, pv, act in zip(pcs, point_vertex, active, strict=True):
            held[pv[(pc.lam != 0) & ~act & (pv >= 0)]] = True
        patch = np.zeros(incidence.shape[1], dtype=bool)
        patch[hot] = True
        for _ in range(self.rings):
            near = incidence[incidence[:, np.flatnonzero(patch)].sum(axis=1).A1 > 0]
            patch[near.indices] = True
        patch &= ~held
        self.last_patch = patch
        if not patch[hot].any():
            return None
        elements = np.flatnonzero(incidence[:, np.flatnonzero(patch)].sum(axis=1).A1 > 0)
        contacts = [(pc, np.flatnonzero(act & patch[np.maximum(pv, 0)]))
                    for pc, pv, act in zip(pcs, point_vertex, active, strict=True)]
        return LocalProblem(self.solver, elements, regions, patch, dof_vertex, free_full,
                            contacts)

    def relax(self, x: ngs.BaseVector, norm: float) -> float:
        """Solve the hotspot's equations at ``x`` (in place) when there is one; returns the
        global scaled residual norm at the (kept or restored) state, ``self.solver.res``
        holding its residual."""
        s = self.solver
        hot = self.hotspot(s.res.FV().NumPy())
        if hot is None:
            return norm
        pcs = s.form.point_contacts
        point_vertex = self._maps[4]
        active = self.active_points()
        problem = self.local_problem(hot, active)
        if problem is None:
            return norm
        patch = problem.patch
        self.last_dofs = problem.dofs
        X = x.FV().NumPy()
        saved = s.state.snapshot()
        res_saved, compl_saved = s.res.FV().NumPy().copy(), s.contact.complementarity
        its = problem.solve(X, target=0.01 * norm, max_iterations=self.max_iterations)
        new = s.scaled_norm(s.residual(x))
        penetrating = any(  # a free point of the patch that came to press on the skull
            (pc.active(s.contact.c_active) & ~act & patch[np.maximum(pv, 0)] & (pv >= 0)).any()
            for pc, pv, act in zip(pcs, point_vertex, active, strict=True))
        kept = bool(new < norm and not penetrating)
        self.records.append(RelaxationRecord(len(hot), int(patch.sum()), its, norm, new, kept))
        log.debug("    hotspot: %d vertices, patch of %d (%d tets, %d contact points), %d local "
                  "Newton iterations: |R| %.3e -> %.3e%s", len(hot), int(patch.sum()),
                  len(problem.items), sum(len(c[1]) for c in problem.contacts), its, norm, new,
                  "" if kept else ", not kept")
        if kept:
            return new
        s.state.restore(saved)  # and the residual at it, without evaluating it again
        for pc in pcs:
            pc.update(X)
        s.res.FV().NumPy()[:] = res_saved
        s.contact.complementarity = compl_saved
        return norm


class LocalProblem:
    """The equations of a patch's DOFs, assembled from its elements' matrices, and the
    constraints ``g_i = 0`` of its active contact points (multipliers ``lambda_i``)::

        r_x = R(x) - P^T [A_i lambda_i n_i],   r_lambda = -A_i g_i,
        [[K - P^T (A lambda grad^2 g) P, -P^T N], [-N^T P, 0]]   (N_i = A_i n_i)

    as :mod:`brainbulge.solver.contact.points` writes them for the whole body."""

    def __init__(self, solver, elements: np.ndarray, regions: np.ndarray, patch: np.ndarray,
                 dof_vertex: np.ndarray, free_full: np.ndarray,
                 contacts: list[tuple[object, np.ndarray]] = ()) -> None:
        form = solver.form
        mesh, fes = form.mesh, form.fes
        self.solver = solver
        self.patch = patch  # its vertices
        self.items = []  # per element: fe, trafo, dofs, integrators, local rows (-1: fixed)
        dofs_all = []
        n_regions = len(mesh.GetMaterials())
        integrators = []
        for bfi in form.a.integrators:  # (an empty BitArray: defined everywhere)
            on = np.array(list(bfi.GetDefinedOn()), dtype=bool)
            integrators.append((bfi, on if len(on) else np.ones(n_regions, dtype=bool)))
        for e in elements:
            ei = ngs.ElementId(ngs.VOL, int(e))
            dofs = np.array(fes.GetDofNrs(ei), dtype=np.int64)
            bfis = [bfi for bfi, on in integrators if on[regions[e]]]
            self.items.append((fes.GetFE(ei), mesh.GetTrafo(ei), dofs, bfis))
            dv = dof_vertex[dofs]
            local = free_full[dofs] & np.where(dv >= 0, patch[np.maximum(dv, 0)], True)
            dofs_all.append(dofs[local])
        self.dofs = np.unique(np.concatenate(dofs_all))
        pos = {int(d): i for i, d in enumerate(self.dofs)}
        self.items = [(fe, tr, dofs, bfis, np.array([pos.get(int(d), -1) for d in dofs]))
                      for fe, tr, dofs, bfis in self.items]
        # the closed form's element systems, all elements at once (else NGSolve's, one by one)
        self.closed = solver.closed
        if self.closed is not None:
            self.elements = np.asarray(elements, dtype=np.int64)
            self.loc = np.array([item[4] for item in self.items])
        u = fes.Range(0)
        is_u = (self.dofs >= u.start) & (self.dofs < u.stop)
        self.scale = np.where(is_u, 1 / solver.force_scale, 1 / solver.volume)
        self.volume = solver.volume
        d = form.dim
        self.contacts = []  # pc, its points, P at them (all DOFs, local DOFs)
        for pc, pts in contacts:
            rows = (pts[:, None] * d + np.arange(d)).ravel()
            moving = np.diff(pc.P[rows][:, self.dofs].tocsr().indptr).reshape(-1, d).sum(1) > 0
            pts = pts[moving]  # (a point with no local DOF has no equation here)
            if len(pts):
                rows = (pts[:, None] * d + np.arange(d)).ravel()
                P = pc.P[rows]
                self.contacts.append((pc, pts, P, P[:, self.dofs].tocsr()))
        self.n_lam = sum(len(pts) for _, pts, _, _ in self.contacts)

    def multipliers(self) -> np.ndarray:
        return np.concatenate([pc.lam[pts] for pc, pts, _, _ in self.contacts] or [[]])

    def set_multipliers(self, lam: np.ndarray) -> None:
        k = 0
        for pc, pts, _, _ in self.contacts:
            pc.lam[pts] = lam[k : k + len(pts)]
            k += len(pts)

    def assemble(self, X: np.ndarray, lam: np.ndarray, tangent: bool
                 ) -> tuple[np.ndarray, sp.csc_matrix | None]:
        """Local residual ``(r_x, r_lambda)`` (and tangent) at the full state ``X`` and the
        patch's multipliers ``lam``."""
        n = len(self.dofs)
        R = np.zeros(n + self.n_lam)
        rows, cols, vals = [], [], []
        if self.closed is not None:
            r_e, K_e = self.closed.element_systems(self.elements, X, tangent)
            on = self.loc >= 0
            np.add.at(R, self.loc[on], r_e[on])
            if tangent:
                pair = on[:, :, None] & on[:, None, :]
                rows.append(np.broadcast_to(self.loc[:, :, None], K_e.shape)[pair])
                cols.append(np.broadcast_to(self.loc[:, None, :], K_e.shape)[pair])
                vals.append(K_e[pair])
        else:
            for fe, tr, dofs, bfis, loc in self.items:
                xe = ngs.Vector(X[dofs])
                on = loc >= 0
                li = loc[on]
                for bfi in bfis:
                    R[li] += np.asarray(bfi.ApplyElementMatrix(fe, xe, tr, HEAP))[on]
                    if tangent:
                        Ke = np.asarray(bfi.CalcLinearizedElementMatrix(fe, xe, tr, HEAP))
                        rows.append(np.repeat(li, len(li)))
                        cols.append(np.tile(li, len(li)))
                        vals.append(Ke[np.ix_(on, on)].ravel())
        blocks = []
        k = n
        for pc, pts, P, P_loc in self.contacts:
            m, d = len(pts), pc.dim
            x = pc.X[pts] + (P @ X).reshape(m, d)
            g, normal = pc.obstacle.gap_and_normal(x)
            g = g - pc.g0[pts]
            w, lm = pc.weights[pts], lam[k - n : k - n + m]
            R[:n] -= P_loc.T @ ((w * lm)[:, None] * normal).ravel()
            R[k : k + m] = -w * g
            if tangent:
                H = -(w * lm)[:, None, None] * pc.hessian_at(x)
                Hb = sp.block_diag(list(H), format="csr")
                N = sp.csr_matrix(((w[:, None] * normal).ravel(),
                                   (np.arange(m * d), np.repeat(np.arange(m), d))),
                                  shape=(m * d, m))
                blocks.append(((P_loc.T @ Hb @ P_loc).tocoo(), (0, 0)))
                blocks.append(((-(P_loc.T @ N)).tocoo(), (0, k)))
                blocks.append(((-(P_loc.T @ N)).T.tocoo(), (k, 0)))
            k += m
        if not tangent:
            return R, None
        for B, (r0, c0) in blocks:
            rows.append(B.row + r0)
            cols.append(B.col + c0)
            vals.append(B.data)
        size = n + self.n_lam
        K = sp.csc_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                          shape=(size, size))
        return R, K

    def norm(self, R: np.ndarray) -> float:
        n = len(self.dofs)
        val = float(np.hypot(np.linalg.norm(R[:n] * self.scale),
                             np.linalg.norm(R[n:]) / self.volume))
        return val if np.isfinite(val) else np.inf

    def solve(self, X: np.ndarray, target: float, max_iterations: int) -> int:
        """Newton with backtracking on the local DOFs of ``X`` (in place) and the patch's
        multipliers until the local scaled residual is at most ``target``; returns the
        iterations."""
        lam = self.multipliers()
        R, K = self.assemble(X, lam, tangent=True)
        norm = self.norm(R)
        n = len(self.dofs)
        for it in range(max_iterations):
            if norm <= target:
                return it
            try:
                dy = spla.splu(K).solve(R)
            except RuntimeError:  # singular local tangent: leave the state as it is
                return it
            if not np.all(np.isfinite(dy)):
                return it
            x0, lam0 = X[self.dofs].copy(), lam.copy()
            step = 1.0
            while step >= 1 / 64:
                X[self.dofs] = x0 - step * dy[:n]
                lam = lam0 - step * dy[n:]
                trial = self.norm(self.assemble(X, lam, tangent=False)[0])
                if trial < (1 - 1e-4 * step) * norm:
                    break
                step *= 0.5
            else:
                X[self.dofs] = x0
                self.set_multipliers(lam0)
                return it
            self.set_multipliers(lam)
            R, K = self.assemble(X, lam, tangent=True)
            norm = self.norm(R)
        return max_iterations

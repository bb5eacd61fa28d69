"""Block-preconditioned GMRES for the condensed MINI (P1-bubble / P1) tangent.

After static condensation of the bubbles the tangent restricted to the free DOFs reads::

    K = [[A, B^T],
         [B, -C]]

with ``A`` the (condensed) displacement stiffness, ``B`` the linearised constraint and
``C >= 0`` the pressure-pressure block that condensing the bubbles leaves behind (MINI's
stabilisation, of order ``h^2 / mu``). ``A`` is not always positive definite: at a swollen
state the geometric term ``p d2J`` makes it indefinite where the pressure exceeds the local
shear modulus. So the method is right-preconditioned GMRES with the block upper-triangular
preconditioner::

    P = [[A~, B^T], [0, -S~]]
    A^-1 ~ one V-cycle of smoothed-aggregation AMG (:mod:`.amg`), rigid-body modes as the
           near-nullspace, aggregation on node blocks, Gauss-Seidel smoothing
    S^-1 ~ one AMG V-cycle on S~ = C + B diag(A)^-1 B^T      (SIMPLE's Schur complement)

The textbook ``S~ = M_p / mu`` is spectrally equivalent to ``S`` for one continuous pressure,
but the pressure here is broken across material zones, and the zones include one-element-thick
layers (CSF, cortex): with the exact ``A`` the mass-matrix Schur complement needed 162-194
GMRES iterations on the 21k-tet brain (61 with one continuous pressure), SIMPLE's 48
(``benchmarks/bench_linear.py`` reruns the comparison). Block-diagonal MINRES needs an SPD
``A~``, which the swollen tangent does not give.

The AMG hierarchies are set up once (``setup``) and reused across Newton iterations: only the
finest level's matrix and smoother are refreshed, ``S~`` once per load step
(:meth:`BlockKrylovSolver.new_load_step`); everything is rebuilt after a failed solve or on
request (``refresh()``). Every solve checks the true residual
``|rhs - K x| / |rhs|`` and raises :class:`ConvergenceError` if it is above ``rtol``.

GMRES is written here rather than taken from SciPy: SciPy's ``gmres`` preconditions from the
left, so it stops on the preconditioned residual (it reported success at a true relative
residual of 0.2 on the brain's tangent). Here GMRES is right-preconditioned: it minimises the
true residual.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from brainbulge.errors import ConvergenceError, InputError
from brainbulge.heap import release_free_memory
from brainbulge.solver.linear.amg import AMGCycle, HierarchicalTwoLevel
from brainbulge.solver.linear.layout import DisplacementLayout, displacement_layout, free_dofs
from brainbulge.solver.linear.sparse_reuse import PatternGather, canonical
from brainbulge.solver.options import KrylovOptions
from brainbulge.solver.threads import serial_openblas

log = logging.getLogger("brainbulge")


@dataclass
class KrylovStats:
    """What the last solves did (for benchmarks and logs)."""

    setups: int = 0
    setup_time_s: float = 0.0
    schur_builds: int = 0
    solves: int = 0
    solve_time_s: float = 0.0
    iterations: list[int] = field(default_factory=list)
    residuals: list[float] = field(default_factory=list)


class BlockKrylovSolver:
    """GMRES with an AMG block preconditioner for ``K x = r`` (the MINI tangent;
    Taylor-Hood's with a two-level cycle on its P2 block, :class:`HierarchicalTwoLevel`).

    ``K`` may have more rows than ``is_u``: the extra trailing rows and columns are further
    multipliers (the active contact constraints of a primal-dual active set, with a zero
    diagonal block); their number may change from one solve to the next. Their Schur
    complement is approximated by ``diag(B_c diag(A)^-1 B_c^T)``.

    Args:
        is_u: (n_free,) True at displacement DOFs among the free DOFs.
        layout: vertex and component of each free displacement DOF (for the rigid-body
            near-nullspace and the node blocks of the AMG).
        krylov: the iteration budget per solve (all restarts included), the restart length
            and the AMG refresh factor (:class:`~brainbulge.solver.options.KrylovOptions`).
        rtol: default relative tolerance on the true residual ``|r - K x| / |r|``.
        amg: extra keyword arguments for ``pyamg.smoothed_aggregation_solver`` (both blocks).

    Attributes:
        amg_u: the cycle approximating ``A^-1`` (:class:`AMGCycle`, or
            :class:`HierarchicalTwoLevel` for a P2 displacement block).
        amg_p: the AMG cycle approximating ``S~^-1``.
    """

    def __init__(self, is_u: np.ndarray, layout: DisplacementLayout,
                 krylov: KrylovOptions | None = None, rtol: float = 1e-8,
                 amg: dict | None = None) -> None:
        krylov = krylov or KrylovOptions()
        self.is_u = np.asarray(is_u, dtype=bool)
        self.iu = np.flatnonzero(self.is_u)
        self.ip = np.flatnonzero(~self.is_u)
        if len(layout.vertex) != len(self.iu):
            raise InputError("layout and is_u disagree on the number of displacement DOFs")
        self.layout = layout
        self.rtol = rtol
        self.maxiter = krylov.max_iterations
        self.restart = krylov.restart
        self.schur_drop = krylov.schur_drop
        self._schur_stale = True  # S~ to be rebuilt at the next solve
        self.stats = KrylovStats()
        self._refresh_requested = False
        self._ready = False
        self._block_plans: tuple[PatternGather, ...] = ()
        self._block_plans_rows = -1
        # displacement AMG on node blocks of the P1 DOFs: slot = dim * node + component
        lin = layout.linear
        nodes, node_idx = np.unique(layout.vertex[lin], return_inverse=True)
        dim = layout.dim
        slot = dim * node_idx + layout.component[lin]
        B = np.zeros((dim * len(nodes), 3 if dim == 2 else 6))
        B[slot] = layout.rigid_body_modes()[lin]
        # MINI: the AMG alone, on K's displacement rows; Taylor-Hood: around it (on the P1
        # rows of the displacement block), Gauss-Seidel on the P2 block
        amg_1 = AMGCycle(dim * len(nodes), slot, dim, B, amg or {},
                         index=self.iu if lin.all() else np.flatnonzero(lin),
                         sweeps=krylov.smoother_sweeps)
        self.amg_u = amg_1 if lin.all() else HierarchicalTwoLevel(self.iu, amg_1)
        self.amg_p = AMGCycle(len(self.ip), np.arange(len(self.ip)), 1, None, amg or {},
                              sweeps=krylov.smoother_sweeps)

    @classmethod
    def from_form(cls, form, krylov: KrylovOptions | None = None, **options
                  ) -> BlockKrylovSolver:
        """Everything the constructor needs, from a MINI or Taylor-Hood :class:`MixedForm`;
        ``krylov`` and ``options`` as the constructor's."""
        free = free_dofs(form)
        rng = form.fes.Range(0)
        is_u = (free >= rng.start) & (free < rng.stop)
        return cls(is_u, displacement_layout(form, free), krylov, **options)

    # --- set-up and reuse ----------------------------------------------------------------
    def _blocks(self, K: sp.csr_matrix) -> tuple[np.ndarray, sp.csr_matrix, sp.csr_matrix]:
        """The diagonal of ``A``, ``B^T`` and ``C`` over the multiplier DOFs: the pressures,
        then any rows of ``K`` beyond ``len(is_u)`` (e.g. contact multipliers of an active
        set). ``A`` itself is not cut out: its AMG gathers its finest level from ``K``."""
        n0 = len(self.is_u)
        if K.shape[0] < n0:
            raise InputError(f"the matrix has {K.shape[0]} rows, fewer than is_u ({n0})")
        if self._block_plans_rows != K.shape[0]:  # another number of multiplier rows
            iu, iq = self.iu, np.concatenate([self.ip, np.arange(n0, K.shape[0])])
            self._block_plans = (PatternGather(lambda M: M[iu][:, iq]),
                                 PatternGather(lambda M: M[iq][:, iq]))
            self._block_plans_rows = K.shape[0]
        Bt, Cneg = (plan(K) for plan in self._block_plans)
        Cneg.data *= -1.0  # (its own values: a gather)
        return K.diagonal()[self.iu], Bt, Cneg

    @staticmethod
    def _d_inv(a_diag: np.ndarray) -> np.ndarray:
        d = np.abs(a_diag)
        return np.divide(1.0, d, out=np.zeros_like(d), where=d > 0)

    def schur_matrix(self, a_diag: np.ndarray, Bt, C) -> sp.csr_matrix:
        """``S~ = C + B diag(A)^-1 B^T`` (SIMPLE's Schur complement) over the pressures
        (``a_diag``: the diagonal of ``A``), its couplings weaker than ``schur_drop
        sqrt(|S_ii S_jj|)`` (:class:`KrylovOptions`) lumped onto the diagonal (stays SPD, a
        cheaper V-cycle). A subclass may approximate ``S`` otherwise.

        The weak entries are dropped from the CSR arrays and the lumps added to the stored
        diagonal in place: no COO copy of the distance-2 stencil, no second CSR."""
        n_p = len(self.ip)
        Bt = Bt[:, :n_p]
        S = canonical(Bt.T @ sp.diags(self._d_inv(a_diag)) @ Bt + C[:n_p][:, :n_p])
        S.sum_duplicates()
        dg = S.diagonal()
        row = np.repeat(np.arange(n_p, dtype=S.indices.dtype), np.diff(S.indptr))
        weak = np.abs(S.data) < self.schur_drop * np.sqrt(np.abs(dg[row] * dg[S.indices]))
        weak &= row != S.indices
        lump = np.bincount(row[weak], np.abs(S.data[weak]), minlength=n_p)
        indptr = np.zeros(n_p + 1, dtype=np.int64)
        np.cumsum(np.bincount(row[~weak], minlength=n_p), out=indptr[1:])
        del row
        keep = ~weak
        S = sp.csr_matrix((S.data[keep], S.indices[keep], indptr), shape=S.shape)
        S.has_sorted_indices = True
        S.setdiag(S.diagonal() + lump)  # the diagonal is stored (SIMPLE's is positive)
        self.stats.schur_builds += 1
        return S

    def setup(self, K: sp.csr_matrix, blocks: tuple | None = None) -> None:
        """Build the AMG hierarchies (displacement block, and the Schur approximation);
        ``blocks``: :meth:`_blocks` of ``K`` if already cut."""
        t0 = time.perf_counter()
        self._ready = False
        self.amg_p.ml = None  # no old hierarchy kept while new ones are built (the
        # displacement one is dropped by AMGCycle.setup)
        a_diag, Bt, C = self._blocks(K) if blocks is None else blocks
        self.amg_u.setup(K)
        self.amg_p.setup(self.schur_matrix(a_diag, Bt, C))
        self._schur_stale = False
        self._ready = True
        self._refresh_requested = False
        self.stats.setups += 1
        self.stats.setup_time_s += time.perf_counter() - t0
        log.debug("AMG setup %.2f s: displacements %s", time.perf_counter() - t0,
                  self.amg_u.describe())

    def refresh(self) -> None:
        """Rebuild the AMG hierarchies at the next solve."""
        self._refresh_requested = True

    def new_load_step(self) -> None:
        """:class:`brainbulge.solver.linear.LinearSolver`'s hook: a new load step rebuilds
        ``S~`` (and its finest AMG level) at the next solve; within a load step it is kept.

        The heap's free pages go back to the system here too
        (:func:`brainbulge.heap.release_free_memory`): at 1.40M tets the kept heap had grown
        by ~0.4 GB per load step (arrays freed in one step that the next step's, of other
        sizes as contact points enter, do not fill); within a load step the touched pages
        are kept."""
        self._schur_stale = True
        release_free_memory()

    def release(self) -> None:
        """Free the AMG hierarchies and the sparse plans (a later solve makes them again)."""
        self.amg_u.release()
        self.amg_p.release()
        self._block_plans, self._block_plans_rows = (), -1
        self._ready = False

    def _update(self, K: sp.csr_matrix) -> tuple[np.ndarray, sp.csr_matrix, sp.csr_matrix]:
        """New matrix: rebuild the hierarchies or reuse them (finest level refreshed)."""
        blocks = self._blocks(K)
        if not self._ready or self._refresh_requested:
            self.setup(K, blocks)
            return blocks
        self.amg_u.update(K)
        if self._schur_stale:
            self.amg_p.update(self.schur_matrix(*blocks))
            self._schur_stale = False
        return blocks

    # --- preconditioner ------------------------------------------------------------------
    def _preconditioner(self, a_diag: np.ndarray, Bt, C) -> Callable[[np.ndarray], np.ndarray]:
        """``z = P^-1 r``: ``z_q = -S~^-1 r_q``, then ``z_u = A~^-1 (r_u - B^T z_q)``."""
        iu = self.iu
        n0, n_p = len(self.is_u), len(self.ip)
        iq = np.concatenate([self.ip, np.arange(n0, n0 + Bt.shape[1] - n_p)])
        amg_u, amg_p = self.amg_u, self.amg_p
        # extra multipliers (rows beyond is_u): diag(B D^-1 B^T + C) of their own
        d_inv = self._d_inv(a_diag)
        Bt_e = Bt[:, n_p:]
        e_diag = (Bt_e.multiply(Bt_e)).T @ d_inv + np.maximum(C.diagonal()[n_p:], 0.0)
        e_inv = np.divide(1.0, e_diag, out=np.zeros_like(e_diag), where=e_diag > 0)

        def apply(r: np.ndarray) -> np.ndarray:
            z = np.empty_like(r)
            rq = r[iq]
            zq = -np.concatenate([amg_p(rq[:n_p]), e_inv * rq[n_p:]])
            z[iq] = zq
            z[iu] = amg_u(r[iu] - Bt @ zq)
            return z

        return apply

    # --- solve ---------------------------------------------------------------------------
    def solve(self, K: sp.csr_matrix, r: np.ndarray, rtol: float | None = None,
              x0: np.ndarray | None = None) -> np.ndarray:
        """``x`` with ``|r - K x| <= rtol |r|`` (true residual), else ConvergenceError.

        ``x0``: an initial guess (e.g. the solution of a nearby system); the tolerance stays
        relative to ``|r|``.
        """
        rtol = self.rtol if rtol is None else rtol
        t0 = time.perf_counter()
        blocks = self._update(K)
        with serial_openblas():  # small BLAS-2 work: threads cost more than they give
            x, its, res = self._krylov(K, r, rtol, self._preconditioner(*blocks), x0)
        log.debug("    %s: %d iterations, relative residual %.1e (%.1f s)", "gmres", its,
                  res, time.perf_counter() - t0)
        self.stats.solves += 1
        self.stats.iterations.append(its)
        self.stats.residuals.append(res)
        self.stats.solve_time_s += time.perf_counter() - t0
        if not res <= rtol:
            self._refresh_requested = True
            raise ConvergenceError(
                f"GMRES reached a relative residual of {res:.2e} > {rtol:.1e} in "
                f"{its} iterations; raise maxiter or use the direct solver")
        return x

    def _krylov(self, K, r: np.ndarray, rtol: float, M,
                x0: np.ndarray | None = None) -> tuple[np.ndarray, int, float]:
        """Restarted Krylov on the true defect until the true residual meets ``rtol``."""
        r = np.asarray(r, dtype=float)
        norm_r = float(np.linalg.norm(r))
        x = np.zeros_like(r)
        if norm_r == 0.0:
            return x, 0, 0.0
        its = 0
        inner_rtol = rtol
        res = 1.0
        defect = r
        if x0 is not None and x0.shape == r.shape:
            defect = r - K @ x0
            res = float(np.linalg.norm(defect)) / norm_r
            if res < 1.0:  # a guess worse than zero is dropped
                x = np.array(x0, dtype=float)
                if res <= rtol:
                    return x, 0, res
            else:
                defect, res = r, 1.0
        while its < self.maxiter:
            target = inner_rtol * norm_r / np.linalg.norm(defect)
            dx, k, _ = _gmres(K, defect, M, target, self.maxiter - its, self.restart)
            x += dx
            its += k
            defect = r - K @ x
            res = float(np.linalg.norm(defect)) / norm_r
            if not np.isfinite(res):
                return x, its, np.inf
            if res <= rtol or k == 0:
                return x, its, res
            # GMRES's estimate (rounding) was optimistic:
            # restart from the true defect asking for more than the remaining reduction
            inner_rtol = max(inner_rtol * rtol / res, 1e-16)
        return x, its, res



def _gmres(K, b: np.ndarray, M, rtol: float, maxiter: int,
           restart: int) -> tuple[np.ndarray, int, float]:
    """Right-preconditioned restarted GMRES, ``x0 = 0``; the residual it tracks is the true
    one (up to rounding). Returns ``(x, iterations, estimated relative residual)``.

    ``M`` is linear (AMG V-cycles with fixed smoothers, block substitutions), so the update of
    a cycle is ``x += M(V_k y)`` with one more application of ``M``, instead of keeping the
    preconditioned vectors ``Z_k = M V_k`` (flexible GMRES): half the basis memory, and half
    of its fresh pages, which are what a large basis costs here (a 60-row basis at 6M DOFs:
    0.6-10 s to fault in on this VM against 0.2 s to rewrite touched rows).
    """
    n = len(b)
    x = np.zeros(n)
    norm_b = float(np.linalg.norm(b))
    its = 0
    r = b.copy()
    beta = norm_b
    while its < maxiter:
        m = min(restart, maxiter - its)
        V = np.empty((m + 1, n))  # rows are written before they are read
        H = np.zeros((m + 1, m))
        cs = np.zeros(m)
        sn = np.zeros(m)
        g = np.zeros(m + 1)
        g[0] = beta
        V[0] = r / beta
        k = 0
        for k in range(m):
            w = K @ M(V[k])
            # classical Gram-Schmidt, twice (BLAS-2 on the basis)
            h = V[: k + 1] @ w
            w -= h @ V[: k + 1]
            h2 = V[: k + 1] @ w
            w -= h2 @ V[: k + 1]
            h += h2
            H[: k + 1, k] = h
            H[k + 1, k] = np.linalg.norm(w)
            if H[k + 1, k] > 0:
                V[k + 1] = w / H[k + 1, k]
            for i in range(k):  # apply the previous rotations
                t = cs[i] * H[i, k] + sn[i] * H[i + 1, k]
                H[i + 1, k] = -sn[i] * H[i, k] + cs[i] * H[i + 1, k]
                H[i, k] = t
            d = np.hypot(H[k, k], H[k + 1, k])
            cs[k], sn[k] = H[k, k] / d, H[k + 1, k] / d
            H[k, k] = d
            H[k + 1, k] = 0.0
            g[k + 1] = -sn[k] * g[k]
            g[k] = cs[k] * g[k]
            its += 1
            if abs(g[k + 1]) <= rtol * norm_b or H[k, k] == 0:
                break
        k += 1
        y = np.linalg.solve(np.triu(H[:k, :k]), g[:k])
        x += M(y @ V[:k])
        r = b - K @ x
        beta = float(np.linalg.norm(r))
        if beta <= rtol * norm_b:
            break
    return x, its, beta / norm_b

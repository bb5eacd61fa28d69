"""Algebraic multigrid cycles for the blocks of the saddle-point preconditioner
(:mod:`.krylov`): one smoothed-aggregation V-cycle (pyamg) with its hierarchy kept across
Newton iterations (:class:`AMGCycle`), and a two-level cycle for a hierarchical P2
displacement block (:class:`HierarchicalTwoLevel`, Taylor-Hood).

pyamg builds the hierarchy; what is written here is what it does not do: pad the unknowns
into node blocks, swap the finest level's matrix without a rebuild, and keep the smoothers'
options when it does.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from brainbulge.errors import InputError
from brainbulge.solver.linear.sparse_reuse import PatternGather

SMOOTHER_KEYS = ("presmoother", "postsmoother")


def _smoother_setup(name: str):
    from pyamg.relaxation import smoothing

    return getattr(smoothing, f"setup_{name}")


_SMOOTHER_SETUP = {
    name: (lambda lvl, _n=name, **kw: _smoother_setup(_n)(lvl, **kw))
    for name in ("gauss_seidel", "block_gauss_seidel", "jacobi", "block_jacobi")
}


class AMGCycle:
    """One smoothed-aggregation V-cycle as a linear operator, with hierarchy reuse.

    ``slot`` maps the unknowns into the (possibly padded) AMG index space; unused slots
    carry identity rows decoupled from the rest. ``index``: the rows and columns of the
    block ``A`` in the matrices ``M`` given to :meth:`setup` and :meth:`update`,
    ``A = M[index][:, index]`` (None: ``A = M``); the padded finest level is gathered from
    ``M`` in one plan, with no copy of ``A`` on the way (at 1.40M tets ``A`` holds 0.4 GB of
    values and 0.3 GB of plan).
    """

    def __init__(self, n_pad: int, slot: np.ndarray, blocksize: int, B: np.ndarray | None,
                 options: dict, index: np.ndarray | None = None, *, sweeps: int) -> None:
        self.n_pad = n_pad
        self.slot = slot
        self.empty = np.setdiff1d(np.arange(n_pad), slot)
        self.blocksize = blocksize
        self.B = B
        self.options = options
        self.sweeps = sweeps  # symmetric Gauss-Seidel sweeps each side (KrylovOptions)
        self.index = index
        self.ml = None
        # the finest level of each new matrix, padded by a plan made once per pattern
        self._padded_csr = PatternGather(self._pad_block, fill=self._fill)

    def _pad_block(self, M: sp.csr_matrix) -> sp.csr_matrix:
        A = M if self.index is None else M[self.index][:, self.index]
        return self._pad(A)

    def _fill(self, M: sp.spmatrix) -> float:
        """The diagonal of the identity rows at unused slots: the mean diagonal of ``A``."""
        diag = np.abs(M.diagonal())
        if self.index is not None:
            diag = diag[self.index]
        return float(np.mean(diag[diag > 0])) if np.any(diag > 0) else 1.0

    def _pad(self, A: sp.spmatrix) -> sp.csr_matrix:
        """``A`` moved to its slots, with zero diagonal entries at the unused ones (the
        padding plan fills them with :meth:`_fill`)."""
        coo = A.tocoo()
        rows = np.concatenate([self.slot[coo.row], self.empty])
        cols = np.concatenate([self.slot[coo.col], self.empty])
        vals = np.concatenate([coo.data, np.zeros(len(self.empty), dtype=coo.data.dtype)])
        Ap = sp.csr_matrix((vals, (rows, cols)), shape=(self.n_pad, self.n_pad))
        Ap.sum_duplicates()
        Ap.sort_indices()
        return Ap

    def padded(self, M: sp.spmatrix) -> sp.spmatrix:
        """``A`` in the AMG's index space (BSR node blocks when ``blocksize > 1``)."""
        Ap = self._padded_csr(M)
        if self.blocksize > 1:
            return Ap.tobsr(blocksize=(self.blocksize, self.blocksize))
        return Ap

    def _options(self) -> dict:
        opts = dict(
            strength=("symmetric", {"theta": 0.0}),
            smooth=("jacobi", {"omega": 4.0 / 3.0}),
            improve_candidates=None,
            max_coarse=500,
            coarse_solver="splu",
        )
        opts.update({k: v for k, v in self.options.items() if k not in SMOOTHER_KEYS})
        return opts

    def _smoothers(self) -> tuple[tuple[str, dict], tuple[str, dict]]:
        """A symmetric Gauss-Seidel sweep (forward, then backward) before and after the
        coarse correction, on every level: the V-cycle stays symmetric.

        One forward sweep before and one backward after is half the work per cycle but does
        not smooth the soft CSF layer (shear modulus 1/10-1/20 of the tissue's) under contact.
        On the 1.40M-tet fine-stage tangent with the contacts' curvature term (1.08M
        unknowns), GMRES iterations (time) to 1e-4, restart 300 (100 where marked):

        ====================================  ===========================================
        one forward / one backward sweep      224 (188 s); restart 100: 5.6e-2 after 200
        one symmetric sweep each side         157 (157 s)
        three symmetric sweeps each side      101 (171 s)
        three on the finest level only        131 (164 s), restart 100
        three extra over the CSF rows only    139 (130 s), restart 100; eight: 167
        ====================================  ===========================================
        """
        sweeps = ("gauss_seidel", {"sweep": "symmetric", "iterations": self.sweeps})
        pre = self.options.get("presmoother", sweeps)
        post = self.options.get("postsmoother", sweeps)
        for name, _ in (pre, post):
            if name not in _SMOOTHER_SETUP:
                raise InputError(f"AMG smoother {name!r} not supported; choose one of "
                                 f"{', '.join(_SMOOTHER_SETUP)}")
        return pre, post

    def setup(self, M: sp.spmatrix) -> None:
        """Aggregate on node blocks (BSR), then smooth and transfer in CSR.

        pyamg's block Gauss-Seidel on BSR was 2x slower per sweep than the scalar one on
        CSR (3x3 blocks, 50k displacement DOFs), for about the same Krylov iterations.

        One copy of each operator is kept: the finest level's matrix is the padding plan's
        (which :meth:`update` replaces; its index arrays are the plan's), and the
        restriction is the transpose of the prolongation (``R = P^T``, a view of ``P``).
        At 495k tets they had held 46 MB of finest-level indices and a 71 MB copy of ``P``.
        A hierarchy made before is dropped first, not kept while the new one is built (at
        1.40M tets the displacement hierarchy holds ~1 GB; a refresh had held two).
        """
        import pyamg
        from pyamg.relaxation.smoothing import change_smoothers

        self.ml = None
        ml = pyamg.smoothed_aggregation_solver(self.padded(M), B=self.B, **self._options())
        for i, lvl in enumerate(ml.levels):  # CSR products in the cycle
            lvl.A = sp.csr_matrix(lvl.A) if i else None  # (the finest's BSR freed first)
            if hasattr(lvl, "P"):
                lvl.P = sp.csr_matrix(lvl.P)
                lvl.R = lvl.P.T  # symmetric A: pyamg's R is P^T too
        ml.levels[0].A = self._padded_csr(M)
        pre, post = self._smoothers()
        change_smoothers(ml, pre, post)
        self.ml = ml

    def update(self, M: sp.spmatrix) -> None:
        """Keep the hierarchy, smooth with the new matrix on the finest level."""
        lvl = self.ml.levels[0]
        lvl.A = self._padded_csr(M)
        if len(self.ml.levels) == 1:
            return
        # not ml.change_solve_matrix: it rebuilds the smoothers without their options
        # (one forward sweep instead of the symmetric ones)
        (pre, pre_kw), (post, post_kw) = self._smoothers()
        lvl.presmoother = _SMOOTHER_SETUP[pre](lvl, **pre_kw)
        lvl.postsmoother = _SMOOTHER_SETUP[post](lvl, **post_kw)

    def __call__(self, r: np.ndarray) -> np.ndarray:
        ml = self.ml
        b = np.zeros(self.n_pad)
        b[self.slot] = r
        if len(ml.levels) == 1:
            return ml.coarse_solver(ml.levels[0].A, b)[self.slot]
        y = np.zeros(self.n_pad)
        # one V-cycle from zero (pyamg's solve() would also form the final residual)
        ml._MultilevelSolver__solve(0, y, b, "V")
        return y[self.slot]

    def describe(self) -> str:
        ml = self.ml
        return f"{len(ml.levels)} levels, operator complexity {ml.operator_complexity():.2f}"

    def release(self) -> None:
        """Drop the hierarchy and the padding plan (the next ``setup`` makes them again)."""
        self.ml = None
        self._padded_csr = PatternGather(self._pad_block, fill=self._fill)


class HierarchicalTwoLevel:
    """One symmetric two-level cycle for a hierarchical P2 displacement block (Taylor-Hood).

    The P2 space splits into its P1 part (the vertex hat functions, whose block ``A_11`` is
    the P1 stiffness) and the edge functions, whose block is well conditioned after
    diagonal scaling, uniformly in ``h`` (the two-level hierarchical basis method: Bank,
    Dupont and Yserentant 1988; Axelsson and Vassilevski). So a Gauss-Seidel sweep over the
    whole block, the P1 AMG V-cycle on the vertex DOFs and a backward sweep make a
    symmetric cycle::

        x  = GS_forward(A, r)
        x += I_1 AMG_11(r - A x)|_1
        x  = GS_backward(A, r) from x

    Written here because pyamg's aggregation needs a nonzero near-nullspace on every node,
    and the rigid motions vanish on the hierarchical edge functions.
    """

    def __init__(self, index: np.ndarray, amg: AMGCycle) -> None:
        self.index = index  # the P2 block's rows and columns in the matrices given
        self.amg = amg  # on the block's P1 rows (its ``index``)
        self.A: sp.csr_matrix | None = None
        self._block = PatternGather(self._cut)

    def _cut(self, M: sp.csr_matrix) -> sp.csr_matrix:
        return M[self.index][:, self.index]

    @property
    def ml(self):
        return self.amg.ml

    def setup(self, M: sp.spmatrix) -> None:
        self.A = self._block(M)
        self.amg.setup(self.A)

    def update(self, M: sp.spmatrix) -> None:
        self.A = self._block(M)
        self.amg.update(self.A)

    def __call__(self, r: np.ndarray) -> np.ndarray:
        from pyamg.relaxation.relaxation import gauss_seidel

        A = self.A
        x = np.zeros_like(r)
        gauss_seidel(A, x, r, iterations=1, sweep="forward")
        d = r - A @ x
        lin = self.amg.index
        x[lin] += self.amg(d[lin])
        gauss_seidel(A, x, r, iterations=1, sweep="backward")
        return x

    def describe(self) -> str:
        return f"P1 part: {self.amg.describe()}, Gauss-Seidel on the P2 block"

    def release(self) -> None:
        self.amg.release()
        self.A = None
        self._block = PatternGather(self._cut)

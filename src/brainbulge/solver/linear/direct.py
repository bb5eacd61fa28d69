"""The direct linear solver: MKL PARDISO on the exported tangent (:class:`PardisoSolver`).

NGSolve assembles; its own sparse direct solvers were measured 2-3x slower than MKL PARDISO
on the hemidisk, so the tangent is exported to SciPy CSR and factorised by ``pypardiso``.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from brainbulge.errors import ConvergenceError

log = logging.getLogger(__name__)


@dataclass
class DirectStats:
    """A direct solver iterates not (no ``iterations``); it counts its matrices solved by the
    LU fallback."""

    iterations: list[int] = field(default_factory=list)
    lu_solves: int = 0


class PardisoSolver:
    """MKL PARDISO in symmetric-indefinite mode on the upper triangle of the tangent, with
    unsymmetric LU as the fallback.

    Measured on the hemidisk (8k DOFs): factorisation 0.03 s against 0.08 s in unsymmetric
    mode. Its pivot perturbation leaves a relative residual of ~1e-7, so the solution is
    refined against the full matrix until ``|K x - r| <= 1e-10 |r|``. Some contact saddle
    points defeat the symmetric mode (111k-tet brain, ~3,400 active contact rows: relative
    residual 3e-2 after refinement, with or without weighted matching); unsymmetric LU with
    partial pivoting solves them to 1e-16 in 1.7x the time, so it takes over when the
    symmetric result misses 1e-6: for that matrix, and for the rest of the run after
    ``LU_AFTER`` such matrices in a row (a single miss, e.g. at the extrapolated first state
    of a hemidisk load step with the rim-refined mesh, 1.4e-2, does not make the run 2x
    slower).
    """

    LU_AFTER = 2

    def __init__(self, symmetric=None, general=None) -> None:
        """``symmetric`` and ``general``: the two factorisations, by default
        ``pattern_reusing_pardiso(-2)`` and ``(11)`` (any object with their methods)."""
        self.symmetric = symmetric or pattern_reusing_pardiso(mtype=-2)
        self.general = general or pattern_reusing_pardiso(mtype=11)
        self._lu_only = False  # after LU_AFTER failures of the symmetric mode in a row
        self._misses = 0  # symmetric failures in a row
        self.stats = DirectStats()

    @property
    def lu_only(self) -> bool:
        """Whether the symmetric mode is given up for the rest of the run."""
        return self._lu_only

    @property
    def lu_solves(self) -> int:
        """Matrices solved by the LU fallback."""
        return self.stats.lu_solves

    def solve(self, K: sp.csr_matrix, r: np.ndarray, rtol: float | None = None,
              x0: np.ndarray | None = None) -> np.ndarray:
        """``x`` to the refinement's ``1e-10`` relative residual (``rtol`` and ``x0`` do not
        apply to a direct solve)."""
        norm_r = max(float(np.linalg.norm(r)), 1e-300)
        residual = np.inf
        if not self._lu_only:
            x, residual = _refined(self.symmetric, sp.triu(K, format="csr"), K, r, norm_r)
            self._misses = 0 if residual <= 1e-6 else self._misses + 1
            if self._misses:
                self._lu_only = self._misses >= self.LU_AFTER
                log.debug("PARDISO symmetric mode: relative residual %.1e; unsymmetric LU "
                          "%s", residual, "from now on" if self._lu_only else "for this one")
        if not residual <= 1e-6:  # also NaN
            self.stats.lu_solves += 1
            x, residual = _refined(self.general, K, K, r, norm_r)
        if not residual <= 1e-6:
            raise ConvergenceError(
                f"the direct solver lost accuracy (relative residual {residual:.1e}); the "
                "matrix is near singular: check the boundary conditions and the mesh"
            )
        return _checked(x)

    def new_load_step(self) -> None:
        """Nothing to renew."""

    def release(self) -> None:
        """Free PARDISO's memory, the symbolic analysis too (a later solve redoes it)."""
        for solver in (self.symmetric, self.general):
            solver.free_memory(everything=True)
            solver.forget_analysis()


def _refined(solver, A: sp.csr_matrix, K: sp.csr_matrix, r: np.ndarray, norm_r: float
             ) -> tuple[np.ndarray, float]:
    """Factorise ``A`` (``K`` or its upper triangle), solve, refine against ``K`` (3 steps at
    most); return ``x`` and ``|r - K x| / |r|``.

    A numeric factorisation on a reused symbolic analysis keeps the analysis' scaling and
    weighted matching, which PARDISO computes from the values of the matrix analysed then
    (Intel's iparm 11 and 13): when the values have moved far, that solve can miss (2D
    fold at alpha 80 / beta 30: 4e-3 with the stale analysis, 1e-10 with a fresh one), so a
    miss is retried once with a fresh analysis before it counts as one."""
    A = solver.on_pattern(A)
    while True:
        reused = solver.analysed
        solver.factorize(A)
        x = solver.solve(A, r)
        for _ in range(3):
            defect = r - K @ x
            if not np.all(np.isfinite(defect)) or np.linalg.norm(defect) <= 1e-10 * norm_r:
                break
            x = x + solver.solve(A, defect)
        solver.free_memory()  # the factors; the symbolic analysis is kept for the next tangent
        residual = float(np.linalg.norm(r - K @ x) / norm_r)
        if residual <= 1e-6 or not reused:
            return x, residual
        solver.forget_analysis()
        solver.reanalyses += 1


def pattern_reusing_pardiso(mtype: int):
    """A ``pypardiso`` solver that redoes PARDISO's symbolic analysis (fill-reducing ordering,
    phase 11) only when a matrix brings new nonzero positions, and otherwise factorises
    numerically (phase 22). Matrices are put on the union of the sparsity patterns seen so
    far and the diagonal (:meth:`on_pattern`; stored zeros where one has no entry): Newton's
    tangents differ
    in pattern only by the contact active set, so the union settles after a few iterations.
    Measured on the 8k-DOF hemidisk tangent: 20 ms -> 5 ms per factorisation. (pypardiso
    always runs phases 11 and 22 together; it has no switch for this.)"""
    _point_pypardiso_to_mkl()
    import pypardiso

    class PatternReusingPardiso(pypardiso.PyPardisoSolver):
        _union: sp.csr_matrix | None = None  # the union pattern (values unused)
        _keys: np.ndarray | None = None  # its entries as row * n + col, ascending
        analysed = False  # whether the union pattern's symbolic analysis is current
        analyses = 0  # symbolic analyses (PARDISO phase 12) done
        reanalyses = 0  # of them, fresh ones after a miss on a reused one (see _refined)

        def forget_analysis(self) -> None:
            """The next factorisation analyses the pattern anew."""
            self.analysed = False

        def on_pattern(self, A: sp.csr_matrix) -> sp.csr_matrix:
            """``A`` on the union pattern, which grows (and is analysed anew) if needed."""
            A.sort_indices()
            keys = _csr_keys(A)
            U = self._union
            if U is not None and U.shape == A.shape:
                idx = np.minimum(np.searchsorted(self._keys, keys), len(self._keys) - 1)
                if np.array_equal(self._keys[idx], keys):
                    data = np.zeros(U.nnz)
                    data[idx] = A.data
                    return sp.csr_matrix((data, U.indices, U.indptr), shape=A.shape)
                keys = _union(self._keys, keys)
            n = A.shape[1]
            # the whole diagonal, stored zeros included: a CSR sum drops the zero pressure
            # diagonal, which the symmetric-indefinite factorisation needs to pivot on
            keys = _union(keys, np.arange(min(A.shape), dtype=np.int64) * (n + 1))
            rows, cols = np.divmod(keys, n)
            self._union = sp.csr_matrix((np.ones(len(keys)), (rows, cols)), shape=A.shape)
            self._keys = keys
            self.analysed = False
            return self.on_pattern(A)

        def factorize(self, A: sp.csr_matrix) -> None:
            """Factorise ``A``, a matrix returned by :meth:`on_pattern`."""
            self._check_A(A)
            if not self.analysed:
                self.free_memory(everything=True)
                self.analyses += 1
            self.factorized_A = (A.copy() if A.nnz <= self.size_limit_storage
                                 else self._hash_csr_matrix(A))  # as pypardiso does
            self.set_phase(22 if self.analysed else 12)
            self._call_pardiso(A, np.zeros((A.shape[0], 1)))
            self.analysed = True

    solver = PatternReusingPardiso(mtype=mtype)
    if mtype == -2:
        # symmetric indefinite: scaling and weighted matching (1-based iparm 11 and 13; off by
        # default in this mode) with METIS ordering and 1e-8 pivot perturbation. Without
        # them the hemidisk's saddle point (pressure block, contact rows) at h = 0.04 /
        # corner 0.004 left 99 perturbed pivots and a relative residual of 1e2, and every
        # tangent went to the 2x slower LU; with them 0 perturbed pivots and 1e-10.
        # 1x1 diagonal pivots within the supernodes (iparm 21 = 0), not Bunch-Kaufman's 1x1
        # and 2x2 (MKL's default, 1); the matching's 2x2 blocks still pair a zero diagonal
        # (Taylor-Hood's pressures) with its partner. MINI's condensed pressure block -C
        # (C = B_b A_bb^-1 B_b^T) vanishes on the constants of each connected piece of a
        # pressure zone, so each small island of a zone (a tet or two of CSF inside another
        # tissue) brings an exactly singular pivot. A 1x1 pivot is perturbed and the
        # refinement repairs it; Bunch-Kaufman folded one into a near-singular 2x2 pivot on
        # the brain with fitted tissue interfaces (an island of two tets sharing a vertex):
        # relative residual 1e2 after refinement although the scaled tangent's condition
        # number is 5e3, as on the staircase mesh, and LU took over. 1x1 pivots solve every
        # tangent measured (brain, hemidisk, MINI and Taylor-Hood) to 1e-10 or better.
        for i, value in {1: 1, 2: 2, 10: 8, 11: 1, 13: 1, 21: 0}.items():
            solver.set_iparm(i, value)
    return solver


def _union(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Sorted union of two integer arrays (``np.union1d`` hashes: ~20x slower here)."""
    keys = np.concatenate([a, b])
    keys.sort()
    return keys[np.r_[True, keys[1:] != keys[:-1]]]


def _csr_keys(A: sp.csr_matrix) -> np.ndarray:
    """The entries of a CSR matrix with sorted indices as ascending ``row * n + col``."""
    rows = np.repeat(np.arange(A.shape[0], dtype=np.int64), np.diff(A.indptr))
    return rows * A.shape[1] + A.indices


def _point_pypardiso_to_mkl() -> None:
    """Tell pypardiso where MKL's runtime is (``PYPARDISO_MKL_RT``) when it sits in
    ``sys.prefix/lib``, as pip's ``mkl`` wheel puts it: otherwise pypardiso searches the whole
    environment recursively at import, ~5 s per process (measured: a third of a hemidisk run)."""
    import os
    import sys
    from pathlib import Path

    if "PYPARDISO_MKL_RT" in os.environ:
        return
    found = sorted(Path(sys.prefix, "lib").glob("libmkl_rt.so*"), key=lambda p: len(p.name))
    if found:
        os.environ["PYPARDISO_MKL_RT"] = str(found[0])


def _checked(x: np.ndarray) -> np.ndarray:
    if not np.all(np.isfinite(x)):
        raise ConvergenceError(
            "the tangent matrix is singular (non-finite linear solve); check that rigid-body "
            "motions are suppressed and every region has a material"
        )
    return x

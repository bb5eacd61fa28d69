"""Linear solves behind one small interface, :class:`LinearSolver`: the direct solver
(:mod:`.direct`, MKL PARDISO) and block-preconditioned GMRES (:mod:`.krylov`, its AMG cycles
in :mod:`.amg`); both read the tangent through the sparsity-pattern plans of
:mod:`.sparse_reuse`."""

from __future__ import annotations

from typing import TYPE_CHECKING, Protocol, runtime_checkable

import numpy as np
import scipy.sparse as sp

from brainbulge.errors import InputError

if TYPE_CHECKING:
    from brainbulge.solver.options import KrylovOptions


class SolveStats(Protocol):
    """What a linear solver counts: its iterations per solve (none for a direct solve)."""

    iterations: list[int]


@runtime_checkable
class LinearSolver(Protocol):
    """What Newton asks of a linear solver (:class:`NewtonSolver`)."""

    stats: SolveStats

    def solve(self, K: sp.csr_matrix, r: np.ndarray, rtol: float | None = None,
              x0: np.ndarray | None = None) -> np.ndarray:
        """``x`` with ``K x = r`` for one tangent ``K`` (a fresh one each Newton iteration):
        to the relative residual ``rtol`` (an iterative solver; None: its default) from the
        guess ``x0``; ConvergenceError when it cannot."""
        ...

    def new_load_step(self) -> None:
        """A Newton solve at a new load starts (a preconditioner may renew a part)."""
        ...

    def release(self) -> None:
        """Free the work memory; a later solve rebuilds it."""
        ...


def make_linear_solver(name: str = "pardiso", form=None, krylov: KrylovOptions | None = None
                       ) -> LinearSolver:
    """``"pardiso"`` (direct, default) or ``"krylov"`` (GMRES preconditioned by blocks
    built from ``form``'s spaces; ``krylov``: its budget, restart and AMG refresh)."""
    if name == "pardiso":
        from brainbulge.solver.linear.direct import PardisoSolver

        return PardisoSolver()
    if name == "krylov":
        from brainbulge.solver.linear.krylov import BlockKrylovSolver

        return BlockKrylovSolver.from_form(form, krylov)
    raise InputError(f"unknown linear solver {name!r}; choose 'pardiso' or 'krylov'")

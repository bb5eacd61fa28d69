"""The active-set step's saddle point, in the form the linear solvers take.

With the active contact rows ``B`` (``B_i = A_i n_i^T P_i``, :mod:`.points`) Newton's system
is ``[[K, -B^T], [-B, 0]] [dx, dlam] = [b, c]`` (``c = -A g`` of the active points). Each
contact point on a node of its own (P1: MINI) is eliminated at its node
(:class:`NodalElimination`); rows that share DOFs (P2 edge midpoints: Taylor-Hood) are
solved in augmented form (:func:`augmented`).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from brainbulge.solver.linear.sparse_reuse import PatternProject


def coo_sum(
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


def augmented(K: sp.csr_matrix, b: np.ndarray, B: sp.csr_matrix, c: np.ndarray,
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

    The projected matrix is ``K`` itself, changed in place at the constrained rows and
    columns (:class:`PatternProject`): from :meth:`system` until :meth:`recover`, or until
    the next elimination made with the same ``project``, ``K`` holds the projected values.
    """

    def __init__(self, K: sp.csr_matrix, B: sp.csr_matrix, c: np.ndarray,
                 is_u: np.ndarray, project: PatternProject | None = None) -> None:
        self._project = project or PatternProject()
        self._project.restore()  # K's own values (a failed solve left them projected)
        self.K = K
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
        rhs = self.project(b - K @ (N @ self.gbar))
        # on K's pattern (Pi K Pi + d P lies in the node blocks K couples), so that the
        # Krylov solver's block plans stay valid whatever the active set; in place
        return self._project(K, N, self.d), rhs

    def recover(self, y: np.ndarray) -> np.ndarray:
        """``[dx, dlam]`` from the solution ``y`` of :meth:`system` (``K`` back to its own
        values)."""
        self._project.restore()
        dx = self.project(y) + self.N @ self.gbar
        dlam = (self.N.T @ (self.K @ dx - self._b)) / self.beta
        return np.concatenate([dx, dlam])

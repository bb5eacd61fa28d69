"""The primal-dual active set of the contact points, and its part of a Newton step.

Each contact point ``i`` (:mod:`.points`) is active when ``lambda_i - c g_i >= 0`` (``c =
mu_max / h`` weighs gap against pressure) and must then stay on the skull, ``g_i = 0``; an
inactive point carries no pressure, ``lambda_i = 0``. Newton's step for ``(dx, dlam)``, with
``x <- x - s dx`` and ``lambda <- lambda - s dlam``, sets ``dlam_I = lambda_I`` on the inactive
points and solves for the active ones::

    [[K, -B_A^T], [-B_A, 0]] [dx, dlam_A] = [R + B_I^T lambda_I, -A g_A]

(:mod:`.saddle`). The residual measured by Newton includes the complementarity
``C_i = lambda_i - max(0, lambda_i - c g_i)`` weighted to a volume.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from brainbulge.solver.contact.points import PointContact
from brainbulge.solver.contact.saddle import NodalElimination, augmented, coo_sum
from brainbulge.solver.linear.sparse_reuse import PatternProject


class ActiveSet:
    """The contact points of a form whose DOFs are ``free`` (of ``ndof``) and their active
    set.

    A point on a clamped edge (no free DOF) does not move: it takes no constraint.
    """

    def __init__(self, form, free: np.ndarray, ndof: int) -> None:
        self.contacts: list[PointContact] = list(form.point_contacts)
        self.h = form.h
        #: weight of gap against pressure in the active set [stress/length]
        self.c_active = form.mu_max / form.h
        free_mask = np.zeros(ndof)
        free_mask[free] = 1.0
        #: per contact, the points that move (have a free DOF)
        self.moving = [
            np.asarray((abs(pc.P) @ free_mask).reshape(pc.n_points, -1).sum(axis=1) > 0)
            for pc in self.contacts
        ]
        #: per contact, ``A C / c`` of the moving points at the last residual [volume]
        self.complementarity: list[np.ndarray] = []
        #: per contact, the active points of the last Newton step
        self.last_active: list[np.ndarray] = []

    def __bool__(self) -> bool:
        return bool(self.contacts)

    def add_forces(self, x: np.ndarray, R: np.ndarray) -> None:
        """``R -= B^T lambda`` at the state ``x`` (full DOF numbering), and the moving
        points' complementarity residuals."""
        self.complementarity = []
        for pc, moving in zip(self.contacts, self.moving, strict=True):
            pc.update(x)
            pc.add_forces(R)
            self.complementarity.append(pc.complementarity(self.c_active)[moving])

    def curvatures(self, x: np.ndarray) -> list[sp.csr_matrix]:
        """``-P^T (A lambda grad^2 g) P`` of each contact at ``x``: the tangent's term from
        the skull's curvature (the points move to ``x``)."""
        out = []
        for pc in self.contacts:
            pc.update(x)
            out.append(-pc.curvature())
        return out

    def max_penetration(self) -> float:
        """Largest penetration ``max(-g, 0)`` of the moving points at the form's state
        [length] (a clamped point may overlap the skull at rest by the surface's geometric
        error: it is not in contact)."""
        return max((pc.max_penetration(moving)
                    for pc, moving in zip(self.contacts, self.moving, strict=True)),
                   default=0.0)

    def linearize(self, rhs: np.ndarray) -> ContactStep:
        """Fix the active set of this Newton step and add ``B_I^T lambda_I`` to ``rhs``
        (full numbering, in place)."""
        step = ContactStep()
        self.last_active = []
        for pc, moving in zip(self.contacts, self.moving, strict=True):
            act = pc.active(self.c_active) & moving
            self.last_active.append(act)
            pc.add_forces(rhs, -np.where(act, 0.0, pc.lam))  # + B_I^T lam_I
            step.dlams.append(pc.lam.copy())  # inactive: to zero
            pts = np.flatnonzero(moving)
            step.rows.append((pc, pts, act[pts]))
        return step


@dataclass
class ContactStep:
    """The constraint part of one Newton step: per contact its moving points and which of
    them are active, and the multiplier steps ``dlam`` (``lambda`` on inactive points)."""

    rows: list[tuple[PointContact, np.ndarray, np.ndarray]] = field(default_factory=list)
    dlams: list[np.ndarray] = field(default_factory=list)
    elimination: NodalElimination | None = None
    #: per contact, the points whose ``dlam`` the linear system gives, in its row order
    solved: list[np.ndarray] = field(default_factory=list)

    def system(self, K: sp.csr_matrix, b: np.ndarray, free: np.ndarray, is_u: np.ndarray,
               project: PatternProject) -> tuple[sp.csr_matrix, np.ndarray]:
        """The linear system of the step on the free DOFs (``K``, ``b``: the tangent and
        right-hand side without contact)."""
        if not self.rows:
            return K, b
        rows = self.rows
        B_all = sp.vstack([pc.B(pts) for pc, pts, _ in rows]).tocsr()[:, free]
        on = np.concatenate([o for _, _, o in rows])
        B = B_all[on]
        c = np.concatenate([-pc.weights[pts[on]] * pc.g[pts[on]] for pc, pts, on in rows])
        n = K.shape[0]
        if NodalElimination.applies(B_all):  # each point's row on a node of its own
            self.solved = [pts[on] for _, pts, on in rows]  # (none active: empty)
            if B.shape[0]:
                self.elimination = NodalElimination(K, B, c, is_u, project=project)
                K, b = self.elimination.system(b)
            return K, b
        if B.shape[0]:
            K, b = augmented(K, b, B, c, is_u)
        # a row per moving point: -B_i dx = c_i if active, -s dlam_i = -s lam_i if not; the
        # size and sparsity do not change with the active set (the direct solver then redoes
        # only the numeric factorisation)
        self.solved = [pts for _, pts, _ in rows]
        B_all = sp.diags(on.astype(float)) @ B_all
        lam = np.concatenate([pc.lam[pts] for pc, pts, _ in rows])
        s_idle = float(np.mean(np.abs(K.diagonal()[: len(is_u)][is_u])))
        D = sp.diags(np.where(on, 0.0, -s_idle))
        c_all = -s_idle * lam
        c_all[on] = c
        nB = len(on)
        K = coo_sum(
            [K.tocoo(), (-B_all).T.tocoo(), (-B_all).tocoo(), D.tocoo()],
            (n + nB, n + nB),
            offsets=[(0, 0), (0, n), (n, 0), (n, n)],
            diagonal=True,
        )
        return K, np.concatenate([b, c_all])

    def recover(self, sol: np.ndarray, n_free: int) -> tuple[np.ndarray, list[np.ndarray]]:
        """``dx`` on the free DOFs and each contact's ``dlam`` from the system's solution."""
        if self.elimination is not None:
            sol = self.elimination.recover(sol)
        k = n_free
        for pts, dlam in zip(self.solved, self.dlams, strict=True):
            dlam[pts] = sol[k : k + len(pts)]
            k += len(pts)
        return sol[:n_free], self.dlams

"""The discrete state a solve changes, in one place: ``x = (u, p)``, the contact pressures
``lambda`` and the load factor ``t`` of a :class:`~brainbulge.solver.mixed.MixedForm`.

Every way of making Newton converge tries something and goes back when it fails (a line
search step, a load step, a start state, a rezoning); each does it through
:meth:`State.snapshot` / :meth:`State.restore`, and starts afresh through
:meth:`State.reset` (``u = 0``, ``p = 0``, ``lambda = 0`` at ``t = 0``, the undeformed body).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import ngsolve as ngs
import numpy as np

if TYPE_CHECKING:
    from brainbulge.solver.mixed import MixedForm


@dataclass(frozen=True)
class Snapshot:
    """A copy of a :class:`State`: ``x`` [length, kPa], ``lam`` per contact [kPa], load ``t``
    [-]."""

    x: ngs.BaseVector
    lam: tuple[np.ndarray, ...]
    load: float


class State:
    """A view of ``form``'s unknowns: ``x`` is the form's own vector (changed in place), the
    multipliers are its contacts' ``lambda``, ``load`` its load parameter."""

    def __init__(self, form: MixedForm) -> None:
        self.form = form

    @property
    def x(self) -> ngs.BaseVector:
        return self.form.gfu.vec

    @property
    def load(self) -> float:
        return float(self.form.load.Get())

    @property
    def multipliers(self) -> tuple[np.ndarray, ...]:
        """The contact pressures ``lambda`` [kPa], the arrays themselves (not copies)."""
        return tuple(pc.lam for pc in self.form.point_contacts)

    def set_multipliers(self, lam: tuple[np.ndarray, ...] | list[np.ndarray]) -> None:
        """Every contact's ``lambda`` from ``lam`` (taken over, not copied)."""
        for pc, v in zip(self.form.point_contacts, lam, strict=True):
            pc.lam = v

    def snapshot(self) -> Snapshot:
        """A copy of ``x``, ``lambda`` and ``t``."""
        x = self.x.CreateVector()
        x.data = self.x
        return Snapshot(x, tuple(pc.lam.copy() for pc in self.form.point_contacts),
                        self.load)

    def restore(self, snap: Snapshot, multipliers: bool = True) -> None:
        """Back to ``snap``: ``x`` and ``t`` (the prescribed displacements are ``x``'s own
        values), and with ``multipliers`` the contact pressures."""
        self.x.data = snap.x
        if multipliers:
            self.set_multipliers([v.copy() for v in snap.lam])
        self.form.load.Set(snap.load)

    def reset(self) -> None:
        """The undeformed body at ``t = 0``: ``x = 0``, ``lambda = 0``."""
        self.x[:] = 0.0
        self.set_multipliers([np.zeros_like(pc.lam) for pc in self.form.point_contacts])
        self.form.set_load(0.0)

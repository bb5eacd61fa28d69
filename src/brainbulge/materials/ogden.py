"""Incompressible Ogden solid (docs/model.md section 2), the family Mooney-Rivlin belongs to.

Isochoric energy [kPa] in the principal isochoric stretches ``lbar_k``::

    psibar = sum_i c_i/alpha_i (lbar1^a_i + lbar2^a_i + lbar3^a_i - 3),
    mu = 1/2 sum_i c_i alpha_i.

Mooney-Rivlin ``(c1, c2)`` is ``c = (c1, -c2)``, ``alpha = (2, -2)``.

The principal values ``lbar_k^2`` of ``Cbar`` are written in closed form (trigonometric
solution of the characteristic cubic) so that NGSolve can differentiate the energy
symbolically. That formula has a removable singularity where two eigenvalues coincide (the
reference state); a tiny regularisation ``eps`` of the deviatoric norm keeps it smooth, with an
energy error of order ``eps^2``. No library offers a differentiable eigenvalue energy for
NGSolve's symbolic forms, hence this hand-written piece.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import ngsolve as ngs
import numpy as np

from brainbulge.errors import InputError
from brainbulge.materials.base import check_finite


@dataclass(frozen=True)
class Ogden:
    """Ogden coefficients ``c`` [kPa] and exponents ``alpha`` [-]."""

    c: tuple[float, ...]
    alpha: tuple[float, ...]
    name: str = "ogden"
    eps: float = field(default=1e-6, repr=False)

    def __post_init__(self) -> None:
        if len(self.c) != len(self.alpha) or not self.c:
            raise InputError(f"{self.name}: give as many coefficients c as exponents alpha")
        check_finite(self.name, *self.c, *self.alpha)
        if any(a == 0 for a in self.alpha):
            raise InputError(f"{self.name}: an Ogden exponent alpha_i is 0; use non-zero values")
        if self.shear_modulus <= 0:
            raise InputError(
                f"{self.name}: shear modulus 1/2 sum c_i alpha_i = {self.shear_modulus:g} kPa "
                "must be positive"
            )

    @property
    def shear_modulus(self) -> float:
        return 0.5 * sum(ci * ai for ci, ai in zip(self.c, self.alpha, strict=True))

    def scaled(self, factor: float) -> Ogden:
        """The same solid ``factor`` times as stiff (every ``c_i`` scaled)."""
        return dataclasses.replace(self, c=tuple(factor * ci for ci in self.c))

    def psi_iso(self, F: ngs.CoefficientFunction) -> ngs.CoefficientFunction:
        J = ngs.Det(F)
        Cbar = J ** (-2 / 3) * (F.trans * F)
        ev = _sym3_eigenvalues(Cbar, self.eps)
        psi = 0
        for ci, ai in zip(self.c, self.alpha, strict=True):
            psi = psi + ci / ai * (sum(e ** (ai / 2) for e in ev) - 3)
        return psi

    def psi_iso_numpy(self, F: np.ndarray) -> np.ndarray:
        F = np.asarray(F, dtype=float)
        J = np.linalg.det(F)
        Cbar = J[..., None, None] ** (-2 / 3) * (np.swapaxes(F, -1, -2) @ F)
        ev = np.linalg.eigvalsh(Cbar)
        return sum(
            ci / ai * ((ev ** (ai / 2)).sum(axis=-1) - 3)
            for ci, ai in zip(self.c, self.alpha, strict=True)
        )


def _sym3_eigenvalues(A: ngs.CoefficientFunction, eps: float) -> list[ngs.CoefficientFunction]:
    """Eigenvalues of a symmetric 3x3 CF (trigonometric Cardano), regularised by ``eps``."""
    q = ngs.Trace(A) / 3
    D = A - q * ngs.Id(3)
    p = ngs.sqrt(ngs.InnerProduct(D, D) / 6 + eps**2)
    r = ngs.Det(D) / (2 * p**3)
    r = ngs.IfPos(r - 1, 1, ngs.IfPos(-1 - r, -1, r))
    phi = ngs.acos(r) / 3
    return [q + 2 * p * ngs.cos(phi + 2 * math.pi * k / 3) for k in range(3)]

"""Incompressible Mooney-Rivlin solid (docs/model.md section 2), neo-Hookean when ``c2 = 0``.

Isochoric energy [kPa]::

    psibar = c1/2 (I1bar - 3) + c2/2 (I2bar - 3),     mu = c1 + c2

(the usual ``C10 = c1/2``, ``C01 = c2/2``). With the multiplier term ``p (J - Js)`` its
Kirchhoff stress is, in closed form::

    tau = (c1 + I1bar c2) bbar - c2 bbar^2 - (I1bar c1/3 + 2 I2bar c2/3 - J p) I

``p`` is tension-positive here (energy ``+p (J - Js)``); users see the pressure
``-p`` (compression positive), see :func:`brainbulge.results.measures.fields.pressure`.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import ngsolve as ngs
import numpy as np

from brainbulge.errors import InputError
from brainbulge.materials.base import check_finite
from brainbulge.materials.kinematics import isochoric_invariants


@dataclass(frozen=True)
class MooneyRivlin:
    """Mooney-Rivlin coefficients ``c1``, ``c2`` [kPa]."""

    c1: float
    c2: float
    name: str = "mooney-rivlin"

    def __post_init__(self) -> None:
        check_finite(self.name, self.c1, self.c2)
        if self.c1 + self.c2 <= 0:
            raise InputError(
                f"{self.name}: c1 + c2 = {self.c1 + self.c2:g} kPa must be positive "
                "(it is the shear modulus); give positive coefficients"
            )

    @property
    def shear_modulus(self) -> float:
        """``mu = c1 + c2`` [kPa]."""
        return self.c1 + self.c2

    def scaled(self, factor: float) -> MooneyRivlin:
        """The same solid ``factor`` times as stiff (``c1``, ``c2`` scaled)."""
        return dataclasses.replace(self, c1=factor * self.c1, c2=factor * self.c2)

    def psi_iso(self, F: ngs.CoefficientFunction) -> ngs.CoefficientFunction:
        return mooney_rivlin_psi(F, self.c1, self.c2)

    def psi_iso_numpy(self, F: np.ndarray) -> np.ndarray:
        I1bar, I2bar, _ = isochoric_invariants_numpy(F)
        return self.c1 / 2 * (I1bar - 3) + self.c2 / 2 * (I2bar - 3)

    def kirchhoff_stress(self, F: np.ndarray, p: np.ndarray | float) -> np.ndarray:
        """Closed-form ``tau(F, p)`` [kPa] for ``F`` of shape ``(..., 3, 3)``."""
        F = np.asarray(F, dtype=float)
        J = np.linalg.det(F)
        b = F @ np.swapaxes(F, -1, -2)
        bbar = J[..., None, None] ** (-2 / 3) * b
        I1bar = np.trace(bbar, axis1=-2, axis2=-1)
        I2bar = 0.5 * (I1bar**2 - np.einsum("...ij,...ji->...", bbar, bbar))
        eye = np.broadcast_to(np.eye(3), F.shape)
        scal = I1bar * self.c1 / 3 + 2 * I2bar * self.c2 / 3 - J * np.asarray(p)
        return (
            (self.c1 + I1bar * self.c2)[..., None, None] * bbar
            - self.c2 * bbar @ bbar
            - scal[..., None, None] * eye
        )


def mooney_rivlin_psi(
    F: ngs.CoefficientFunction,
    c1: float | ngs.CoefficientFunction,
    c2: float | ngs.CoefficientFunction,
) -> ngs.CoefficientFunction:
    """``psibar = c1/2 (I1bar - 3) + c2/2 (I2bar - 3)`` [kPa]; coefficients may vary in space."""
    I1bar, I2bar, _ = isochoric_invariants(F)
    return c1 / 2 * (I1bar - 3) + c2 / 2 * (I2bar - 3)


def neo_hookean(c1: float, name: str = "neo-hookean") -> MooneyRivlin:
    """Neo-Hookean solid, ``psibar = c1/2 (I1bar - 3)``, ``mu = c1`` [kPa]."""
    return MooneyRivlin(c1=c1, c2=0.0, name=name)


def isochoric_invariants_numpy(F: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(I1bar, I2bar, J)`` for ``F`` of shape ``(..., 3, 3)``."""
    F = np.asarray(F)
    J = np.linalg.det(F)
    C = np.swapaxes(F, -1, -2) @ F
    I1 = np.trace(C, axis1=-2, axis2=-1)
    I2 = 0.5 * (I1**2 - np.einsum("...ij,...ji->...", C, C))
    return J ** (-2 / 3) * I1, J ** (-4 / 3) * I2, J

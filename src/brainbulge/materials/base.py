"""What every constitutive model provides: an isochoric energy ``psibar(F)``.

The full mixed energy of docs/model.md section 2 is ``psi = psibar(F) + p (J - Js)``; the
multiplier term is added by the solver (:mod:`brainbulge.solver.mixed`), the same for every
material, so a material only knows its isochoric part. Stresses and tangents are obtained by
symbolic differentiation of ``psibar`` (NGSolve ``Variation``): the energy is the single
source of truth.
"""

from __future__ import annotations

import math
from typing import Protocol, runtime_checkable

import ngsolve as ngs
import numpy as np

from brainbulge.errors import InputError


@runtime_checkable
class Material(Protocol):
    """An isochoric hyperelastic energy [kPa = kJ/m^3]."""

    name: str

    @property
    def shear_modulus(self) -> float:
        """Small-strain shear modulus ``mu`` [kPa]."""
        ...

    def scaled(self, factor: float) -> Material:
        """The same solid ``factor`` times as stiff (every modulus scaled) [-]."""
        ...

    def psi_iso(self, F: ngs.CoefficientFunction) -> ngs.CoefficientFunction:
        """Isochoric strain energy density ``psibar(F)`` [kPa] of a 3x3 ``F``."""
        ...

    def psi_iso_numpy(self, F: np.ndarray) -> np.ndarray:
        """The same energy for an array of 3x3 ``F`` (shape ``(..., 3, 3)``) [kPa]."""
        ...


def check_finite(label: str, *values: float) -> None:
    """Reject NaN and infinite parameters with a one-line message."""
    for v in values:
        if not isinstance(v, (int, float)) or not math.isfinite(v):
            raise InputError(f"{label}: parameter {v!r} is not a finite number; give real values")


def kirchhoff_deviator(material: Material, F: np.ndarray, step: float = 1e-6) -> np.ndarray:
    """The deviatoric Kirchhoff stress ``dev tau = dev(dpsibar/dF F^T)`` [kPa] of ``material``
    at deformation gradients ``F`` (n, 3, 3): in closed form where the material has one
    (``kirchhoff_stress(F, p)``), else by central differences of ``psi_iso_numpy`` (relative
    step ``step``). The multiplier adds ``J p I``, which the deviator drops."""
    F = np.asarray(F, dtype=float)
    if hasattr(material, "kirchhoff_stress"):
        tau = material.kirchhoff_stress(F, 0.0)
    else:
        P = np.empty_like(F)
        for i in range(3):
            for j in range(3):
                dF = np.zeros((3, 3))
                dF[i, j] = step
                P[:, i, j] = (material.psi_iso_numpy(F + dF)
                              - material.psi_iso_numpy(F - dF)) / (2 * step)
        tau = P @ np.swapaxes(F, -1, -2)
    trace = np.trace(tau, axis1=-2, axis2=-1) / 3.0
    return tau - trace[..., None, None] * np.eye(3)

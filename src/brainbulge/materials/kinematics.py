"""Kinematics of docs/model.md section 1 as NGSolve coefficient functions.

``F = I + Grad u``; in plane strain (2D meshes) ``F`` is embedded in 3x3 with ``F33 = 1``, so
``J = det F`` is the in-plane area ratio. Isochoric invariants, with ``b = F F^T`` and
``C = F^T F`` sharing their invariants::

    I1 = tr C,  I2 = (tr^2 C - tr C^2)/2,  I1bar = J^(-2/3) I1,  I2bar = J^(-4/3) I2.
"""

from __future__ import annotations

import ngsolve as ngs


def deformation_gradient(u: ngs.CoefficientFunction, dim: int) -> ngs.CoefficientFunction:
    """The 3x3 deformation gradient ``F = I + Grad u`` (plane strain: ``F33 = 1``) [-]."""
    G = ngs.Grad(u)
    if dim == 3:
        return ngs.Id(3) + G
    if dim != 2:
        raise ValueError(f"dimension must be 2 or 3, got {dim}")
    return ngs.CF((1 + G[0, 0], G[0, 1], 0, G[1, 0], 1 + G[1, 1], 0, 0, 0, 1), dims=(3, 3))


def isochoric_invariants(
    F: ngs.CoefficientFunction,
) -> tuple[ngs.CoefficientFunction, ngs.CoefficientFunction, ngs.CoefficientFunction]:
    """``(I1bar, I2bar, J)`` of a 3x3 deformation gradient."""
    C = F.trans * F
    J = ngs.Det(F)
    I1 = ngs.Trace(C)
    I2 = 0.5 * (I1 * I1 - ngs.InnerProduct(C, C))
    return J ** (-2 / 3) * I1, J ** (-4 / 3) * I2, J

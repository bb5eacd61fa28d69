"""The MINI residual and condensed tangent of a Mooney-Rivlin solid, in compiled loops (3D).

NGSolve's ``Variation`` forms the Hessian of the energy by automatic differentiation: about
65 second-order AD evaluations of the energy per integration point (9 + 1 proxy components,
the mixed derivatives by polarisation). That was the largest cost of a Newton iteration
(45 s per tangent at 1.4M tets on two cores). The Hessian of the energy has a closed form,
and a tet's element matrix is a few thousand flops, so it is written out here once and
compiled with Numba (written by hand: no library assembles this element; NGSolve's
bilinear forms with a compiled closed-form Hessian cost as much as its AD, measured).

Energy per unit reference volume (MODEL.md section 2, :mod:`brainbulge.solver.mixed`)::

    W(F, p) = c1/2 (J^(-2/3) I1 - 3) + c2/2 (J^(-4/3) I2 - 3) + p (J - Js)

With ``psi(I1, I2, J)`` and the derivatives ``dI1 = 2 F``, ``dI2 = 2 (I1 F - F C)``,
``dJ = H = cof F`` and ``d2I1[A, B] = 2 A:B``, ``d2I2[A, B] = 2 (2 (F:A)(F:B) + I1 A:B
- A:(B C) - A:(F B^T F) - A:(b B))``, ``d2J[A, B] = ((H:A)(H:B) - A:(H B^T H))/J``,
in index form (``A_ijkl = d2W / dF_ij dF_kl``, ``b = F F^T``, ``C = F^T F``)::

    A_ijkl = 4 psi2 F_ij F_kl + (psiJJ + psiJ/J) H_ij H_kl
           + psi1J (2 F_ij H_kl + 2 H_ij F_kl) + psi2J (dI2_ij H_kl + H_ij dI2_kl)
           - 2 psi2 F_il F_kj - psiJ/J H_il H_kj
           + (2 psi1 + 2 psi2 I1) d_ik d_jl - 2 psi2 (d_ik C_lj + b_ik d_jl)

    psi1 = c1/2 J^(-2/3),  psi2 = c2/2 J^(-4/3),
    psiJ = -c1/3 J^(-5/3) I1 - 2 c2/3 J^(-7/3) I2 + p,
    psi1J = -c1/3 J^(-5/3),  psi2J = -2 c2/3 J^(-7/3),
    psiJJ = 5 c1/9 J^(-8/3) I1 + 14 c2/9 J^(-10/3) I2.

Element matrix over the 4-point rule of order 2 (the rule NGSolve's ``Variation`` uses for
MINI), displacement shape functions ``N_a`` (the 4 barycentric ``lambda_a`` and the bubble
``B = c_B lambda_0 lambda_1 lambda_2 lambda_3``), pressure shape functions ``lambda_c``::

    K_(ai)(bk) = sum_q w_q  dN_a/dX_j  A_ijkl  dN_b/dX_l
    K_(ai)c    = sum_q w_q  H_ij dN_a/dX_j  lambda_c,      K_cd = 0

and the bubble condensed statically: ``S = K_ee - K_eb K_bb^-1 K_be``, with
``E = -K_bb^-1 K_be`` and ``K_bb^-1`` kept for the bubble part of a Newton step
(NGSolve's ``harmonic_extension``, its transpose, and ``inner_solve``). The residual is
``R_(ai) = sum_q w_q P_ij dN_a/dX_j`` and ``R_c = sum_q w_q (J - Js(t)) lambda_c`` with
``P = dW/dF = 2 psi1 F + psi2 dI2 + psiJ H`` (7x faster than NGSolve's compiled ``Apply``
on a 146-tet mesh; a 21k-tet solve's assembly 3.0 -> 2.3 s).
"""

from __future__ import annotations

import logging
import re
import time

import ngsolve as ngs
import numba
import numpy as np
import scipy.sparse as sp

from brainbulge.geometry.ngsolve_arrays import element_vertices, vertex_coordinates
from brainbulge.materials.mooney_rivlin import MooneyRivlin
from brainbulge.solver.fast.element_graph import colour_elements, element_pattern
from brainbulge.solver.threads import available_cores

log = logging.getLogger(__name__)
# Numba's compiler logs every pass at DEBUG: tens of thousands of lines in a run's log
logging.getLogger("numba").setLevel(logging.WARNING)

#: barycentric coordinates of the 4-point rule of order 2 on the tetrahedron (weights 1/4)
_A, _B = 0.5854101966249685, 0.1381966011250105
QUAD_POINTS = np.array([[_A, _B, _B, _B], [_B, _A, _B, _B], [_B, _B, _A, _B], [_B, _B, _B, _A]])


@numba.njit(cache=True, inline="always")
def hessian(F, p, c1, c2, A, H, n=3):  # noqa: ANN001, ANN202 - Numba kernel
    """``A = d2W/dF2`` as a 9x9 matrix (row ``3 i + j``, column ``3 k + l``) and
    ``H = cof F = dJ/dF`` for one integration point (the closed form of the module); with
    ``n = 2`` only the entries with ``i, j, k, l < 2`` (plane strain)."""
    H[0, 0] = F[1, 1] * F[2, 2] - F[1, 2] * F[2, 1]
    H[0, 1] = F[1, 2] * F[2, 0] - F[1, 0] * F[2, 2]
    H[0, 2] = F[1, 0] * F[2, 1] - F[1, 1] * F[2, 0]
    H[1, 0] = F[0, 2] * F[2, 1] - F[0, 1] * F[2, 2]
    H[1, 1] = F[0, 0] * F[2, 2] - F[0, 2] * F[2, 0]
    H[1, 2] = F[0, 1] * F[2, 0] - F[0, 0] * F[2, 1]
    H[2, 0] = F[0, 1] * F[1, 2] - F[0, 2] * F[1, 1]
    H[2, 1] = F[0, 2] * F[1, 0] - F[0, 0] * F[1, 2]
    H[2, 2] = F[0, 0] * F[1, 1] - F[0, 1] * F[1, 0]
    J = F[0, 0] * H[0, 0] + F[0, 1] * H[0, 1] + F[0, 2] * H[0, 2]
    C = np.empty((3, 3))
    b = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            C[i, j] = F[0, i] * F[0, j] + F[1, i] * F[1, j] + F[2, i] * F[2, j]
            b[i, j] = F[i, 0] * F[j, 0] + F[i, 1] * F[j, 1] + F[i, 2] * F[j, 2]
    I1 = C[0, 0] + C[1, 1] + C[2, 2]
    CC = 0.0
    for i in range(3):
        for j in range(3):
            CC += C[i, j] * C[i, j]
    I2 = 0.5 * (I1 * I1 - CC)
    a = J ** (-2.0 / 3.0)
    a2 = a * a
    psi1 = 0.5 * c1 * a
    psi2 = 0.5 * c2 * a2
    psiJ = -c1 / 3.0 * a / J * I1 - 2.0 * c2 / 3.0 * a2 / J * I2 + p
    psi1J = -c1 / 3.0 * a / J
    psi2J = -2.0 * c2 / 3.0 * a2 / J
    psiJJ = 5.0 * c1 / 9.0 * a / (J * J) * I1 + 14.0 * c2 / 9.0 * a2 / (J * J) * I2
    dI2 = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            dI2[i, j] = 2.0 * (I1 * F[i, j] - (F[i, 0] * C[0, j] + F[i, 1] * C[1, j]
                                                + F[i, 2] * C[2, j]))
    s_kron = 2.0 * psi1 + 2.0 * psi2 * I1
    s_HH = psiJJ + psiJ / J
    s_sw = psiJ / J
    for i in range(n):
        for j in range(n):
            for k in range(n):
                for m in range(n):  # m is the l of the docstring
                    e = (4.0 * psi2 * F[i, j] * F[k, m] + s_HH * H[i, j] * H[k, m]
                         + 2.0 * psi1J * (F[i, j] * H[k, m] + H[i, j] * F[k, m])
                         + psi2J * (dI2[i, j] * H[k, m] + H[i, j] * dI2[k, m])
                         - 2.0 * psi2 * F[i, m] * F[k, j] - s_sw * H[i, m] * H[k, j])
                    if i == k:
                        e -= 2.0 * psi2 * C[m, j]
                        if j == m:
                            e += s_kron
                    if j == m:
                        e -= 2.0 * psi2 * b[i, k]
                    A[3 * i + j, 3 * k + m] = e


@numba.njit(cache=True, inline="always")
def _inverse3(M, out):  # noqa: ANN001, ANN202 - Numba kernel
    """``out = M^-1`` of a 3x3 matrix by cofactors; returns ``det M`` (``out`` untouched
    when it is zero)."""
    det = (M[0, 0] * (M[1, 1] * M[2, 2] - M[1, 2] * M[2, 1])
           - M[0, 1] * (M[1, 0] * M[2, 2] - M[1, 2] * M[2, 0])
           + M[0, 2] * (M[1, 0] * M[2, 1] - M[1, 1] * M[2, 0]))
    if det != 0.0:
        out[0, 0] = (M[1, 1] * M[2, 2] - M[1, 2] * M[2, 1]) / det
        out[0, 1] = (M[0, 2] * M[2, 1] - M[0, 1] * M[2, 2]) / det
        out[0, 2] = (M[0, 1] * M[1, 2] - M[0, 2] * M[1, 1]) / det
        out[1, 0] = (M[1, 2] * M[2, 0] - M[1, 0] * M[2, 2]) / det
        out[1, 1] = (M[0, 0] * M[2, 2] - M[0, 2] * M[2, 0]) / det
        out[1, 2] = (M[0, 2] * M[1, 0] - M[0, 0] * M[1, 2]) / det
        out[2, 0] = (M[1, 0] * M[2, 1] - M[1, 1] * M[2, 0]) / det
        out[2, 1] = (M[0, 1] * M[2, 0] - M[0, 0] * M[2, 1]) / det
        out[2, 2] = (M[0, 0] * M[1, 1] - M[0, 1] * M[1, 0]) / det
    return det


@numba.njit(cache=True, inline="always")
def _vertex_gradients(e, verts, coords, g):  # noqa: ANN001, ANN202 - Numba kernel
    """Rows 0-3 of ``g`` (5 x 3): the gradients of the barycentrics of element ``e``
    (``T^-1`` has those of lambda_1..3, lambda_0's is minus their sum); returns ``det T``
    (zero for a degenerate element, ``g`` then untouched)."""
    T = np.empty((3, 3))
    for i in range(3):
        for d in range(3):
            T[d, i] = coords[verts[e, i + 1], d] - coords[verts[e, 0], d]
    Tinv = np.empty((3, 3))
    det = _inverse3(T, Tinv)
    if det != 0.0:
        for i in range(3):
            for d in range(3):
                g[i + 1, d] = Tinv[i, d]
        for d in range(3):
            g[0, d] = -(g[1, d] + g[2, d] + g[3, d])
    return det


@numba.njit(cache=True, inline="always")
def _at_point(L, g, U, P, cb, F):  # noqa: ANN001, ANN202 - Numba kernel
    """At the point of barycentrics ``L``: the bubble's gradient into ``g[4]``, ``F`` from
    the displacement coefficients ``U`` (4 vertices and the bubble); returns ``p``."""
    for d in range(3):  # grad B = c_B sum_i (prod_{j != i} lambda_j) grad lambda_i
        s = 0.0
        for i in range(4):
            prod = 1.0
            for j in range(4):
                if j != i:
                    prod *= L[j]
            s += prod * g[i, d]
        g[4, d] = cb * s
    for i in range(3):
        for j in range(3):
            s = 1.0 if i == j else 0.0
            for a in range(5):
                s += U[a, i] * g[a, j]
            F[i, j] = s
    return L[0] * P[0] + L[1] * P[1] + L[2] * P[2] + L[3] * P[3]


@numba.njit(cache=True, inline="always")
def stress(F, p, c1, c2, P, H, C):  # noqa: ANN001, ANN202 - Numba kernel
    """``P = dW/dF = 2 psi1 F + psi2 dI2 + psiJ H`` and ``H = cof F`` (3x3) of the
    module's energy, ``C`` a work array; returns ``J``."""
    H[0, 0] = F[1, 1] * F[2, 2] - F[1, 2] * F[2, 1]
    H[0, 1] = F[1, 2] * F[2, 0] - F[1, 0] * F[2, 2]
    H[0, 2] = F[1, 0] * F[2, 1] - F[1, 1] * F[2, 0]
    H[1, 0] = F[0, 2] * F[2, 1] - F[0, 1] * F[2, 2]
    H[1, 1] = F[0, 0] * F[2, 2] - F[0, 2] * F[2, 0]
    H[1, 2] = F[0, 1] * F[2, 0] - F[0, 0] * F[2, 1]
    H[2, 0] = F[0, 1] * F[1, 2] - F[0, 2] * F[1, 1]
    H[2, 1] = F[0, 2] * F[1, 0] - F[0, 0] * F[1, 2]
    H[2, 2] = F[0, 0] * F[1, 1] - F[0, 1] * F[1, 0]
    J = F[0, 0] * H[0, 0] + F[0, 1] * H[0, 1] + F[0, 2] * H[0, 2]
    CC = 0.0
    for i in range(3):
        for j in range(3):
            C[i, j] = F[0, i] * F[0, j] + F[1, i] * F[1, j] + F[2, i] * F[2, j]
            CC += C[i, j] * C[i, j]
    I1 = C[0, 0] + C[1, 1] + C[2, 2]
    I2 = 0.5 * (I1 * I1 - CC)
    a = J ** (-2.0 / 3.0)  # NaN for J <= 0, as NGSolve's
    psi1 = 0.5 * c1 * a
    psi2 = 0.5 * c2 * a * a
    psiJ = -c1 / 3.0 * a / J * I1 - 2.0 * c2 / 3.0 * a * a / J * I2 + p
    for i in range(3):
        for j in range(3):
            FC = F[i, 0] * C[0, j] + F[i, 1] * C[1, j] + F[i, 2] * C[2, j]
            P[i, j] = 2.0 * psi1 * F[i, j] + 2.0 * psi2 * (I1 * F[i, j] - FC) + psiJ * H[i, j]
    return J


@numba.njit(cache=True)
def _element_residual(e, verts, coords, x, nH1, nv, zoff, c1, c2, Js_t, cb, qp, r,  # noqa: ANN001, ANN202
                      g, U, Pn, F, P, H, C):
    """Residual ``r`` (19, the local order of :func:`_element`) of element ``e`` at ``x``:
    ``r_(ai) = sum_q w_q P_ij dN_a/dX_j``, ``r_c = sum_q w_q (J - Js_t) lambda_c``; NaN for
    a degenerate element. ``g`` ... ``C``: work arrays."""
    for i in range(3):
        for a in range(4):
            U[a, i] = x[i * nH1 + verts[e, a]]
        U[4, i] = x[i * nH1 + nv + e]
    for a in range(4):
        Pn[a] = x[zoff[e] + verts[e, a]]
    det = _vertex_gradients(e, verts, coords, g)
    r[:] = 0.0 if det != 0.0 else np.nan
    w = abs(det) / 6.0 / 4.0
    for q in range(qp.shape[0] if det != 0.0 else 0):
        p = _at_point(qp[q], g, U, Pn, cb, F)
        J = stress(F, p, c1[e], c2[e], P, H, C)
        for a in range(5):
            ra = 3 * a if a < 4 else 16
            for i in range(3):
                r[ra + i] += w * (P[i, 0] * g[a, 0] + P[i, 1] * g[a, 1] + P[i, 2] * g[a, 2])
        for c in range(4):
            r[12 + c] += w * (J - Js_t[e]) * qp[q, c]


@numba.njit(cache=True, parallel=True)
def _residual(order, chunks, verts, coords, x, nH1, nv, zoff, c1, c2, Js_t, cb, qp, R):  # noqa: ANN001, ANN202
    """``R`` (all DOFs, zeroed by the caller) summed element by element over the colours of
    :func:`_assemble`."""
    for c in range(len(chunks) - 1):
        lo, hi = chunks[c], chunks[c + 1]
        n_par = 8
        for t in numba.prange(n_par):
            g, U = np.empty((5, 3)), np.empty((5, 3))
            F, P, H, C = np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3))
            Pn, r = np.empty(4), np.empty(19)
            for s in range(lo + (hi - lo) * t // n_par, lo + (hi - lo) * (t + 1) // n_par):
                e = order[s]
                _element_residual(e, verts, coords, x, nH1, nv, zoff, c1, c2, Js_t, cb, qp, r,
                                  g, U, Pn, F, P, H, C)
                for i in range(3):
                    for a in range(4):
                        R[i * nH1 + verts[e, a]] += r[3 * a + i]
                    R[i * nH1 + nv + e] += r[16 + i]
                for a in range(4):
                    R[zoff[e] + verts[e, a]] += r[12 + a]


@numba.njit(cache=True)
def _element_systems(elements, verts, coords, x, nH1, nv, zoff, c1, c2, Js_t, cb, qp,  # noqa: ANN001, ANN202
                     tangent, K, r):
    """Uncondensed residuals ``r[k]`` and, if ``tangent``, matrices ``K[k]`` of
    ``elements[k]`` (local order of :func:`_element`; NaN for a degenerate element)."""
    g, U = np.empty((5, 3)), np.empty((5, 3))
    F, P, H, C = np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3))
    Pn = np.empty(4)
    Ke = np.empty((19, 19))
    gd = np.empty(16, dtype=np.int64)
    for k in range(len(elements)):
        e = elements[k]
        _element_residual(e, verts, coords, x, nH1, nv, zoff, c1, c2, Js_t, cb, qp, r[k],
                          g, U, Pn, F, P, H, C)
        if tangent:
            if not _element(e, verts, coords, x, nH1, nv, zoff, c1, c2, cb, qp, Ke, gd):
                Ke[:, :] = np.nan
            K[k] = Ke


@numba.njit(cache=True)
def _element(e, verts, coords, x, nH1, nv, zoff, c1, c2, cb, qp, K, gd):  # noqa: ANN001, ANN202
    """Element matrix ``K`` (19 x 19: 12 vertex displacements ``3 a + i``, 4 pressures,
    3 bubble components) of element ``e`` at the state ``x``, and its 16 external global
    DOFs ``gd``. Returns False for a degenerate element (zero volume)."""
    g = np.empty((5, 3))
    det = _vertex_gradients(e, verts, coords, g)
    if det == 0.0:
        return False
    w = abs(det) / 6.0 / 4.0
    U = np.empty((5, 3))  # displacement coefficients: 4 vertices and the bubble
    for i in range(3):
        for a in range(4):
            U[a, i] = x[i * nH1 + verts[e, a]]
        U[4, i] = x[i * nH1 + nv + e]
    P = np.empty(4)
    for a in range(4):
        P[a] = x[zoff[e] + verts[e, a]]
        for i in range(3):
            gd[3 * a + i] = i * nH1 + verts[e, a]
        gd[12 + a] = zoff[e] + verts[e, a]
    K[:, :] = 0.0
    F = np.empty((3, 3))
    A = np.empty((9, 9))
    H = np.empty((3, 3))
    T1 = np.empty((9, 5, 3))
    for q in range(qp.shape[0]):
        L = qp[q]
        p = _at_point(L, g, U, P, cb, F)
        hessian(F, p, c1[e], c2[e], A, H)
        for r in range(9):  # T1[ij, b, k] = sum_l A[ij, kl] dN_b/dX_l
            for bb in range(5):
                for k in range(3):
                    T1[r, bb, k] = (A[r, 3 * k] * g[bb, 0] + A[r, 3 * k + 1] * g[bb, 1]
                                    + A[r, 3 * k + 2] * g[bb, 2])
        for a in range(5):
            ra = 3 * a if a < 4 else 16
            for i in range(3):
                for bb in range(5):
                    rb = 3 * bb if bb < 4 else 16
                    for k in range(3):
                        K[ra + i, rb + k] += w * (g[a, 0] * T1[3 * i, bb, k]
                                                  + g[a, 1] * T1[3 * i + 1, bb, k]
                                                  + g[a, 2] * T1[3 * i + 2, bb, k])
                hg = w * (H[i, 0] * g[a, 0] + H[i, 1] * g[a, 1] + H[i, 2] * g[a, 2])
                for c in range(4):
                    K[ra + i, 12 + c] += hg * L[c]
                    K[12 + c, ra + i] += hg * L[c]
    return True


@numba.njit(cache=True, parallel=True)
def _assemble(order, chunks, verts, coords, x, nH1, nv, zoff, c1, c2, cb, qp,  # noqa: ANN001, ANN202
              indptr, indices, data, Kbb_inv, E):
    """Condensed element matrices added into ``data`` (CSR pattern with sorted columns that
    holds every element's DOF pairs), chunk by chunk: the chunks of one colour share no
    vertex, so they run in parallel. Returns the
    number of degenerate elements (zero volume or a singular bubble block)."""
    bad = 0
    for c in range(len(chunks) - 1):  # colours: chunks[c] .. chunks[c + 1] index ``order``
        lo, hi = chunks[c], chunks[c + 1]
        n_par = 8
        for t in numba.prange(n_par):
            K = np.empty((19, 19))
            gd = np.empty(16, dtype=np.int64)
            Kbb = np.empty((3, 3))
            inv = np.empty((3, 3))
            start = lo + (hi - lo) * t // n_par
            stop = lo + (hi - lo) * (t + 1) // n_par
            for s in range(start, stop):
                e = order[s]
                if not _element(e, verts, coords, x, nH1, nv, zoff, c1, c2, cb, qp, K, gd):
                    bad += 1
                    continue
                for i in range(3):
                    for j in range(3):
                        Kbb[i, j] = K[16 + i, 16 + j]
                if _inverse3(Kbb, inv) == 0.0:
                    bad += 1
                    continue
                for i in range(3):
                    for j in range(3):
                        Kbb_inv[e, i, j] = inv[i, j]
                    for r in range(16):  # E = -K_bb^-1 K_be
                        E[e, i, r] = -(inv[i, 0] * K[16, r] + inv[i, 1] * K[17, r]
                                       + inv[i, 2] * K[18, r])
                srt = np.argsort(gd)  # the element's columns in ascending order
                for r in range(16):
                    pos = indptr[gd[r]]  # walk the row once, merging with the columns
                    for m in range(16):
                        s2 = srt[m]
                        col = gd[s2]
                        while indices[pos] < col:
                            pos += 1
                        data[pos] += (K[r, s2] + K[r, 16] * E[e, 0, s2]
                                      + K[r, 17] * E[e, 1, s2] + K[r, 18] * E[e, 2, s2])
    return bad


class MiniTangent:
    """The condensed tangent of a :class:`~brainbulge.solver.mixed.MixedForm` (3D MINI,
    Mooney-Rivlin regions, straight tets) and its bubble operators.

    :meth:`assemble` returns the tangent over all DOFs in NGSolve's sparsity pattern (as
    ``form.a.AssembleLinearization`` followed by ``form.a.mat``, the same numbers to
    round-off); :meth:`extend_trans`, :meth:`extend` and :meth:`inner_solve` act as
    ``form.a.harmonic_extension_trans``, ``harmonic_extension`` and ``inner_solve``
    for that tangent.
    """

    #: the local DOF (``3 a + i``, pressures ``12 + c``, bubble ``16 + i``) of each of
    #: NGSolve's element DOFs (x: 4 vertices and the bubble, y, z, 4 pressures)
    ngsolve_order = np.array([0, 3, 6, 9, 16, 1, 4, 7, 10, 17, 2, 5, 8, 11, 18, 12, 13, 14, 15])

    def __init__(self, form) -> None:  # noqa: ANN001 - MixedForm (import cycle)
        t0 = time.perf_counter()
        mesh, fes = form.mesh, form.fes
        self.verts, region = element_vertices(mesh)
        self.coords = vertex_coordinates(mesh)
        nv, ne = mesh.nv, mesh.ne
        V = fes.components[0]
        self.nH1 = V.ndof // 3
        self.nv = nv
        self.ndof = fes.ndof
        names = mesh.GetMaterials()
        mats = form.problem.materials
        self.c1 = np.array([mats[n].c1 for n in names])[region]
        self.c2 = np.array([mats[n].c2 for n in names])[region]
        self.form = form
        self.Js = np.array([float(form.problem.swelling.get(n, 1.0)) for n in names])[region]
        # each element's pressure space: the zone (regex over region names) it belongs to
        offsets = np.cumsum([0] + [s.ndof for s in fes.components])
        zone_of_region = np.full(len(names), -1)
        for z, pat in enumerate(form.pressure_zones):
            rx = re.compile(f"^(?:{pat})$")
            for r, n in enumerate(names):
                if rx.match(n):
                    zone_of_region[r] = z
        self.zoff = offsets[1 + zone_of_region[region]].astype(np.int64)
        self._check_dofs(fes)
        self.cb = _bubble_constant(V, mesh)
        colour = colour_elements(self.verts, nv)
        if (colour < 0).any():
            raise ValueError("more than 128 colours needed for the element loop")
        self.order = np.argsort(colour, kind="stable").astype(np.int64)
        n_col = int(colour.max()) + 1
        self.chunks = np.searchsorted(colour[self.order], np.arange(n_col + 1)).astype(np.int64)
        self.Kbb_inv = np.zeros((ne, 3, 3))
        self.E = np.zeros((ne, 3, 16))
        self.bubble_dofs = (np.arange(3)[None, :] * self.nH1 + nv + np.arange(ne)[:, None])
        self.ext_dofs = np.concatenate(
            [(np.arange(3)[None, None, :] * self.nH1 + self.verts[:, :, None]).reshape(ne, 12),
             self.zoff[:, None] + self.verts], axis=1)
        self._pattern = element_pattern(self.ext_dofs, self.ndof)
        numba.set_num_threads(min(available_cores(), numba.config.NUMBA_NUM_THREADS))
        log.info("closed-form MINI tangent: %d elements in %d colours, pattern %d non-zeros "
                 "(%.1f s)", ne, n_col, self._pattern.nnz, time.perf_counter() - t0)

    def _check_dofs(self, fes: ngs.FESpace) -> None:
        """The DOF numbers assumed by the kernel against NGSolve's, for a few elements."""
        ne = self.verts.shape[0]
        for e in sorted({0, ne // 3, ne // 2, ne - 1}):
            dofs = fes.GetDofNrs(ngs.ElementId(ngs.VOL, e))
            u = [i * self.nH1 + v for i in range(3) for v in (*self.verts[e], self.nv + e)]
            p = [int(self.zoff[e] + v) for v in self.verts[e]]
            got = [d for d in dofs if d >= 0]
            if got[:15] != u or got[15:] != p:
                raise ValueError(f"unexpected DOF numbering of element {e}: {dofs}")

    def assemble(self, x: np.ndarray) -> sp.csr_matrix:
        """The condensed tangent at the state ``x`` (full DOF vector) [force/length]."""
        P = self._pattern
        data = np.zeros(P.nnz)
        bad = _assemble(self.order, self.chunks, self.verts, self.coords, np.asarray(x),
                        self.nH1, self.nv, self.zoff, self.c1, self.c2, self.cb, QUAD_POINTS,
                        P.indptr, P.indices, data, self.Kbb_inv, self.E)
        if bad:  # as NGSolve's tangent of such a state: not finite, Newton rejects it
            log.warning("%d degenerate elements in the tangent", bad)
            data[:] = np.nan
        return sp.csr_matrix((data, P.indices, P.indptr), shape=P.shape)

    def residual(self, x: np.ndarray) -> np.ndarray:
        """``R(x)`` over all DOFs at the form's current load (NaN where an element folds,
        as NGSolve's residual of such a state)."""
        R = np.zeros(self.ndof)
        _residual(self.order, self.chunks, self.verts, self.coords, np.asarray(x), self.nH1,
                  self.nv, self.zoff, self.c1, self.c2, self._Js_t(), self.cb, QUAD_POINTS, R)
        return R

    def element_systems(self, elements: np.ndarray, x: np.ndarray, tangent: bool
                        ) -> tuple[np.ndarray, np.ndarray | None]:
        """Residuals ``(n, m)`` and, if ``tangent``, matrices ``(n, m, m)`` of ``elements``
        at the state ``x``, uncondensed, in the order of NGSolve's element DOFs
        (``fes.GetDofNrs``), as its integrators' ``ApplyElementMatrix`` /
        ``CalcLinearizedElementMatrix`` give them (for the hotspot's local problems)."""
        elements = np.asarray(elements, dtype=np.int64)
        m = len(self.ngsolve_order)
        r = np.empty((len(elements), m))
        K = np.empty((len(elements) if tangent else 0, m, m))
        self._element_systems(elements, np.asarray(x), tangent, K, r)
        o = self.ngsolve_order
        return r[:, o], (K[:, o][:, :, o] if tangent else None)

    def _element_systems(self, elements: np.ndarray, x: np.ndarray, tangent: bool,
                         K: np.ndarray, r: np.ndarray) -> None:
        _element_systems(elements, self.verts, self.coords, x, self.nH1, self.nv, self.zoff,
                         self.c1, self.c2, self._Js_t(), self.cb, QUAD_POINTS, tangent, K, r)

    def _Js_t(self) -> np.ndarray:
        """``Js(t) = 1 + t (Js - 1)`` per element at the form's load ``t``."""
        return 1.0 + self.form.load.Get() * (self.Js - 1.0)

    def extend_trans(self, r: np.ndarray) -> np.ndarray:
        """``E^T r_b`` summed into the external DOFs (``harmonic_extension_trans``)."""
        contrib = np.einsum("eij,ei->ej", self.E, r[self.bubble_dofs])
        return np.bincount(self.ext_dofs.ravel(), contrib.ravel(), minlength=self.ndof)

    def extend(self, dx: np.ndarray) -> np.ndarray:
        """Bubble values ``E dx_e`` (``harmonic_extension``), zero elsewhere."""
        out = np.zeros(self.ndof)
        out[self.bubble_dofs] = np.einsum("eij,ej->ei", self.E, dx[self.ext_dofs])
        return out

    def inner_solve(self, r: np.ndarray) -> np.ndarray:
        """Bubble values ``K_bb^-1 r_b`` (``inner_solve``), zero elsewhere."""
        out = np.zeros(self.ndof)
        out[self.bubble_dofs] = np.einsum("eij,ej->ei", self.Kbb_inv, r[self.bubble_dofs])
        return out


def applies(form) -> bool:  # noqa: ANN001 - MixedForm
    """Whether :class:`MiniTangent` computes this form's tangent: 3D MINI, every region
    Mooney-Rivlin, straight tets (the contact terms are added by Newton)."""
    return (form.element == "mini" and form.dim == 3 and form.mesh.GetCurveOrder() == 1
            and all(isinstance(m, MooneyRivlin) for m in form.problem.materials.values()))


def _bubble_constant(V: ngs.FESpace, mesh: ngs.Mesh) -> float:
    """``c_B`` of NGSolve's interior bubble ``B = c_B lambda_0 lambda_1 lambda_2 lambda_3``
    (order-4 H1 on a tet), from its value at the first element's centroid."""
    gf = ngs.GridFunction(V)
    gf.vec.FV().NumPy()[mesh.nv] = 1.0  # the first element's bubble, x component
    el = mesh[ngs.ElementId(ngs.VOL, 0)]
    centroid = np.mean([mesh[v].point for v in el.vertices], axis=0)
    val = gf(mesh(*centroid))[0]
    # a second point checks the product form
    bary = np.array([0.1, 0.2, 0.3, 0.4])
    pts = np.array([mesh[v].point for v in el.vertices])
    val2 = gf(mesh(*(bary @ pts)))[0]
    cb = val * 4**4
    if not np.isclose(val2, cb * np.prod(bary), rtol=1e-10):
        raise ValueError("NGSolve's tet bubble is not c lambda_0 lambda_1 lambda_2 lambda_3")
    return float(cb)

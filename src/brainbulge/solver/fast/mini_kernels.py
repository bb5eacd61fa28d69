"""Compiled element kernels of the 3D MINI element of a Mooney-Rivlin solid: residual,
tangent and condensed tangent (used by :mod:`brainbulge.solver.fast.mini_tangent`).

NGSolve's ``Variation`` forms the Hessian of the energy by automatic differentiation: about
65 second-order AD evaluations of the energy per integration point (9 + 1 proxy components,
the mixed derivatives by polarisation). That was the largest cost of a Newton iteration
(45 s per tangent at 1.4M tets on two cores). The Hessian of the energy has a closed form,
and a tet's element matrix is a few thousand flops, so it is written out here once and
compiled with Numba (written by hand: no library assembles this element; NGSolve's
bilinear forms with a compiled closed-form Hessian cost as much as its AD, measured).

Energy per unit reference volume (docs/model.md section 2, :mod:`brainbulge.solver.mixed`)::

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

import numba
import numpy as np

#: barycentric coordinates of the 4-point rule of order 2 on the tetrahedron (weights 1/4)
_A, _B = 0.5854101966249685, 0.1381966011250105
QUAD_POINTS = np.array([[_A, _B, _B, _B], [_B, _A, _B, _B], [_B, _B, _A, _B], [_B, _B, _B, _A]])


@numba.njit(cache=True, inline="always")
def cofactor(F, H):  # noqa: ANN001, ANN202 - Numba kernel
    """``H = cof F = J F^-T`` of a 3x3 ``F``; returns ``J = det F``."""
    H[0, 0] = F[1, 1] * F[2, 2] - F[1, 2] * F[2, 1]
    H[0, 1] = F[1, 2] * F[2, 0] - F[1, 0] * F[2, 2]
    H[0, 2] = F[1, 0] * F[2, 1] - F[1, 1] * F[2, 0]
    H[1, 0] = F[0, 2] * F[2, 1] - F[0, 1] * F[2, 2]
    H[1, 1] = F[0, 0] * F[2, 2] - F[0, 2] * F[2, 0]
    H[1, 2] = F[0, 1] * F[2, 0] - F[0, 0] * F[2, 1]
    H[2, 0] = F[0, 1] * F[1, 2] - F[0, 2] * F[1, 1]
    H[2, 1] = F[0, 2] * F[1, 0] - F[0, 0] * F[1, 2]
    H[2, 2] = F[0, 0] * F[1, 1] - F[0, 1] * F[1, 0]
    return F[0, 0] * H[0, 0] + F[0, 1] * H[0, 1] + F[0, 2] * H[0, 2]


@numba.njit(cache=True, inline="always")
def psi_derivatives(J, I1, I2, c1, c2, p):  # noqa: ANN001, ANN202 - Numba kernel
    """``(psi1, psi2, psiJ, psi1J, psi2J, psiJJ)`` of the module's energy (NaN for
    ``J <= 0``, as NGSolve's)."""
    a = J ** (-2.0 / 3.0)
    a2 = a * a
    return (0.5 * c1 * a, 0.5 * c2 * a2,
            -c1 / 3.0 * a / J * I1 - 2.0 * c2 / 3.0 * a2 / J * I2 + p,
            -c1 / 3.0 * a / J, -2.0 * c2 / 3.0 * a2 / J,
            5.0 * c1 / 9.0 * a / (J * J) * I1 + 14.0 * c2 / 9.0 * a2 / (J * J) * I2)


@numba.njit(cache=True, inline="always")
def hessian_entries(F, H, C, b, dI2, J, I1, d, A, n):  # noqa: ANN001, ANN202 - Numba kernel
    """``A[n i + j, n k + l] = d2W/dF_ij dF_kl`` for ``i, j, k, l < n`` (the module's
    index form), from ``F``, ``H``, ``C``, ``b``, ``dI2`` and ``d`` of
    :func:`psi_derivatives`."""
    psi1, psi2, psiJ, psi1J, psi2J, psiJJ = d
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
                    A[n * i + j, n * k + m] = e


@numba.njit(cache=True, inline="always")
def _right_cauchy_green(F, C):  # noqa: ANN001, ANN202 - Numba kernel
    """``C = F^T F`` (3x3); returns ``(I1, I2)``."""
    CC = 0.0
    for i in range(3):
        for j in range(3):
            C[i, j] = F[0, i] * F[0, j] + F[1, i] * F[1, j] + F[2, i] * F[2, j]
            CC += C[i, j] * C[i, j]
    I1 = C[0, 0] + C[1, 1] + C[2, 2]
    return I1, 0.5 * (I1 * I1 - CC)


@numba.njit(cache=True, inline="always")
def hessian(F, p, c1, c2, A, H):  # noqa: ANN001, ANN202 - Numba kernel
    """``A = d2W/dF2`` as a 9x9 matrix (row ``3 i + j``, column ``3 k + l``) and
    ``H = cof F = dJ/dF`` for one integration point (the closed form of the module)."""
    J = cofactor(F, H)
    C = np.empty((3, 3))
    b = np.empty((3, 3))
    I1, I2 = _right_cauchy_green(F, C)
    for i in range(3):
        for j in range(3):
            b[i, j] = F[i, 0] * F[j, 0] + F[i, 1] * F[j, 1] + F[i, 2] * F[j, 2]
    dI2 = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            dI2[i, j] = 2.0 * (I1 * F[i, j] - (F[i, 0] * C[0, j] + F[i, 1] * C[1, j]
                                                + F[i, 2] * C[2, j]))
    hessian_entries(F, H, C, b, dI2, J, I1, psi_derivatives(J, I1, I2, c1, c2, p), A, 3)


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
def _gather(e, verts, x, nH1, nv, zoff, U, P):  # noqa: ANN001, ANN202 - Numba kernel
    """Element ``e``'s displacement coefficients ``U`` (4 vertices and the bubble, x y z)
    and vertex pressures ``P`` out of the DOF vector ``x``."""
    for i in range(3):
        for a in range(4):
            U[a, i] = x[i * nH1 + verts[e, a]]
        U[4, i] = x[i * nH1 + nv + e]
    for a in range(4):
        P[a] = x[zoff[e] + verts[e, a]]


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
    J = cofactor(F, H)
    I1, I2 = _right_cauchy_green(F, C)
    psi1, psi2, psiJ, _, _, _ = psi_derivatives(J, I1, I2, c1, c2, p)
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
    _gather(e, verts, x, nH1, nv, zoff, U, Pn)
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
    P = np.empty(4)
    _gather(e, verts, x, nH1, nv, zoff, U, P)
    for a in range(4):
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
              rows, indptr, indices, data, Kbb_inv, E):
    """Condensed element matrices added into ``data`` (CSR pattern with sorted columns that
    holds every element's DOF pairs), chunk by chunk: the chunks of one colour share no
    vertex, so they run in parallel. ``rows``: each DOF's row and column in the pattern
    (-1: left out, such as a fixed DOF; ascending where kept). Returns the
    number of degenerate elements (zero volume or a singular bubble block)."""
    bad = 0
    for c in range(len(chunks) - 1):  # colours: chunks[c] .. chunks[c + 1] index ``order``
        lo, hi = chunks[c], chunks[c + 1]
        n_par = 8
        for t in numba.prange(n_par):
            K = np.empty((19, 19))
            gd = np.empty(16, dtype=np.int64)
            gr = np.empty(16, dtype=np.int64)
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
                for r in range(16):
                    gr[r] = rows[gd[r]]
                srt = np.argsort(gr)  # the element's columns in ascending order
                for r in range(16):
                    if gr[r] < 0:
                        continue
                    pos = indptr[gr[r]]  # walk the row once, merging with the columns
                    for m in range(16):
                        s2 = srt[m]
                        col = gr[s2]
                        if col < 0:
                            continue
                        while indices[pos] < col:
                            pos += 1
                        data[pos] += (K[r, s2] + K[r, 16] * E[e, 0, s2]
                                      + K[r, 17] * E[e, 1, s2] + K[r, 18] * E[e, 2, s2])
    return bad

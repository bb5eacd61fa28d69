"""The plane-strain MINI residual and condensed tangent of a Mooney-Rivlin solid (2D).

The 2D counterpart of :mod:`brainbulge.solver.fast.mini_tangent`: the same energy and its
closed-form derivatives, evaluated at the plane-strain deformation gradient
``F = [[F_2D, 0], [0, 1]]`` (so ``J = det F_2D`` and the in-plane block of ``cof F`` is
``cof F_2D``)::

    W(F, p) = c1/2 (J^(-2/3) I1 - 3) + c2/2 (J^(-4/3) I2 - 3) + p (J - Js(t))
    P = dW/dF = 2 psi1 F + psi2 dI2 + psiJ H,          dI2 = 2 (I1 F - F C),  H = cof F

    R_(ai) = sum_q w_q  P_ij dN_a/dX_j,          R_c = sum_q w_q (J - Js(t)) lambda_c
    K_(ai)(bk) = sum_q w_q  dN_a/dX_j  A_ijkl  dN_b/dX_l,
    K_(ai)c = sum_q w_q  H_ij dN_a/dX_j  lambda_c

with ``A = d2W/dF2`` of :func:`~brainbulge.solver.fast.mini_kernels.hessian` (indices
``i, j, k, l`` in the plane), ``N_a`` the three hats ``lambda_a`` and the bubble
``B = c_B lambda_0 lambda_1 lambda_2``, the bubble condensed statically as in 3D. The
hemidisk's boundary triangles are curved (quadratic geometry): the physical gradients
``dN/dX = J_e^-T dN/dxi`` and the weights ``w_q |det J_e|`` come from NGSolve's element
maps at NGSolve's own integration rule (order 5, 12 points: the rule its ``Variation`` uses
here, energies equal to 1e-15), computed once per mesh.

Written by hand for speed: NGSolve's automatic differentiation took 0.17 s per tangent and
0.07 s per residual on the 11k-DOF headline mesh, the largest part of a 2D solve (line
searches evaluate many residuals); these loops take milliseconds.
"""

from __future__ import annotations

import ngsolve as ngs
import numba
import numpy as np
import scipy.sparse as sp

from brainbulge.materials.mooney_rivlin import MooneyRivlin
from brainbulge.solver.fast.element_graph import element_pattern, numbering
from brainbulge.solver.fast.mini_kernels import hessian_entries, psi_derivatives
from brainbulge.solver.fast.mini_tangent import MiniTangent

#: order of NGSolve's integration rule for the 2D MINI energy (vertex P1 + cubic bubble)
QUAD_ORDER = 5
#: the kernels' local DOF (6 vertex displacements ``2 a + i``, 3 pressures, 2 bubble
#: components) of each of NGSolve's element DOFs (x: 3 vertices and the bubble, y, pressures)
NGSOLVE_ORDER = np.array([0, 2, 4, 9, 1, 3, 5, 10, 6, 7, 8])
#: gradients of the reference hats ``lambda_0 = xi, lambda_1 = eta, lambda_2 = 1 - xi - eta``
_REF_GRAD = np.array([[1.0, 0.0], [0.0, 1.0], [-1.0, -1.0]])


@numba.njit(cache=True)
def plane_strain(F, p, c1, c2, P, H, A, C, b, dI2, tangent):  # noqa: ANN001, ANN202 - kernel
    """``P = dW/dF``, ``H = cof F`` and, if ``tangent``, ``A = d2W/dF2`` (row ``2 i + j``,
    column ``2 k + l``) of the in-plane ``F`` (2x2, ``F_33 = 1``); returns ``J``. The
    formulas of :func:`~brainbulge.solver.fast.mini_kernels.hessian` with every index in
    the plane (``I1 = tr C + 1``, ``I2 = (I1^2 - |C|^2 - 1) / 2``); ``C``, ``b``, ``dI2``
    are work arrays (no allocation per integration point)."""
    H[0, 0] = F[1, 1]
    H[0, 1] = -F[1, 0]
    H[1, 0] = -F[0, 1]
    H[1, 1] = F[0, 0]
    J = F[0, 0] * F[1, 1] - F[0, 1] * F[1, 0]
    for i in range(2):
        for j in range(2):
            C[i, j] = F[0, i] * F[0, j] + F[1, i] * F[1, j]
            b[i, j] = F[i, 0] * F[j, 0] + F[i, 1] * F[j, 1]
    I1 = C[0, 0] + C[1, 1] + 1.0
    I2 = 0.5 * (I1 * I1 - (C[0, 0] ** 2 + C[0, 1] ** 2 + C[1, 0] ** 2 + C[1, 1] ** 2 + 1.0))
    d = psi_derivatives(J, I1, I2, c1, c2, p)
    for i in range(2):
        for j in range(2):
            dI2[i, j] = 2.0 * (I1 * F[i, j] - (F[i, 0] * C[0, j] + F[i, 1] * C[1, j]))
            P[i, j] = 2.0 * d[0] * F[i, j] + d[1] * dI2[i, j] + d[2] * H[i, j]
    if tangent:
        hessian_entries(F, H, C, b, dI2, J, I1, d, A, 2)
    return J


@numba.njit(cache=True)
def _element(e, verts, G, Wq, L, x, nH1, nv, zoff, c1, c2, Js_t, tangent, K, r):  # noqa: ANN001, ANN202
    """Element residual ``r`` and, if ``tangent``, matrix ``K`` (11 local DOFs: 6 vertex
    displacements ``2 a + i``, 3 pressures, 2 bubble components) of element ``e`` at the
    state ``x``."""
    F = np.empty((2, 2))
    P = np.empty((2, 2))
    H = np.empty((2, 2))
    A = np.empty((4, 4))
    C = np.empty((2, 2))
    b = np.empty((2, 2))
    dI2 = np.empty((2, 2))
    T1 = np.empty((4, 4, 2))
    U = np.empty((4, 2))
    Pn = np.empty(3)
    for i in range(2):
        for a in range(3):
            U[a, i] = x[i * nH1 + verts[e, a]]
        U[3, i] = x[i * nH1 + nv + e]
    for c in range(3):
        Pn[c] = x[zoff[e] + verts[e, c]]
    r[:] = 0.0
    if tangent:
        K[:, :] = 0.0
    for q in range(L.shape[0]):
        for i in range(2):
            for j in range(2):
                s = 1.0 if i == j else 0.0
                for a in range(4):
                    s += U[a, i] * G[e, q, a, j]
                F[i, j] = s
        p = L[q, 0] * Pn[0] + L[q, 1] * Pn[1] + L[q, 2] * Pn[2]
        J = plane_strain(F, p, c1[e], c2[e], P, H, A, C, b, dI2, tangent)
        w = Wq[e, q]
        for a in range(4):
            ra = 2 * a if a < 3 else 9
            for i in range(2):
                r[ra + i] += w * (P[i, 0] * G[e, q, a, 0] + P[i, 1] * G[e, q, a, 1])
        for c in range(3):
            r[6 + c] += w * (J - Js_t[e]) * L[q, c]
        if not tangent:
            continue
        for ij in range(4):  # T1[ij, b, k] = sum_l A[ij, kl] dN_b/dX_l
            for bb in range(4):
                for k in range(2):
                    T1[ij, bb, k] = (A[ij, 2 * k] * G[e, q, bb, 0]
                                     + A[ij, 2 * k + 1] * G[e, q, bb, 1])
        for a in range(4):
            ra = 2 * a if a < 3 else 9
            for i in range(2):
                for bb in range(4):
                    rb = 2 * bb if bb < 3 else 9
                    for k in range(2):
                        K[ra + i, rb + k] += w * (G[e, q, a, 0] * T1[2 * i, bb, k]
                                                  + G[e, q, a, 1] * T1[2 * i + 1, bb, k])
                hg = w * (H[i, 0] * G[e, q, a, 0] + H[i, 1] * G[e, q, a, 1])
                for c in range(3):
                    K[ra + i, 6 + c] += hg * L[q, c]
                    K[6 + c, ra + i] += hg * L[q, c]


@numba.njit(cache=True)
def _residual(verts, G, Wq, L, x, nH1, nv, zoff, c1, c2, Js_t, R):  # noqa: ANN001, ANN202
    """``R`` (full DOF numbering, zeroed by the caller) of all elements at the state ``x``
    (NaN terms where an element folds)."""
    K = np.empty((1, 1))
    r = np.empty(11)
    for e in range(verts.shape[0]):
        _element(e, verts, G, Wq, L, x, nH1, nv, zoff, c1, c2, Js_t, False, K, r)
        for i in range(2):
            for a in range(3):
                R[i * nH1 + verts[e, a]] += r[2 * a + i]
            R[i * nH1 + nv + e] += r[9 + i]
        for c in range(3):
            R[zoff[e] + verts[e, c]] += r[6 + c]


@numba.njit(cache=True)
def _tangent(verts, G, Wq, L, x, nH1, nv, zoff, c1, c2, Js_t, slots, data, Kbb_inv, E):  # noqa: ANN001, ANN202
    """Condensed element matrices (the 9 external DOFs, the 2 bubble components condensed)
    added into ``data`` at ``slots`` (per element, the 9 x 9 positions in the CSR data,
    -1 for a pair left out of the pattern);
    ``E = -K_bb^-1 K_be`` and ``K_bb^-1`` per element. Returns the number of elements with
    a singular bubble block."""
    K = np.empty((11, 11))
    r = np.empty(11)
    bad = 0
    for e in range(verts.shape[0]):
        _element(e, verts, G, Wq, L, x, nH1, nv, zoff, c1, c2, Js_t, True, K, r)
        det = K[9, 9] * K[10, 10] - K[9, 10] * K[10, 9]
        if det == 0.0:
            bad += 1
            continue
        Kbb_inv[e, 0, 0] = K[10, 10] / det
        Kbb_inv[e, 0, 1] = -K[9, 10] / det
        Kbb_inv[e, 1, 0] = -K[10, 9] / det
        Kbb_inv[e, 1, 1] = K[9, 9] / det
        for i in range(2):
            for m in range(9):
                E[e, i, m] = -(Kbb_inv[e, i, 0] * K[9, m] + Kbb_inv[e, i, 1] * K[10, m])
        for m in range(9):
            for n in range(9):
                if slots[e, m, n] >= 0:
                    data[slots[e, m, n]] += K[m, n] + K[m, 9] * E[e, 0, n] + K[m, 10] * E[e, 1, n]
    return bad


@numba.njit(cache=True)
def _element_systems(elements, verts, G, Wq, L, x, nH1, nv, zoff, c1, c2, Js_t, tangent,  # noqa: ANN001, ANN202
                     K, r):
    """Uncondensed residuals ``r[k]`` and matrices ``K[k]`` of ``elements[k]`` (local order
    of :func:`_element`)."""
    Ke = np.empty((11, 11))
    re = np.empty(11)
    for k in range(len(elements)):
        _element(elements[k], verts, G, Wq, L, x, nH1, nv, zoff, c1, c2, Js_t, tangent, Ke, re)
        r[k] = re
        if tangent:
            K[k] = Ke


@numba.njit(cache=True)
def _slots(ext, indptr, indices):  # noqa: ANN001, ANN202
    """Position in the CSR data of every element's DOF pair ``(ext[e, m], ext[e, n])``
    (-1 where either is left out, -1)."""
    ne, k = ext.shape
    out = np.empty((ne, k, k), dtype=np.int64)
    for e in range(ne):
        for m in range(k):
            row = ext[e, m]
            for n in range(k):
                if row < 0 or ext[e, n] < 0:
                    out[e, m, n] = -1
                    continue
                lo, hi = indptr[row], indptr[row + 1]
                while lo < hi:  # bisection in the row's sorted columns
                    mid = (lo + hi) // 2
                    if indices[mid] < ext[e, n]:
                        lo = mid + 1
                    else:
                        hi = mid
                out[e, m, n] = lo
    return out


class PlaneMiniTangent(MiniTangent):
    """Residual and condensed tangent of a 2D :class:`~brainbulge.solver.mixed.MixedForm`
    (MINI, Mooney-Rivlin regions, straight or curved triangles) with the bubble operators
    of :class:`~brainbulge.solver.fast.mini_tangent.MiniTangent`."""

    ngsolve_order = NGSOLVE_ORDER

    def __init__(self, form, free: np.ndarray | None = None) -> None:  # noqa: ANN001
        mesh, fes = form.mesh, form.fes
        self._element_data(form)
        nv, ne = mesh.nv, mesh.ne
        self._check_dofs(fes)
        self.G, self.Wq, self.L = _element_geometry(mesh, _bubble_constant(fes.components[0],
                                                                           mesh))
        self.Kbb_inv = np.zeros((ne, 2, 2))
        self.E = np.zeros((ne, 2, 9))
        self.bubble_dofs = np.arange(2)[None, :] * self.nH1 + nv + np.arange(ne)[:, None]
        self.ext_dofs = np.concatenate(
            [(np.arange(2)[None, None, :] * self.nH1 + self.verts[:, :, None]).reshape(ne, 6),
             self.zoff[:, None] + self.verts], axis=1)
        rows = numbering(self.ndof, free)[self.ext_dofs]  # -1: a DOF left out
        self._pattern = element_pattern(rows, self.ndof if free is None else len(free))
        self._slots = _slots(rows, self._pattern.indptr, self._pattern.indices)

    def _check_dofs(self, fes: ngs.FESpace) -> None:
        """The DOF numbers assumed by the kernels against NGSolve's, for a few elements."""
        ne = self.verts.shape[0]
        for e in sorted({0, ne // 3, ne // 2, ne - 1}):
            dofs = [d for d in fes.GetDofNrs(ngs.ElementId(ngs.VOL, e)) if d >= 0]
            u = [i * self.nH1 + v for i in range(2) for v in (*self.verts[e], self.nv + e)]
            p = [int(self.zoff[e] + v) for v in self.verts[e]]
            if dofs[:8] != u or dofs[8:] != p:
                raise ValueError(f"unexpected DOF numbering of element {e}: {dofs}")

    def residual(self, x: np.ndarray) -> np.ndarray:
        """``R(x)`` over all DOFs at the form's current load (NaN where an element folds,
        as NGSolve's residual of such a state)."""
        R = np.zeros(self.ndof)
        _residual(self.verts, self.G, self.Wq, self.L, np.asarray(x), self.nH1, self.nv,
                  self.zoff, self.c1, self.c2, self._Js_t(), R)
        return R

    def assemble(self, x: np.ndarray) -> sp.csr_matrix:
        """The condensed tangent at the state ``x`` (full DOF vector) [force/length], on
        all DOFs or on the ``free`` ones given at set-up."""
        P = self._pattern
        data = np.zeros(P.nnz)
        bad = _tangent(self.verts, self.G, self.Wq, self.L, np.asarray(x), self.nH1, self.nv,
                       self.zoff, self.c1, self.c2, self._Js_t(), self._slots, data,
                       self.Kbb_inv, self.E)
        if bad:
            data[:] = np.nan
        return P.matrix(data)

    def _element_systems(self, elements: np.ndarray, x: np.ndarray, tangent: bool,
                         K: np.ndarray, r: np.ndarray) -> None:
        _element_systems(elements, self.verts, self.G, self.Wq, self.L, x, self.nH1, self.nv,
                         self.zoff, self.c1, self.c2, self._Js_t(), tangent, K, r)


def applies(form) -> bool:  # noqa: ANN001 - MixedForm
    """Whether :class:`PlaneMiniTangent` computes this form's residual and tangent: 2D MINI,
    every region Mooney-Rivlin, no contact in the energy (the contact points' terms are
    added by Newton)."""
    return (form.element == "mini" and form.dim == 2 and not form.penalty_contacts
            and all(isinstance(m, MooneyRivlin) for m in form.problem.materials.values()))


def _element_geometry(mesh: ngs.Mesh, cb: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Physical gradients ``G (ne, nq, 4, 2)`` of the three hats and the bubble, weights
    ``w_q |det J_e| (ne, nq)`` and barycentrics ``(nq, 3)`` at NGSolve's rule of order
    :data:`QUAD_ORDER`, from NGSolve's element maps (curved elements included)."""
    ir = ngs.IntegrationRule(ngs.TRIG, QUAD_ORDER)
    xi = np.array([p[:2] for p in ir.points])
    w = np.array(list(ir.weights))
    L = np.column_stack([xi[:, 0], xi[:, 1], 1.0 - xi[:, 0] - xi[:, 1]])
    jac = np.asarray(ngs.specialcf.JacobianMatrix(2)(mesh.MapToAllElements(ir, ngs.VOL)))
    jac = jac.reshape(mesh.ne, len(w), 2, 2)  # dX_r / dxi_c
    det = jac[..., 0, 0] * jac[..., 1, 1] - jac[..., 0, 1] * jac[..., 1, 0]
    inv_t = np.empty_like(jac)  # J^-T
    inv_t[..., 0, 0] = jac[..., 1, 1] / det
    inv_t[..., 0, 1] = -jac[..., 1, 0] / det
    inv_t[..., 1, 0] = -jac[..., 0, 1] / det
    inv_t[..., 1, 1] = jac[..., 0, 0] / det
    ref = np.empty((len(w), 4, 2))  # reference gradients, the bubble's by the product rule
    ref[:, :3] = _REF_GRAD
    ref[:, 3] = cb * (L[:, [1]] * L[:, [2]] * _REF_GRAD[0] + L[:, [0]] * L[:, [2]]
                      * _REF_GRAD[1] + L[:, [0]] * L[:, [1]] * _REF_GRAD[2])
    G = np.einsum("eqrc,qac->eqar", inv_t, ref)
    return np.ascontiguousarray(G), np.abs(det) * w, L


def _bubble_constant(V: ngs.FESpace, mesh: ngs.Mesh) -> float:
    """``c_B`` of NGSolve's triangle bubble ``B = c_B lambda_0 lambda_1 lambda_2`` (order-3
    H1), from its values at two reference points of the first element."""
    gf = ngs.GridFunction(V)
    gf.vec.FV().NumPy()[mesh.nv] = 1.0  # the first element's bubble, x component
    ir = ngs.IntegrationRule([(1 / 3, 1 / 3, 0), (0.2, 0.3, 0)], [1.0, 1.0])
    vals = np.asarray(gf(mesh.MapToAllElements(ir, ngs.VOL)))[:2, 0]
    cb = vals[0] * 27.0
    if not np.isclose(vals[1], cb * 0.2 * 0.3 * 0.5, rtol=1e-10):
        raise ValueError("NGSolve's triangle bubble is not c lambda_0 lambda_1 lambda_2")
    return float(cb)

"""The 3D MINI residual and condensed tangent of a Mooney-Rivlin solid, in NGSolve's DOF
layout, from the compiled kernels of :mod:`brainbulge.solver.fast.mini_kernels`.

NGSolve's ``Variation`` forms the Hessian of the energy by automatic differentiation (45 s
per tangent at 1.4M tets on two cores); the kernels evaluate the closed form element by
element, in parallel over colours of elements that share no vertex
(:mod:`brainbulge.solver.fast.element_graph`), into the sparsity pattern of all element
DOF pairs. :class:`MiniTangent` checks NGSolve's DOF numbering at set-up, keeps the bubble
blocks for the condensed Newton step, and gives the hotspot's local problems their
uncondensed element systems.
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
from brainbulge.solver.fast.element_graph import colour_elements, element_pattern, numbering
from brainbulge.solver.fast.mini_kernels import (
    QUAD_POINTS,
    _assemble,
    _element_systems,
    _residual,
)
from brainbulge.solver.threads import available_cores

log = logging.getLogger(__name__)
# Numba's compiler logs every pass at DEBUG: tens of thousands of lines in a run's log
logging.getLogger("numba").setLevel(logging.WARNING)


class MiniTangent:
    """The condensed tangent of a :class:`~brainbulge.solver.mixed.MixedForm` (3D MINI,
    Mooney-Rivlin regions, straight tets) and its bubble operators.

    :meth:`assemble` returns the tangent over all DOFs in NGSolve's sparsity pattern (as
    ``form.a.AssembleLinearization`` followed by ``form.a.mat``, the same numbers to
    round-off), or, given ``free`` (ascending DOF numbers), straight on those DOFs: the
    rows and columns of the others are left out of the pattern when it is built, so
    Newton holds one tangent-sized matrix and no gather of its free part.
    :meth:`extend_trans`, :meth:`extend` and :meth:`inner_solve` act as
    ``form.a.harmonic_extension_trans``, ``harmonic_extension`` and ``inner_solve``
    for that tangent (on vectors over all DOFs).
    """

    #: the local DOF (``3 a + i``, pressures ``12 + c``, bubble ``16 + i``) of each of
    #: NGSolve's element DOFs (x: 4 vertices and the bubble, y, z, 4 pressures)
    ngsolve_order = np.array([0, 3, 6, 9, 16, 1, 4, 7, 10, 17, 2, 5, 8, 11, 18, 12, 13, 14, 15])

    def __init__(self, form, free: np.ndarray | None = None) -> None:  # noqa: ANN001
        # (form: a MixedForm, not imported: an import cycle)
        t0 = time.perf_counter()
        mesh, fes = form.mesh, form.fes
        self._element_data(form)
        self.coords = vertex_coordinates(mesh)
        nv, ne = mesh.nv, mesh.ne
        V = fes.components[0]
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
        self._rows = numbering(self.ndof, free)  # each DOF's row in the tangent, -1: none
        self._pattern = element_pattern(self._rows[self.ext_dofs],
                                        self.ndof if free is None else len(free))
        numba.set_num_threads(min(available_cores(), numba.config.NUMBA_NUM_THREADS))
        log.info("closed-form MINI tangent: %d elements in %d colours, pattern %d non-zeros "
                 "(%.1f s)", ne, n_col, self._pattern.nnz, time.perf_counter() - t0)

    def _element_data(self, form) -> None:  # noqa: ANN001 - MixedForm
        """Per element: vertices, Mooney-Rivlin ``c1``, ``c2``, target ``Js`` and the offset
        of its pressure zone's space (the zone: a regex over region names); the numbers of
        vertices, of scalar H1 DOFs (vertices and bubbles) and of all DOFs."""
        mesh, fes = form.mesh, form.fes
        self.form = form
        self.verts, region = element_vertices(mesh)
        self.nv, self.nH1, self.ndof = mesh.nv, fes.components[0].ndof // mesh.dim, fes.ndof
        names = mesh.GetMaterials()
        mats = form.problem.materials
        self.c1 = np.array([mats[n].c1 for n in names])[region]
        self.c2 = np.array([mats[n].c2 for n in names])[region]
        self.Js = np.array([float(form.problem.swelling.get(n, 1.0)) for n in names])[region]
        offsets = np.cumsum([0] + [s.ndof for s in fes.components])
        zone_of_region = np.full(len(names), -1)
        for z, pat in enumerate(form.pressure_zones):
            rx = re.compile(f"^(?:{pat})$")
            for r, n in enumerate(names):
                if rx.match(n):
                    zone_of_region[r] = z
        self.zoff = offsets[1 + zone_of_region[region]].astype(np.int64)

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
        """The condensed tangent at the state ``x`` (full DOF vector) [force/length], on
        all DOFs or on the ``free`` ones given at set-up."""
        P = self._pattern
        data = np.zeros(P.nnz)
        bad = _assemble(self.order, self.chunks, self.verts, self.coords, np.asarray(x),
                        self.nH1, self.nv, self.zoff, self.c1, self.c2, self.cb, QUAD_POINTS,
                        self._rows, P.indptr, P.indices, data, self.Kbb_inv, self.E)
        if bad:  # as NGSolve's tangent of such a state: not finite, Newton rejects it
            log.warning("%d degenerate elements in the tangent", bad)
            data[:] = np.nan
        return P.matrix(data)

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

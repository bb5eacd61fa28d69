"""Mixed displacement-pressure formulation of the swelling, incompressible solid.

Stationary point of the Lagrangian (MODEL.md section 2) over ``(u, p)``::

    Pi(u, p) = int_Omega [ psibar(F) + p (J - Js(t)) ] dV
             + sum_contacts int_Gamma_c 1/(2 r) <lambda - r g(X + u)>_+^2 dA

with ``Js(t) = 1 + t (Js - 1)`` the swelling ramped by the load factor ``t`` in [0, 1]. ``p``
is the Lagrange multiplier of ``J = Js`` (tension positive). Contact is frictionless and
unilateral against rigid obstacles with signed distance ``g`` (``g >= 0`` admissible), by an
augmented Lagrangian: ``r`` is the penalty, ``lambda >= 0`` the contact pressure, updated by
Uzawa's rule ``lambda <- s(lambda - r g)`` until the penetration is below tolerance. ``s`` is
a C1-smoothed ramp ``<z>_+`` (width ``eps = 0.02 mu``), and the obstacle is offset by
``eps/(2r)`` so that ``g = 0`` is the converged state wherever the contact pressure exceeds
``eps``. The contact term written above with ``<.>_+^2/(2r)`` is, precisely,
``S(lambda - r g)/r`` with ``S' = s``.

NGSolve's ``Variation`` differentiates ``Pi`` symbolically: residual and tangent come exactly
from the energy. Inf-sup stable pairs: Taylor-Hood P2/P1 (2D and 3D) and MINI, P1 + bubble /
P1, with the bubbles condensed statically.
"""

from __future__ import annotations

import logging
import re

import ngsolve as ngs
import numpy as np

from brainbulge.errors import InputError
from brainbulge.materials.kinematics import deformation_gradient
from brainbulge.materials.mooney_rivlin import MooneyRivlin, mooney_rivlin_psi
from brainbulge.model.problem import Problem
from brainbulge.solver.compile_cache import compilation_failed, native_compiler_ready
from brainbulge.solver.point_contact import PointContact

log = logging.getLogger(__name__)

ELEMENTS = ("taylor-hood", "mini")


class MixedForm:
    """Spaces, unknowns and the symbolic energy of a :class:`Problem`."""

    def __init__(
        self,
        problem: Problem,
        element: str = "taylor-hood",
        contact_penalty: float | None = None,
        compile_energy: bool = False,
    ) -> None:
        if element not in ELEMENTS:
            raise InputError(f"unknown element {element!r}; choose one of {', '.join(ELEMENTS)}")
        self.problem = problem
        self.element = element
        mesh = problem.mesh
        self.mesh = mesh
        dim = mesh.dim
        self.dim = dim

        comp_flags = {}
        for i, name in enumerate("xyz"[:dim]):
            pats = [p for p in (problem.clamped, problem.clamped_components.get(i, "")) if p]
            pats += [b for b, d in problem.displacements.items() if d[i] is not None]
            if pats:
                comp_flags[f"dirichlet{name}"] = "|".join(pats)
        V = ngs.VectorH1(mesh, order=2 if element == "taylor-hood" else 1, **comp_flags)
        if element == "mini":
            V.SetOrder(ngs.TRIG if dim == 2 else ngs.TET, 3 if dim == 2 else 4)
            V.Update()
        # pressure: continuous P1 within each zone of equal material and swelling, broken
        # across zones, where the exact pressure jumps (a continuous p smears the jump and
        # spoils J = Js next to swelling interfaces)
        self.pressure_zones = _pressure_zones(problem)
        Qs = [ngs.H1(mesh, order=1, definedon=mesh.Materials(z)) for z in self.pressure_zones]
        self.fes = ngs.FESpace([V, *Qs])
        self.condense = element == "mini"
        self._bubble_dofs: np.ndarray | None = None  # MINI's cell-bubble DOFs in u's space
        self.load = ngs.Parameter(0.0)  # load factor t
        self.gfu = ngs.GridFunction(self.fes)

        u, *ps = self.fes.TrialFunction()
        F = deformation_gradient(u, dim)
        J = ngs.Det(F)
        self.Js = problem.swelling_cf()
        Js_t = 1 + self.load * (self.Js - 1)
        self.a = ngs.BilinearForm(self.fes, symmetric=True, condense=self.condense)
        self.split_zones = split_energy(mesh.ne, len(ps), compile_energy)
        if self.split_zones:  # W_z = psi + p_z (J - Js) over each zone z
            for zone, p_z in zip(self.pressure_zones, ps, strict=True):
                W = _compiled(self._psi_iso(F) + p_z * (J - Js_t), compile_energy)
                self.a += ngs.Variation(W * ngs.dx(definedon=mesh.Materials(zone)))
        else:  # one expression with p = sum_z p_z (each p_z is zero outside its zone)
            p = sum(ps[1:], ps[0])
            W = _compiled(self._psi_iso(F) + p * (J - Js_t), compile_energy)
            self.a += ngs.Variation(W * ngs.dx)

        # contact: augmented Lagrangian with a multiplier field on each contact boundary
        self.mu_max = max(m.shear_modulus for m in problem.materials.values())
        self.contact_multipliers: list[ngs.GridFunction] = []
        self.contact_gaps: list[ngs.CoefficientFunction] = []
        self.contact_regions: list[ngs.Region] = []
        self.contact_masks: list[ngs.CoefficientFunction] = []
        self._contact_z: list[ngs.CoefficientFunction] = []
        h = _mesh_size(mesh)
        self.h = h
        self.r0 = contact_penalty if contact_penalty is not None else 100 * self.mu_max / h
        self.r = ngs.Parameter(self.r0)  # raised by penalty continuation at the final load
        self.eps_c = 0.02 * self.mu_max  # smoothing of the contact law [kPa]
        self.g_off = self.eps_c / (2 * self.r)  # makes g = 0 the fixed point of Uzawa
        X = ngs.CF((ngs.x, ngs.y, ngs.z)[:dim])
        self.point_contacts: list[PointContact] = []
        for c in problem.contacts:
            if c.active_set:  # exact multipliers at the nodes
                self.point_contacts.append(PointContact(self, c.boundary, c.obstacle))
                continue
            region = mesh.Boundaries(c.boundary)
            if not any(region.Mask()):
                raise InputError(f"contact boundary {c.boundary!r} matches no mesh boundary")
            # multiplier and initial gap: discontinuous per boundary facet, so that the Uzawa
            # update is a local projection that does not smear the peaked contact pressure
            L = ngs.SurfaceL2(mesh, order=3, definedon=region)
            lam = ngs.GridFunction(L)
            # initial-gap adjustment (as Abaqus' "adjust"): the curved mesh boundary lies on
            # the skull only up to the geometric error, ~1e-6 R; gaps and overclosures below
            # 1e-3 h at rest are removed, so a boundary that rests on the skull touches it
            g_rest = c.obstacle.gap(X)
            g0 = ngs.GridFunction(L)
            g0.Set(ngs.IfPos(1e-3 * h - ngs.Norm(g_rest), g_rest, 0), ngs.BND, definedon=region)
            g = c.obstacle.gap(X + u) - g0
            Wc = contact_energy(lam - self.r * (g - self.g_off), self.r, self.eps_c)
            self.a += ngs.Variation(Wc * ngs.ds(definedon=region))
            self.contact_multipliers.append(lam)
            self.contact_regions.append(region)
            self.contact_masks.append(boundary_indicator(mesh, c.boundary))
            u_gf = self.gfu.components[0]
            self.contact_gaps.append(c.obstacle.gap(X + u_gf) - g0)
            self._contact_z.append(lam - self.r * (self.contact_gaps[-1] - self.g_off))

    def _psi_iso(self, F: ngs.CoefficientFunction) -> ngs.CoefficientFunction:
        """Isochoric energy over all regions: one expression with region-wise coefficients."""
        mats = self.problem.materials
        mesh = self.mesh
        if all(isinstance(m, MooneyRivlin) for m in mats.values()):
            c1 = mesh.MaterialCF({r: m.c1 for r, m in mats.items()}, default=0)
            c2 = mesh.MaterialCF({r: m.c2 for r, m in mats.items()}, default=0)
            return mooney_rivlin_psi(F, c1, c2)
        psi = 0
        for region, m in mats.items():
            mask = mesh.MaterialCF({region: 1.0}, default=0.0)
            psi = psi + mask * m.psi_iso(F)
        return psi

    @property
    def contacts_present(self) -> bool:
        return bool(self.contact_multipliers or self.point_contacts)

    # --- fields of the current state -------------------------------------------------
    @property
    def u(self) -> ngs.GridFunction:
        return self.gfu.components[0]

    def output_displacement(self) -> ngs.GridFunction:
        """The displacement the outputs sample [length]: ``u`` for Taylor-Hood; for MINI its
        P1 part ``u_L`` (a copy of ``u`` with the cell bubbles zeroed).

        MINI's bubbles stabilise the pressure; they do not approximate the displacement
        better (``|u - u_L|_1 = O(h)`` as ``|u - u_h|_1``). Their gradients oscillate inside
        each element with zero mean (``int_T grad b = int_dT b n = 0``), so ``grad u_L`` is
        the element mean of ``grad u``, and ``det(I + grad u_L)`` the element's deformed
        volume over its reference volume exactly (the bubbles vanish on the element's
        boundary, which fixes the image's volume). Sampled at integration points, the
        bubbles' oscillation widens the distribution of stretch and strain: on a 62k-tet
        brain it raised the 99th percentile of the principal strain from 0.139 to 0.192 and
        its largest value from 0.33 to 0.93 (docs/design.md, "Elements")."""
        if self.element != "mini":
            return self.u
        if self._bubble_dofs is None:
            from brainbulge.geometry.ngsolve_arrays import vertex_dofs

            V = self.fes.components[0]
            bubble = np.ones(V.ndof, dtype=bool)
            vd = vertex_dofs(V, self.mesh)
            bubble[vd[vd >= 0]] = False
            self._bubble_dofs = np.flatnonzero(bubble)
        u_L = ngs.GridFunction(self.fes.components[0])
        u_L.vec.data = self.u.vec
        u_L.vec.FV().NumPy()[self._bubble_dofs] = 0.0
        return u_L

    @property
    def p(self) -> ngs.CoefficientFunction:
        """Pressure multiplier ``p`` (tension positive) [kPa]."""
        comps = self.gfu.components[1:]
        return sum(comps[1:], comps[0])

    def F(self) -> ngs.CoefficientFunction:
        return deformation_gradient(self.u, self.dim)

    def set_load(self, t: float) -> None:
        """Set the load factor ``t`` and the prescribed boundary displacements ``t u_D``."""
        self.load.Set(t)
        for boundary, values in self.problem.displacements.items():
            region = self.mesh.Boundaries(boundary)
            for i, v in enumerate(values):
                if v is not None:
                    self.u.components[i].Set(t * v, ngs.BND, definedon=region)

    def Js_current(self) -> ngs.CoefficientFunction:
        return 1 + self.load * (self.Js - 1)

    def update_contact_multipliers(self) -> None:
        """Uzawa update ``lambda <- <lambda - r g>_+`` on each contact boundary."""
        for lam, z, region in zip(
            self.contact_multipliers, self._contact_z, self.contact_regions, strict=True
        ):
            lam.Set(contact_pressure_law(z, self.eps_c), ngs.BND, definedon=region)

    def multiplier_state(self) -> list[np.ndarray]:
        """A copy of every contact multiplier (to undo a failed step)."""
        state = [lam.vec.FV().NumPy().copy() for lam in self.contact_multipliers]
        return state + [pc.lam.copy() for pc in self.point_contacts]

    def restore_multipliers(self, state: list[np.ndarray]) -> None:
        n = len(self.contact_multipliers)
        for lam, v in zip(self.contact_multipliers, state[:n], strict=True):
            lam.vec.FV().NumPy()[:] = v
        for pc, v in zip(self.point_contacts, state[n:], strict=True):
            pc.lam = v.copy()

    def contact_pressure(self) -> ngs.CoefficientFunction:
        """Current contact pressure ``<lambda - r g>_+`` [kPa] (zero off contact)."""
        total = ngs.CF(0)
        for z, mask in zip(self._contact_z, self.contact_masks, strict=True):
            total = total + contact_pressure_law(z, self.eps_c) * mask
        for pc in self.point_contacts:
            total = total + pc.fields()[0]
        return total

    def gap(self) -> ngs.CoefficientFunction:
        """Signed distance to the obstacle on contact boundaries (large elsewhere) [length]."""
        total = ngs.CF(0)
        for g, mask in zip(self.contact_gaps, self.contact_masks, strict=True):
            total = total + ngs.IfPos(mask - 0.5, g, 0)
        for pc in self.point_contacts:
            total = total + pc.fields()[1]
        return total


def contact_pressure_law(z: ngs.CoefficientFunction, eps: float) -> ngs.CoefficientFunction:
    """Smoothed ramp ``s(z)``: 0 for z <= 0, ``z^2/(2 eps)`` up to ``eps``, ``z - eps/2`` above.

    A C1 contact law keeps the Newton tangent continuous when integration points enter or
    leave contact (a sharp ``<z>_+`` made the active set chatter at the opening's corners).
    """
    return ngs.IfPos(z, ngs.IfPos(z - eps, z - eps / 2, z * z / (2 * eps)), 0)


def contact_energy(z: ngs.CoefficientFunction, r: float, eps: float) -> ngs.CoefficientFunction:
    """Potential with ``d/dg = -s(z)`` for ``z = lambda - r g``: ``S(z)/r``, ``S' = s``."""
    S = ngs.IfPos(z, ngs.IfPos(z - eps, z * z / 2 - eps * z / 2 + eps**2 / 6, z**3 / (6 * eps)), 0)
    return S / r


def boundary_indicator(mesh: ngs.Mesh, pattern: str) -> ngs.CoefficientFunction:
    """1 on boundaries whose name matches the regex ``pattern``, 0 elsewhere."""
    import re

    rx = re.compile(f"^(?:{pattern})$")
    names = {b for b in mesh.GetBoundaries() if rx.match(b)}
    return mesh.BoundaryCF({b: 1.0 for b in names}, default=0.0)


def _pressure_zones(problem: Problem) -> list[str]:
    """Regex per group of regions with the same material and target swelling."""
    groups: dict[tuple, list[str]] = {}
    for region in sorted(set(problem.mesh.GetMaterials())):
        key = (repr(problem.materials[region]), float(problem.swelling.get(region, 1.0)))
        groups.setdefault(key, []).append(region)
    return ["|".join(re.escape(r) for r in regions) for regions in groups.values()]


def _mesh_size(mesh: ngs.Mesh) -> float:
    """A typical element size [length]: (volume / elements)^(1/dim) times a shape factor."""
    vol = ngs.Integrate(ngs.CF(1), mesh)
    return float((vol / mesh.ne) ** (1 / mesh.dim)) * (1.5 if mesh.dim == 2 else 2.0)


#: elements from which a natively compiled energy is split per pressure zone (see
#: :func:`split_energy`)
SPLIT_MIN_ELEMENTS = 200_000


def split_energy(elements: int, zones: int, native: bool) -> bool:
    """Whether to integrate the energy zone by zone, ``sum_z int_z psi + p_z (J - Js) dV``,
    instead of one expression with ``p = sum_z p_z``.

    NGSolve's ``Variation`` differentiates the energy twice with respect to every trial
    function it references: nine components of ``Grad u`` and one pressure per zone. Its
    tangent costs about the square of that count, so with the brain's four zones (13
    variables against 10 per zone) one expression took 42.6 s per tangent and the split
    31.8 s (1.54M tets, compiled; 2D hemidisk, interpreted: 72 -> 59 ms at 15k DOFs). Each
    split expression is compiled on its own, though
    (~6 s each without a cache hit, ~1.5 s with one), which pays only on large meshes; the
    interpreted (2D) energy has nothing to compile and is always split.
    """
    if zones < 2:
        return False
    return not native or elements >= SPLIT_MIN_ELEMENTS


def _compiled(W: ngs.CoefficientFunction, native: bool) -> ngs.CoefficientFunction:
    """``W`` compiled to NGSolve's expression code; with ``native`` to machine code by the
    C++ compiler (a one-off ~10 s that makes 3D assembly ~3.5x faster: 2.9 s -> 0.8 s per
    tangent on a 21k-tet brain), falling back to the expression code without a compiler.
    After :func:`brainbulge.runtime.configure` (the command line calls it) the compiler runs
    through ``ccache`` (:mod:`brainbulge.solver.compile_cache`, which also finds ``ngscxx``
    next to the interpreter): the same energy compiled again, by another scenario or run, is
    a cache hit."""
    if native and native_compiler_ready():
        try:
            return W.Compile(realcompile=True, wait=True)
        except Exception as exc:  # noqa: BLE001 - NGSolve raises its own types; keep running
            compilation_failed(str(exc).splitlines()[0] if str(exc) else type(exc).__name__)
    return W.Compile()

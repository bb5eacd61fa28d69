"""Mixed displacement-pressure formulation of the swelling, incompressible solid.

Stationary point of the Lagrangian (docs/model.md section 2) over ``(u, p)``::

    Pi(u, p) = int_Omega [ psibar(F) + p (J - Js(t)) ] dV

with ``Js(t) = 1 + t (Js - 1)`` the swelling ramped by the load factor ``t`` in [0, 1]. ``p``
is the Lagrange multiplier of ``J = Js`` (tension positive). Contact with the rigid skull is
frictionless and unilateral, with exact multipliers at the boundary's contact points
(:mod:`brainbulge.solver.contact`): their forces are added to the residual outside the
energy; or, in 2D, by a penalty in the energy (:mod:`brainbulge.solver.contact.penalty`).

NGSolve's ``Variation`` differentiates ``Pi`` symbolically: residual and tangent come exactly
from the energy. Inf-sup stable pairs: Taylor-Hood P2/P1 (2D and 3D) and MINI, P1 + bubble /
P1, with the bubbles condensed statically.
"""

from __future__ import annotations

import re

import ngsolve as ngs
import numpy as np

from brainbulge.errors import InputError
from brainbulge.materials.kinematics import deformation_gradient
from brainbulge.materials.mooney_rivlin import MooneyRivlin, mooney_rivlin_psi
from brainbulge.model.problem import Problem
from brainbulge.solver.compile_cache import compilation_failed, native_compiler_ready
from brainbulge.solver.contact.penalty import PenaltyContact
from brainbulge.solver.contact.points import PointContact

ELEMENTS = ("taylor-hood", "mini")


class MixedForm:
    """Spaces, unknowns and the symbolic energy of a :class:`Problem`."""

    def __init__(
        self,
        problem: Problem,
        element: str = "taylor-hood",
        compile_energy: bool = False,
    ) -> None:
        if element not in ELEMENTS:
            raise InputError(f"unknown element {element!r}; choose one of {', '.join(ELEMENTS)}")
        self.problem = problem
        self.element = element
        self.compile_energy = compile_energy
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
                W = compiled(self._psi_iso(F) + p_z * (J - Js_t), compile_energy)
                self.a += ngs.Variation(W * ngs.dx(definedon=mesh.Materials(zone)))
        else:  # one expression with p = sum_z p_z (each p_z is zero outside its zone)
            p = sum(ps[1:], ps[0])
            W = compiled(self._psi_iso(F) + p * (J - Js_t), compile_energy)
            self.a += ngs.Variation(W * ngs.dx)

        # contact: the skull's contact points, with exact multipliers (the active set)
        self.mu_max = max(m.shear_modulus for m in problem.materials.values())
        self.h = _mesh_size(mesh)
        self.point_contacts = [PointContact(self, c.boundary, c.obstacle)
                               for c in problem.contacts if c.penalty is None]
        # contact by a penalty in the energy (2D, :mod:`brainbulge.solver.contact.penalty`)
        self.penalty_contacts = [PenaltyContact(self, c.boundary, c.obstacle, c.penalty)
                                 for c in problem.contacts if c.penalty is not None]
        for pc in self.penalty_contacts:
            self.a += ngs.Variation(pc.energy(u) * pc.ds)

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
        return bool(self.point_contacts or self.penalty_contacts)

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

    def contact_pressure(self) -> ngs.CoefficientFunction:
        """Current contact pressure ``lambda |grad g|`` [kPa] at the contact points, as a
        boundary field (zero off contact)."""
        total = ngs.CF(0)
        for pc in self.point_contacts:
            total = total + pc.fields()[0]
        for pen in self.penalty_contacts:
            total = total + pen.pressure()
        return total

    def gap(self) -> ngs.CoefficientFunction:
        """Signed distance to the obstacle on contact boundaries (large elsewhere) [length]."""
        total = ngs.CF(0)
        for pc in self.point_contacts:
            total = total + pc.fields()[1]
        for pen in self.penalty_contacts:
            total = total + pen.gap()
        return total


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


def compiled(W: ngs.CoefficientFunction, native: bool) -> ngs.CoefficientFunction:
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

"""The hemidisk cases of docs/model.md sections 4-5 and 10 as :class:`Problem` s.

The base is clamped. A case symmetric about the axis (a sector under an opening centred at
90 deg) is solved on its half ``x >= 0`` with ``u_x = 0`` on the axis (boundary
``symmetry``) unless ``full_domain``. The skull is ``paper`` (the default) or ``rigid`` (an
extension).

``skull = "paper"``, the paper's model (its section 3), with the edge at the opening rounded
by ``skull_edge_radius`` (:class:`RigidSkull2D` given :data:`PAPER_SKULL_THICKNESS`):

- ``sliding``: the whole material arc, skull part and opening, in frictionless contact with
  the rounded skull by a penalty at its Gauss points (``Contact(..., penalty=kappa)``): the
  tissue slides along the skull, is released past the edge and turns outward round it;
- ``noslip``: ``u = 0`` on the skull arc ("the boundary nodes are fixed"); the opening in
  contact with the rounded skull.

With ``skull_edge_radius = 0`` the skull is the paper's sharp-edged arc (:class:`SkullArc2D`,
kept for comparison): no-slip leaves the opening traction-free; sliding holds the material
arc to ``r <= R`` on the whole circle by exact multipliers at its vertices (primal-dual
active set), also past the edge's angle (docs/design.md, "2D sliding at the paper's sharp
edge").

``skull = "rigid"``: a rigid shell of thickness ``skull_thickness`` with the same rounding
and the same contact as the rounded paper skull.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

from brainbulge.errors import InputError
from brainbulge.model.brain_case import SWELLING_RANGE  # target Js, as for the brain
from brainbulge.model.options import check_ranges, number, option, solver_fields

if TYPE_CHECKING:  # loaded on use: the command line's parser reads the case without NGSolve
    import ngsolve as ngs

    from brainbulge.geometry.hemidisk import Hemidisk
    from brainbulge.geometry.skull2d import RigidSkull2D, SkullArc2D
    from brainbulge.materials import MooneyRivlin
    from brainbulge.model.problem import Problem
    from brainbulge.solver.options import SolverOptions

CONTACTS = ("sliding", "noslip")
SKULLS = ("paper", "rigid")
ELEMENTS = ("mini", "taylor-hood")
#: target Js of a swelling sector (the paper's Figures 2-3) and of a swelling disk (its
#: Figure 4): the default of :attr:`HemidiskCase.swelling`
SECTOR_SWELLING = 1.2
DISK_SWELLING = 1.3
#: the rounded skull edge: the arc's mesh size there is the edge radius over this (the
#: active set cycles with the rounding unresolved, at rho on an h = 0.05 R mesh; rho/3 and
#: rho/5 converge; docs/design.md)
EDGE_MESH_RATIO = 3.0
#: the penalty's stiffness in units of the tissue's shear modulus over R: the skull is entered
#: by the contact pressure / kappa, 3.5e-5 to 8e-5 R at Js 1.2 (kappa = 1e7 for the paper's
#: gray matter at R = 1); a ten times softer one let the small openings' tissue 1e-2 R in
PENALTY = 3.0e4
#: the resolved edge's step control (ramp, newton options): each load step sized so that
#: the tissue at the edge slides about three edge elements, from the last converged state,
#: every Newton update capped at 0.4 of the smallest edge at a vertex (the best of the
#: variants measured, docs/design.md: the half domain's headline 73 -> 63 Newton
#: iterations against two elements and 0.3; a cap of 0.5 costs more)
RESOLVED_EDGE_STEPS = ({"slide": 3.0, "predictor": False}, {"step_cap": 0.4})
#: the paper's zero-thickness arc, rounded, is given this thickness [R]: no bulge reaches
#: its outer surface, and tissue pressing out past the rounding meets the end face
PAPER_SKULL_THICKNESS = 2.0
#: element sizes [units of R]: 0.005 R makes ~150,000 triangles (P2: hours of Newton); a
#: corner or rim size below 1e-4 R makes Netgen grade over 4 decades
MESH_SIZE_RANGE = (0.005, 1.0)
LOCAL_MESH_SIZE_MIN = 1e-4


@dataclass
class HemidiskCase:
    """One hemidisk run, a plain value that round-trips through TOML.

    Angles in degrees, lengths in units of ``R`` unless ``R`` is given otherwise. Each field
    is declared once with its default, unit, range and help (:func:`option`); the ranges are
    checked here, and the command line ``brainbulge hemidisk`` is built from these fields.
    """

    alpha: float | None = option(80.0, "swelling sector angle", unit=" deg", range=(1e-3, 180.0),
                                 label="sector angle alpha")
    beta: float = option(60.0, "opening angle", unit=" deg", range=(0.0, 180.0),
                         label="opening angle beta")
    opening_center: float = option(90.0, "angle of the opening's centre (90 = symmetry axis)",
                                   unit=" deg", range=(0.0, 180.0), label="opening centre")
    disk: list[float] | None = option(None, "a swelling disk instead of a sector",
                                      unit=" R", metavar=("CX", "CY", "RADIUS"))
    swelling: float | None = option(
        None, "target swelling Js of the sector or disk", range=SWELLING_RANGE,
        label="swelling Js", hint=f"{SECTOR_SWELLING:g} = {SECTOR_SWELLING - 1:.0%} swelling")
    contact: str = option("sliding", "contact of the tissue with the skull: frictionless "
                          "sliding or no-slip", choices=CONTACTS)
    skull: str = option(
        "paper", "paper: the paper's skull arc, its edge at the opening rounded by "
        "--skull-edge-radius (0: the paper's sharp edge, the opening traction-free); rigid: "
        "a rigid shell of finite thickness with rounded cut edges (an extension, "
        "docs/model.md)", choices=SKULLS)
    R: float = option(1.0, "hemidisk radius [length]", range=(1e-3, 1e4), label="radius R",
                      flag="--radius", hint="lengths scale with R: R = 1 is usual")
    mesh_size: float = option(0.05, "element size", unit=" R", range=MESH_SIZE_RANGE,
                              solver=True,
                              hint="smaller meshes take hours: 0.005 R is ~150,000 triangles")
    corner_mesh_size: float | None = option(
        None, "element size at the singular points (default mesh size / 5)", unit=" R",
        range=(LOCAL_MESH_SIZE_MIN, "mesh_size"), hint="at most the mesh size", solver=True)
    rim_mesh_size: float | None = option(
        None, "element size on the circles of radius edge exclusion around the singular "
        "points, where the max_*/min_* extremes sit (default mesh size / 10)", unit=" R",
        range=(LOCAL_MESH_SIZE_MIN, "mesh_size"), hint="at most the mesh size", solver=True)
    steps: int = option(4, "initial number of load steps", range=(1, 1000), solver=True)
    element: str = option(
        "taylor-hood", "Taylor-Hood (P2/P1) or MINI (P1 + bubble / P1). On the rounded edge "
        "Taylor-Hood runs all 32 sector scenarios, MINI stops sliding alpha 80 / beta 30 at "
        "load 0.94; on the sharp edge (--skull-edge-radius 0) take MINI: Taylor-Hood stops "
        "there", choices=ELEMENTS, solver=True)
    material: str = option("paper", "tissue preset: paper or paper-pa")
    tissue: str = option("gray", "tissue of the preset", internal=True)
    skull_thickness: float = option(0.2, "thickness of the rigid skull", unit=" R",
                                    internal=True)
    skull_edge_radius: float = option(
        0.03, "rounding radius of the skull's edge at the opening (0: the paper's sharp "
        "edge, the skull arc held, skull paper only); the arc is meshed at a third of it "
        "near the edge", unit=" R", range=(0.0, 0.1),
        hint="0.015-0.05 R measured (docs/verification.md)")
    edge_exclusion: float = option(
        0.05, "radius around the singular points left out of max_*/min_*", unit=" R",
        range=(0.0, 0.2), hint="beyond, max_*/min_* cover little")
    full_domain: bool = option(
        False, "solve a case symmetric about the axis (a sector under an opening centred at "
        "90 deg) on the whole hemidisk instead of its half x >= 0 with u_x = 0 on the axis "
        "(a check: the results are reported for the whole hemidisk either way)", solver=True)
    rezone: bool = option(True, "remesh through the deformation when the deformed mesh "
                          "degenerates or a load step fails (docs/design.md)", solver=True)
    name: str = option("hemidisk", "the run's name", internal=True)

    def __post_init__(self) -> None:
        if self.contact not in CONTACTS:
            raise InputError(f"contact {self.contact!r} unknown; choose 'sliding' or 'noslip'")
        if self.skull not in SKULLS:
            raise InputError(f"skull {self.skull!r} unknown; choose 'paper' (the paper's arc) "
                             "or 'rigid' (a rigid shell with rounded cut edges)")
        if self.skull == "rigid" and self.skull_edge_radius <= 0:
            raise InputError("the rigid skull needs a rounded cut edge: give "
                             "--skull-edge-radius > 0")
        if not isinstance(self.full_domain, bool):
            raise InputError(f"full_domain = {self.full_domain!r} must be true or false")
        if not isinstance(self.rezone, bool):
            raise InputError(f"rezone = {self.rezone!r} must be true or false")
        if self.disk is not None:
            if len(self.disk) != 3 or not all(isinstance(v, int | float) and math.isfinite(v)
                                              for v in self.disk):
                raise InputError(f"disk {self.disk} needs three finite numbers: CX CY RADIUS")
            number("disk radius", self.disk[2], 1e-3, 0.9, " R", hint="the swelling disk's size")
            self.alpha = None  # a disk replaces the default sector
        if self.swelling is None:
            self.swelling = DISK_SWELLING if self.disk is not None else SECTOR_SWELLING
        check_ranges(self)

    @property
    def geometry(self) -> Hemidisk:
        from brainbulge.geometry.hemidisk import Hemidisk

        disk = tuple(self.disk) if self.disk is not None else None
        return Hemidisk(
            R=self.R,
            alpha_deg=self.alpha,
            beta_deg=self.beta,
            opening_center_deg=self.opening_center,
            disk=disk,  # type: ignore[arg-type]
            half=self.half,
        )

    @property
    def half(self) -> bool:
        """Whether the case is solved on the half hemidisk ``x >= 0``: when it is symmetric
        about the axis (a sector, the opening centred at 90 deg) and not ``full_domain``."""
        return (not self.full_domain and self.disk is None
                and (self.beta == 0 or self.opening_center == 90))

    @property
    def corner_h(self) -> float:
        """Element size at the singular points [length] (default a fifth of the mesh size)."""
        if self.corner_mesh_size is not None:
            return self.corner_mesh_size * self.R
        return self.mesh_size * self.R / 5

    @property
    def rim_h(self) -> float | None:
        """Element size on the rims of the edge-exclusion disks [length] (default a tenth of
        the mesh size; None without edge exclusion)."""
        if self.edge_exclusion <= 0:
            return None
        if self.rim_mesh_size is not None:
            return self.rim_mesh_size * self.R
        return self.mesh_size * self.R / 10

    @property
    def rounded(self) -> bool:
        """Whether the skull's edge is rounded (``skull_edge_radius > 0``): the contact is
        then one penalty on the whole arc against the rounded skull, on a mesh resolved at
        the edge, with the resolved edge's step control (:data:`RESOLVED_EDGE_STEPS`)."""
        return self.skull_edge_radius > 0

    @property
    def edge_h(self) -> float | None:
        """Element size along the arc at the opening's edges [length]: the edge radius over
        :data:`EDGE_MESH_RATIO` (None for the sharp edge)."""
        return self.skull_edge_radius * self.R / EDGE_MESH_RATIO if self.rounded else None

    def mesh(self) -> ngs.Mesh:
        """The reference mesh: ``mesh_size``, ``corner_h`` at the singular points,
        ``rim_h`` on the rims of the edge-exclusion disks, where ``max_*`` / ``min_*`` sit,
        and ``edge_h`` along the arc at the opening's edges."""
        return self.geometry.mesh(
            self.mesh_size * self.R, self.corner_h, self.rim_h, self.edge_exclusion * self.R,
            self.edge_h,
        )

    @property
    def skull_arc(self) -> SkullArc2D:
        """The paper's skull: the arc ``r = R`` outside the opening."""
        from brainbulge.geometry.skull2d import SkullArc2D

        return SkullArc2D(R=self.R, beta_deg=self.beta, center_deg=self.opening_center)

    @property
    def rigid_skull(self) -> RigidSkull2D:
        """The skull with its edge rounded: the ``rigid`` skull's shell, or the paper's arc
        given :data:`PAPER_SKULL_THICKNESS` (beyond any bulge) so that tissue pressing out
        past the rounding meets the bone's end face."""
        from brainbulge.geometry.skull2d import RigidSkull2D

        thickness = self.skull_thickness if self.skull == "rigid" else PAPER_SKULL_THICKNESS
        return RigidSkull2D(
            R=self.R,
            beta_deg=self.beta,
            center_deg=self.opening_center,
            thickness=thickness * self.R,
            edge_radius=self.skull_edge_radius * self.R,
        )

    @property
    def obstacle(self) -> SkullArc2D | RigidSkull2D:
        """The skull the tissue is in contact with: the rounded skull, or the paper's
        sharp-edged arc (``skull_edge_radius = 0``)."""
        return self.rigid_skull if self.rounded else self.skull_arc

    def contact_stiffness(self) -> float:
        """The penalty's stiffness ``kappa = PENALTY mu / R`` [stress/length]
        (:data:`PENALTY`)."""
        return PENALTY * self.tissue_material().shear_modulus / self.R

    def solver_options(self, progress: bool = False) -> SolverOptions:
        """The solver's options for this case: its ``steps``, and on a rounded edge the
        resolved edge's step control (:data:`RESOLVED_EDGE_STEPS`)."""
        from dataclasses import replace

        from brainbulge.solver.options import SolverOptions

        options = SolverOptions(steps=self.steps, progress=progress)
        if not self.rounded:
            return options
        ramp, newton = RESOLVED_EDGE_STEPS
        return SolverOptions(ramp=replace(options.ramp, **ramp),
                             newton=replace(options.newton, **newton), progress=progress)

    def tissue_material(self) -> MooneyRivlin:
        from brainbulge.materials import preset

        mats = preset(self.material)
        if self.tissue not in mats:
            raise InputError(f"tissue {self.tissue!r} not in preset {self.material!r}")
        return mats[self.tissue]


def hemidisk_problem(case: HemidiskCase, mesh: ngs.Mesh | None = None) -> Problem:
    """Mesh the hemidisk (or take ``mesh``, e.g. a rezoned one) and set materials, swelling
    and the contact condition."""
    from brainbulge.model.problem import Contact, Problem

    skull = case.obstacle
    if mesh is None:
        mesh = case.mesh()
    m = case.tissue_material()
    materials = {r: m for r in set(mesh.GetMaterials())}
    swelling = {"swelling": case.swelling}
    mirror = {0: "symmetry"} if case.half else {}  # u_x = 0 on the axis
    if case.rounded:  # one penalty contact on the whole arc against the rounded skull
        kappa = case.contact_stiffness()
        if case.contact == "noslip":
            opening = [Contact("opening", skull, kappa)] if case.beta > 0 else []
            return Problem(mesh, materials, swelling, clamped="base|skull",
                           clamped_components=mirror, contacts=opening)
        return Problem(mesh, materials, swelling, clamped="base", clamped_components=mirror,
                       contacts=[Contact("skull|opening", skull, kappa)])
    if case.contact == "noslip":
        opening = []  # the paper's opening is traction-free and meets no obstacle
        if case.skull == "rigid" and case.beta > 0:
            opening = [Contact("opening", skull)]
        return Problem(mesh, materials, swelling, clamped="base|skull",
                       clamped_components=mirror, contacts=opening)
    sliding = "skull" if case.skull == "paper" else "skull|opening"
    return Problem(
        mesh, materials, swelling, clamped="base", clamped_components=mirror,
        contacts=[Contact(sliding, skull)],
    )


#: the fields of :class:`HemidiskCase` that say how it is discretised and solved (the
#: ``[solver]`` table of a run file); the others say what is simulated (``[case]``)
SOLVER_FIELDS = solver_fields(HemidiskCase)

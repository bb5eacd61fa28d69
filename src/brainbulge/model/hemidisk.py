"""The hemidisk cases of docs/model.md sections 4-5 as :class:`Problem` s.

The base is clamped. The skull is ``paper`` (the default) or ``rigid`` (an extension).

``skull = "paper"``, the paper's model (its section 3): the skull is the arc ``r = R`` outside
the opening, of zero thickness with a sharp edge (:class:`SkullArc2D`); the opening arc is
traction-free and meets no obstacle.

- ``noslip``: ``u = 0`` on the skull arc ("the boundary nodes are fixed");
- ``sliding``: the skull arc's boundary slides without friction on the circle ``r = R`` over
  the skull's angular extent, may separate inward, and is released once it passes the edge
  (unilateral contact with :class:`SkullArc2D`), so the tissue "rotates outward around the
  opening edge".

``skull = "rigid"``, an extension: a rigid shell of thickness ``skull_thickness`` with cut
edges rounded by ``skull_edge_radius`` (:class:`RigidSkull2D`), the rounding in the bone.

- ``noslip``: ``u = 0`` on the skull part of the arc; the opening part is free but cannot
  enter the shell's cut faces (frictionless unilateral contact);
- ``sliding``: frictionless unilateral contact of the whole arc (skull part and opening) with
  the shell, so tissue slides along it and bulges around the rounded cut edges. Known limit:
  with small openings and large swelling regions (alpha 60-80, beta 30) the tissue pressed
  around the rounding is squeezed in a layer one element thick and the ramp stops
  (docs/known-limits.md).

Contact is frictionless, with exact contact pressures at the boundary nodes by a primal-dual
active set.
"""

from __future__ import annotations

from dataclasses import dataclass

import ngsolve as ngs

from brainbulge.errors import InputError
from brainbulge.geometry.hemidisk import Hemidisk
from brainbulge.geometry.skull2d import RigidSkull2D, SkullArc2D
from brainbulge.materials import MooneyRivlin, preset
from brainbulge.model.problem import Contact, Problem

CONTACTS = ("sliding", "noslip")
SKULLS = ("paper", "rigid")

#: the fields of :class:`HemidiskCase` that say how it is discretised and solved (the
#: ``[solver]`` table of a run file); the others say what is simulated (``[case]``)
SOLVER_FIELDS = ("mesh_size", "corner_mesh_size", "rim_mesh_size", "steps", "element",
                 "rezone", "contact_method")


@dataclass
class HemidiskCase:
    """One hemidisk run, a plain value that round-trips through TOML.

    Angles in degrees, lengths in units of ``R`` unless ``R`` is given otherwise.
    """

    alpha: float | None = 80.0
    beta: float = 60.0
    opening_center: float = 90.0
    disk: list[float] | None = None
    swelling: float = 1.2
    contact: str = "sliding"
    skull: str = "paper"
    R: float = 1.0
    mesh_size: float = 0.05
    corner_mesh_size: float | None = None
    rim_mesh_size: float | None = None
    steps: int = 4
    element: str = "mini"
    material: str = "paper"
    tissue: str = "gray"
    skull_thickness: float = 0.2
    skull_edge_radius: float = 0.05
    edge_exclusion: float = 0.05
    rezone: bool = True
    name: str = "hemidisk"

    def __post_init__(self) -> None:
        if self.contact not in CONTACTS:
            raise InputError(f"contact {self.contact!r} unknown; choose 'sliding' or 'noslip'")
        if self.skull not in SKULLS:
            raise InputError(f"skull {self.skull!r} unknown; choose 'paper' (the paper's arc) "
                             "or 'rigid' (a rigid shell with rounded cut edges)")
        import math

        if not isinstance(self.swelling, (int, float)) or not math.isfinite(self.swelling):
            raise InputError(f"swelling Js = {self.swelling!r} must be a number")
        if self.swelling <= 0:
            raise InputError(f"swelling Js = {self.swelling} must be positive (1.2 = 20% swelling)")
        if not isinstance(self.rezone, bool):
            raise InputError(f"rezone = {self.rezone!r} must be true or false")
        if self.edge_exclusion < 0:
            raise InputError(f"edge exclusion {self.edge_exclusion} must be >= 0")
        for name in ("corner_mesh_size", "rim_mesh_size"):
            value = getattr(self, name)
            if value is not None and not (math.isfinite(value) and value > 0):
                raise InputError(f"{name.replace('_', ' ')} {value} must be a positive number")
        if self.disk is not None and self.alpha is not None:
            self.alpha = None  # a disk replaces the default sector

    @property
    def geometry(self) -> Hemidisk:
        disk = tuple(self.disk) if self.disk is not None else None
        if disk is not None and len(disk) != 3:
            raise InputError("disk needs three numbers: CX CY RADIUS")
        return Hemidisk(
            R=self.R,
            alpha_deg=self.alpha,
            beta_deg=self.beta,
            opening_center_deg=self.opening_center,
            disk=disk,  # type: ignore[arg-type]
        )

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

    def mesh(self) -> ngs.Mesh:
        """The reference mesh: ``mesh_size``, ``corner_h`` at the singular points and
        ``rim_h`` on the rims of the edge-exclusion disks, where ``max_*`` / ``min_*`` sit."""
        return self.geometry.mesh(
            self.mesh_size * self.R, self.corner_h, self.rim_h, self.edge_exclusion * self.R
        )

    @property
    def skull_arc(self) -> SkullArc2D:
        """The paper's skull: the arc ``r = R`` outside the opening."""
        return SkullArc2D(R=self.R, beta_deg=self.beta, center_deg=self.opening_center)

    @property
    def rigid_skull(self) -> RigidSkull2D:
        """The rigid shell of the ``rigid`` skull (its parameters are checked for either)."""
        return RigidSkull2D(
            R=self.R,
            beta_deg=self.beta,
            center_deg=self.opening_center,
            thickness=self.skull_thickness * self.R,
            edge_radius=self.skull_edge_radius * self.R,
        )

    @property
    def obstacle(self) -> SkullArc2D | RigidSkull2D:
        """The skull the tissue is in contact with: the paper's arc or the rigid shell."""
        return self.skull_arc if self.skull == "paper" else self.rigid_skull

    def tissue_material(self) -> MooneyRivlin:
        mats = preset(self.material)
        if self.tissue not in mats:
            raise InputError(f"tissue {self.tissue!r} not in preset {self.material!r}")
        return mats[self.tissue]


def hemidisk_problem(case: HemidiskCase, mesh: ngs.Mesh | None = None) -> Problem:
    """Mesh the hemidisk (or take ``mesh``, e.g. a rezoned one) and set materials, swelling
    and the contact condition."""
    skull = case.obstacle
    if mesh is None:
        mesh = case.mesh()
    m = case.tissue_material()
    materials = {r: m for r in set(mesh.GetMaterials())}
    swelling = {"swelling": case.swelling}
    if case.contact == "noslip":
        opening = []  # the paper's opening is traction-free and meets no obstacle
        if case.skull == "rigid" and case.beta > 0:
            opening = [Contact("opening", skull)]
        return Problem(mesh, materials, swelling, clamped="base|skull", contacts=opening)
    sliding = "skull" if case.skull == "paper" else "skull|opening"
    return Problem(
        mesh, materials, swelling, clamped="base",
        contacts=[Contact(sliding, skull)],
    )

"""Case C of docs/model.md section 6: white-matter swelling in a personalised brain (3D).

The labelled brain mesh (:mod:`brainbulge.geometry.brain`, lengths in mm) carries regions
``"{tissue}_{side}"`` (gray, white, csf, cerebellum, brainstem; left, right). Every region is
an incompressible Mooney-Rivlin solid with the parameters of docs/model.md section 2 (the
brainstem, absent from the paper's table, takes the cerebellum's), bonded to its neighbours.
The inferior surface ``base`` is fixed, and with ``fix = "inferior+superior"`` (default,
the paper's Figure 6) also the ``superior`` band of the outer CSF surface along the superior
midline (:class:`~brainbulge.geometry.brain.boundaries.SuperiorBand`); the rest of the outer
surface, ``skull``, slides without friction on the rigid skull (:class:`RigidSkull`,
evaluated at the deformed position); the ``flap`` is traction-free where it does not touch
the bone (in contact with the same skull, whose rounded cut edge overhangs the opening's rim;
a flap that crosses the superior band wins there). White matter swells, ``Js: 1 ->
swelling``, in the left hemisphere, the right, or both.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from brainbulge.errors import InputError
from brainbulge.geometry.brain import BrainMesh, to_ngsolve
from brainbulge.geometry.brain.boundaries import UNILATERAL_DIAMETER_MM, SuperiorBand
from brainbulge.geometry.brain.defaults import (
    FIXATIONS,
    LARGE_TETS,
    SUPERIOR_ELEVATION_DEG,
    SUPERIOR_WIDTH_MM,
    VOLUME_OF,
)
from brainbulge.geometry.brain.skull import EDGE_RADIUS_MM
from brainbulge.materials import MooneyRivlin, preset
from brainbulge.model.problem import Contact, Problem

FLAPS = ("frontal", "left", "right", "custom", "none")
SWELL_SIDES = {"both": ("left", "right"), "left": ("left",), "right": ("right",)}



def size_defaults(tets: int, refine: int | None = None, coarse_tets: int | None = None,
                  linear_solver: str | None = None,
                  mesh_given: bool = False) -> tuple[int, int | None, str]:
    """``(refine, coarse_tets, linear_solver)`` for a mesh of about ``tets`` tets; each
    argument given (not None) is kept as it is.

    From :data:`LARGE_TETS` up: Netgen at ``tets / 8``, refined once (``refine = 1``), the
    load ramped on the fine mesh and GMRES with AMG blocks (``krylov``); below it: one
    Netgen mesh, PARDISO. Mesh sequencing (``coarse_tets``) only when asked for: on the
    1.40M-tet template the fine stage did not converge from a coarse state (from a separate
    100k-tet mesh, nor from the nested 175k one) and then ramped anyway, so sequencing cost
    38.7 minutes and 17.4 GB against the ramp's 17 minutes and 12.5 GB (docs/performance.md).
    ``coarse_tets = 0`` is the same as None. A mesh read from a file (``mesh_given``) is not
    refined unless asked.
    """
    large = tets >= LARGE_TETS and not mesh_given
    if refine is None:
        refine = 1 if large else 0
    if linear_solver is None:
        linear_solver = "krylov" if large else "pardiso"
    return refine, coarse_tets or None, linear_solver


#: tissue -> row of the material table used for it
TISSUE_MATERIAL = {
    "gray": "gray",
    "white": "white",
    "csf": "csf",
    "cerebellum": "cerebellum",
    "brainstem": "cerebellum",
}

#: the fields of :class:`CraniectomyCase` that say how it is discretised and solved (the
#: ``[solver]`` table of a run file); the others say what is simulated (``[case]``)
SOLVER_FIELDS = ("tets", "refine", "element", "linear_solver", "steps", "tolerance",
                 "compile", "coarse_tets", "coarse_mesh")


@dataclass
class CraniectomyCase:
    """One 3D scenario: which flap is open, which white matter swells, and how.

    Attributes:
        flap: ``frontal``, ``left``, ``right``, ``custom`` (needs ``flap_centre_mm``) or
            ``none`` (intact skull: infeasible with swelling, reported as such).
        swell: white matter that swells: ``both``, ``left`` or ``right`` hemisphere.
        swelling: target ``Js`` [-] (the paper: 1.1).
        tets: about how many tetrahedra when the mesh is built here.
        mesh: a ``brain.npz`` written by ``brainbulge mesh`` (overrides ``tets``).
        labels, label_map: a NIfTI segmentation and its label map (default: ICBM152).
        brain_volume_ml: scale the geometry so that the volume ``volume_of`` names is this [ml].
        volume_of: ``intracranial`` (all tissue incl. CSF), ``brain`` (cerebral gray + white
            matter) or ``white`` (white matter).
        flap_centre_mm, flap_diameter_mm: a custom flap on the skull [mm].
        fibres: a 4D NIfTI (nx, ny, nz, 3) of axon directions (e.g. DTI V1) in world axes;
            ``lambda_n`` and ``lambda_t`` use them instead of the radial direction.
        material: material preset (``paper`` or ``paper-pa``).
        element: ``mini`` (P1 + bubble / P1) or ``taylor-hood`` (P2 / P1).
        linear_solver: ``pardiso`` (direct) or ``krylov`` (GMRES + AMG blocks, for large
            meshes; with Taylor-Hood a two-level cycle on the P2 block); None: from the size
            (:func:`size_defaults`, as ``refine`` and ``coarse_tets``).
        steps: initial load steps.
        tolerance: Newton's stopping tolerance at full load, on the scaled residual (force /
            (mu L^2), volume / |Omega|; :class:`~brainbulge.solver.SolverOptions`) [-].
        compile: compile the energy to machine code (a one-off ~10 s; assembly ~3.5x faster).
        edge_radius_mm: radius of the rounded cut edge of the skull at the flap [mm].
        edge_exclusion_mm: band around the flap rim left out of ``max_*`` outputs [mm].
        fix: the fixed part of the outer surface: ``inferior`` (the base) or
            ``inferior+superior`` (and the band along the superior midline).
        superior_width_mm, superior_elevation_deg: the superior band's width across the
            mid-sagittal plane [mm] and its lowest elevation seen from the brain centre [deg].
        coarse_tets: mesh sequencing (:mod:`brainbulge.solver.remesh.sequencing`): ramp the load
            first on a mesh of about this many tets of the same geometry, then start the fine
            mesh's Newton at full load from its solution (MINI only; fewer fine iterations);
            0: none.
        coarse_mesh: the same with a ``brain.npz`` as the coarse mesh (with ``mesh``).
        refine: build the mesh at about ``tets / 8**refine`` tets and refine it uniformly
            ``refine`` times (new surface nodes on the skull's inner surface). With
            ``coarse_tets = tets / 8**refine`` the coarse mesh of sequencing is the unrefined
            one: the meshes are nested and the coarse solution carries over exactly.
        name: label of the scenario.
        extra: what a planner records about the case (``brainbulge plan``: the candidate
            centre's index and side, its point on the skull, why a flap was refused); not
            read by the simulation.
    """

    flap: str = "left"
    swell: str = "both"
    swelling: float = 1.1
    tets: int = 30_000
    mesh: str | None = None
    labels: str | None = None
    label_map: str = "synthseg"
    brain_volume_ml: float | None = None
    volume_of: str = "intracranial"
    flap_centre_mm: tuple[float, float, float] | None = None
    flap_diameter_mm: float | None = None
    fibres: str | None = None
    material: str = "paper"
    element: str = "mini"
    linear_solver: str | None = None
    steps: int = 4
    tolerance: float = 1e-9
    compile: bool = True
    edge_radius_mm: float = EDGE_RADIUS_MM
    edge_exclusion_mm: float = 5.0
    fix: str = "inferior+superior"
    superior_width_mm: float = SUPERIOR_WIDTH_MM
    superior_elevation_deg: float = SUPERIOR_ELEVATION_DEG
    coarse_tets: int | None = None
    coarse_mesh: str | None = None
    refine: int | None = None
    name: str = ""
    extra: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.flap not in FLAPS:
            raise InputError(f"unknown flap {self.flap!r}; choose one of {', '.join(FLAPS)}")
        if self.flap == "custom" and self.flap_centre_mm is None and self.mesh is None:
            raise InputError("a custom flap needs its centre: --flap-centre X Y Z (mm)")
        if self.swell not in SWELL_SIDES:
            raise InputError(
                f"unknown swelling side {self.swell!r}; choose one of {', '.join(SWELL_SIDES)}"
            )
        if not (isinstance(self.swelling, (int, float)) and 0.5 <= self.swelling <= 2.0):
            raise InputError(f"swelling Js = {self.swelling!r} must lie in [0.5, 2] (paper: 1.1)")
        if not (isinstance(self.tets, int) and 1_000 <= self.tets <= 5_000_000):
            raise InputError(f"tets = {self.tets!r} must be a whole number in [1000, 5000000]")
        self.refine, self.coarse_tets, self.linear_solver = size_defaults(
            self.tets, self.refine, self.coarse_tets, self.linear_solver,
            self.mesh is not None)
        if self.linear_solver not in ("pardiso", "krylov"):
            raise InputError(f"linear solver {self.linear_solver!r}: choose pardiso or krylov")
        if not isinstance(self.steps, int) or self.steps < 1:
            raise InputError(f"steps = {self.steps!r} must be a positive integer")
        if not (isinstance(self.tolerance, (int, float)) and 0 < self.tolerance <= 1e-3):
            raise InputError(f"tolerance = {self.tolerance!r} must lie in (0, 1e-3] (default 1e-9)")
        if self.element not in ("mini", "taylor-hood"):
            raise InputError(f"unknown element {self.element!r}; choose mini or taylor-hood")
        tissue_materials(self.material)  # an unknown preset fails here, before any meshing
        if not 0 < self.edge_radius_mm <= 10:
            raise InputError(f"edge radius {self.edge_radius_mm} mm must lie in (0, 10]")
        if not 0 <= self.edge_exclusion_mm <= 50:
            raise InputError(f"edge exclusion {self.edge_exclusion_mm} mm must lie in [0, 50]")
        if self.volume_of not in VOLUME_OF:
            raise InputError(f"unknown volume_of {self.volume_of!r}; choose one of "
                             f"{', '.join(VOLUME_OF)}")
        if self.fix not in FIXATIONS:
            raise InputError(f"unknown fixation {self.fix!r}; choose one of "
                             f"{', '.join(FIXATIONS)}")
        self.superior_band()  # a bad width or elevation fails here
        if self.mesh is not None and not Path(self.mesh).exists():
            raise InputError(f"brain mesh {self.mesh} does not exist; build one with "
                             "`brainbulge mesh --out DIR` and pass DIR/brain.npz")
        if self.mesh is not None:
            # a custom flap is a boundary condition: it opens on the given mesh
            custom = self.flap == "custom"
            geometry = {"--labels": self.labels, "--brain-volume": self.brain_volume_ml,
                        "--volume-of": None if self.volume_of == "intracranial" else self.volume_of,
                        "--flap-centre": None if custom else self.flap_centre_mm,
                        "--flap-diameter": None if custom else self.flap_diameter_mm,
                        "--label-map": None if self.label_map == "synthseg" else self.label_map}
            given = [k for k, v in geometry.items() if v is not None]
            if given:
                raise InputError(
                    f"--mesh fixes the geometry, so {', '.join(given)} would be ignored; drop "
                    "them, or build a mesh with them by `brainbulge mesh` and pass that")
        if not (isinstance(self.refine, int) and 0 <= self.refine <= 3):
            raise InputError(f"refine = {self.refine!r} must be 0, 1, 2 or 3")
        if self.refine and self.mesh is not None:
            raise InputError("--refine applies to a mesh built here, not to --mesh: build a "
                             "refined one with `brainbulge mesh --refine` and pass that")
        self._check_sequencing()
        if self.fibres is not None and not Path(self.fibres).is_file():
            raise InputError(f"fibre image {self.fibres} does not exist")
        if not self.name:
            self.name = f"{self.flap}-flap_{self.swell}-swelling"

    @property
    def nested_coarse(self) -> bool:
        """The coarse mesh of sequencing is the Netgen mesh that the fine one refines
        (``coarse_tets = tets // 8**refine``): built once, no second Netgen run."""
        return (self.mesh is None and bool(self.refine) and self.coarse_tets is not None
                and self.coarse_tets == self.tets // 8**self.refine)

    def superior_band(self) -> SuperiorBand | None:
        """The fixed superior band, or None with ``fix = "inferior"``."""
        band = SuperiorBand(self.superior_width_mm, self.superior_elevation_deg)
        return band if self.fix == "inferior+superior" else None

    def _check_sequencing(self) -> None:
        if self.coarse_tets is None and self.coarse_mesh is None:
            return
        if self.element != "mini":
            raise InputError("mesh sequencing (--coarse-tets, --coarse-mesh) needs --element "
                             "mini")
        if self.coarse_tets is not None and self.coarse_mesh is not None:
            raise InputError("give --coarse-tets or --coarse-mesh, not both")
        if self.coarse_mesh is not None and not Path(self.coarse_mesh).exists():
            raise InputError(f"coarse brain mesh {self.coarse_mesh} does not exist; build one "
                             "with `brainbulge mesh --tets N --out DIR` and pass DIR/brain.npz")
        if self.coarse_tets is not None:
            if self.mesh is not None:
                raise InputError("--coarse-tets builds the coarse mesh from the geometry "
                                 "inputs, which --mesh fixes: pass --coarse-mesh instead")
            if not (isinstance(self.coarse_tets, int) and 1_000 <= self.coarse_tets < self.tets):
                raise InputError(f"coarse_tets = {self.coarse_tets!r} must be a whole number "
                                 f"in [1000, tets = {self.tets})")


def brain_mesh_for(case: CraniectomyCase) -> BrainMesh:
    """Load or build the labelled brain mesh of ``case``."""
    from brainbulge.geometry.brain import (
        build_brain_mesh,
        load_brain_mesh,
        load_tissue_image,
    )

    if case.mesh is not None:
        path = Path(case.mesh)
        bm = load_brain_mesh(path / "brain.npz" if path.is_dir() else path)
        if case.flap == "custom" and case.flap_centre_mm is not None:
            open_custom_flap(bm, case)
    else:
        image = load_tissue_image(case.labels, case.label_map) if case.labels else None
        kwargs = {}
        if case.flap_centre_mm is not None:
            kwargs["custom_flap_centre_mm"] = tuple(case.flap_centre_mm)
            if case.flap_diameter_mm is not None:
                kwargs["custom_flap_diameter_mm"] = case.flap_diameter_mm
        bm = build_brain_mesh(image, target_tets=case.tets,
                              brain_volume_ml=case.brain_volume_ml, volume_of=case.volume_of,
                              refinements=case.refine,
                              keep_unrefined=case.nested_coarse, **kwargs)
    if case.flap != "none" and case.flap not in bm.flaps:
        raise InputError(f"flap {case.flap!r} is not defined on this mesh (it has "
                         f"{', '.join(sorted(bm.flaps))}); rebuild it with the flap's centre")
    return bm


def open_custom_flap(bm: BrainMesh, case: CraniectomyCase) -> None:
    """Open the case's custom flap (``flap_centre_mm``, ``flap_diameter_mm``, default 120
    mm) on the loaded mesh ``bm`` as ``bm.flaps["custom"]``, by the fitting rule of
    :mod:`brainbulge.geometry.brain.flap_fit` (refused if it reaches the fixed base or
    crosses the midline, clipped at the fixed superior band); the mesh is not rebuilt."""
    from brainbulge.geometry.brain.flap_fit import attach_flap, fit_flap

    diameter = case.flap_diameter_mm or UNILATERAL_DIAMETER_MM
    attach_flap(bm, fit_flap(bm, case.flap_centre_mm, diameter, case.superior_band()))


def coarse_brain_mesh_for(case: CraniectomyCase, fine: BrainMesh | None = None
                          ) -> BrainMesh | None:
    """The coarse mesh of mesh sequencing (``coarse_tets`` or ``coarse_mesh``), or None;
    the ``unrefined`` mesh of ``fine`` when the two are nested (``case.nested_coarse``)."""
    if case.coarse_tets is None and case.coarse_mesh is None:
        return None
    if case.nested_coarse and fine is not None and fine.unrefined is not None:
        return fine.unrefined
    if case.coarse_mesh is not None:
        coarse = replace(case, mesh=case.coarse_mesh, coarse_mesh=None)
    else:
        coarse = replace(case, tets=case.coarse_tets, coarse_tets=None, refine=0)
    return brain_mesh_for(coarse)


def tissue_materials(material: str) -> dict[str, MooneyRivlin]:
    """Tissue name -> material of the preset (brainstem as cerebellum)."""
    table = preset(material)
    return {t: table[m] for t, m in TISSUE_MATERIAL.items()}


def brain_problem(bm: BrainMesh, case: CraniectomyCase) -> Problem:
    """The NGSolve problem of ``case`` on the brain mesh ``bm``."""
    flap = None if case.flap == "none" else case.flap
    band = case.superior_band()
    mesh = to_ngsolve(bm, flap=flap, superior=band)
    by_tissue = tissue_materials(case.material)
    materials = {}
    for region in set(mesh.GetMaterials()):
        tissue = region.rsplit("_", 1)[0]
        if tissue not in by_tissue:
            raise InputError(f"mesh region {region!r} has no tissue material")
        materials[region] = by_tissue[tissue]
    swelling = {
        f"white_{side}": float(case.swelling)
        for side in SWELL_SIDES[case.swell]
        if f"white_{side}" in materials
    }
    if not swelling:
        raise InputError("the mesh has no white matter on the swelling side; check the labels")
    skull = bm.skull(flap, edge_radius_mm=case.edge_radius_mm)
    clamped = "base" if band is None else "base|superior"
    # the flap is traction-free but may not pass into the bone: its rounded cut edge lies
    # over the opening's rim (up to edge_radius_mm inside the cutter)
    return Problem(mesh, materials, swelling, clamped=clamped,
                   contacts=[Contact("skull|flap", skull)])


def white_matter_volume_ml(bm: BrainMesh, sides: tuple[str, ...]) -> float:
    """Reference volume of the white matter on ``sides`` [ml]."""
    vols = bm.region_volumes_ml()
    return float(np.sum([vols.get(f"white_{s}", 0.0) for s in sides]))

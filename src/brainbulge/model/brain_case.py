"""The 3D craniectomy case (docs/model.md section 6) as a plain value: its options, each
declared once with default, unit, range and help (:func:`~brainbulge.model.options.option`).

``brainbulge brain``, ``brainbulge study craniectomy``, ``brainbulge plan`` and the run
files take their options, defaults, ranges and help from :class:`CraniectomyCase`; the case
checks them (:func:`~brainbulge.model.options.check_ranges`). Light: the command line's parser
reads it without the meshing stack or NGSolve (the problem is built by
:mod:`brainbulge.model.brain`).
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from brainbulge.errors import InputError
from brainbulge.geometry.brain.defaults import (
    BRAIN_VOLUME_RANGE_ML,
    EDGE_RADIUS_MM,
    EDGE_RADIUS_RANGE_MM,
    FIXATIONS,
    FLAP_DIAMETER_RANGE_MM,
    LARGE_TETS,
    SUPERIOR_ELEVATION_DEG,
    SUPERIOR_ELEVATION_RANGE_DEG,
    SUPERIOR_WIDTH_MM,
    SUPERIOR_WIDTH_RANGE_MM,
    UNILATERAL_DIAMETER_MM,
    VOLUME_OF,
)
from brainbulge.model.options import check_ranges, option, solver_fields

if TYPE_CHECKING:  # loaded on use: the parser reads the case without the meshing stack
    from brainbulge.geometry.brain.boundaries import SuperiorBand

FLAPS = ("frontal", "left", "right", "custom", "none")
SWELL_SIDES = {"both": ("left", "right"), "left": ("left",), "right": ("right",)}
ELEMENTS = ("mini", "taylor-hood")
LINEAR_SOLVERS = ("pardiso", "krylov")
#: target Js of the white matter (the paper: 1.1); the hemidisk's range too
SWELLING_RANGE = (0.5, 2.0)
#: tets of a brain mesh: more than 5 million need more memory than a workstation has
TETS_RANGE = (1_000, 5_000_000)
#: the coarsest mesh Netgen makes of the ICBM152 template: below ~25,000 target tets it
#: gives up ("too many trials") and retries for minutes (measured: 5,000 and 10,000 did not
#: finish in 5 minutes)
TEMPLATE_TETS_MIN = 25_000
#: the template's labelled volume [ml] (all tissues of ``icbm152_tissue_image``)
TEMPLATE_LABELLED_ML = 1883.0
#: a user's segmentation (``--labels``): target tets per ml of labelled tissue before
#: refinement. Netgen's trouble depends on the element size in mm against a brain's mm-scale
#: surface, so the template's densities carry over: below 10,000 tets (5.3 per ml) it gave up
#: on the template, from 25,000 (13.3 per ml) it meshes; in between a warning.
LABELS_TETS_PER_ML = (10_000 / TEMPLATE_LABELLED_ML, TEMPLATE_TETS_MIN / TEMPLATE_LABELLED_ML)
#: what ``--help`` says of the least ``--tets`` (the same numbers the checks enforce)
TETS_FLOOR_TEXT = (f"of the ICBM152 template at least {TEMPLATE_TETS_MIN} x 8^K with --refine "
                   f"K, of a --labels image at least {LABELS_TETS_PER_ML[0]:.1f} per ml of tissue")


def size_defaults(tets: int, refine: int | None = None, linear_solver: str | None = None,
                  mesh_given: bool = False) -> tuple[int, str]:
    """``(refine, linear_solver)`` for a mesh of about ``tets`` tets (a mesh
    read from a file: its own number of tets); each argument given (not None) is kept as it
    is.

    From :data:`LARGE_TETS` up: Netgen at ``tets / 8``, refined once (``refine = 1``), the
    load ramped on the fine mesh and GMRES with AMG blocks (``krylov``); below it: one
    Netgen mesh, PARDISO. A mesh read from a file (``mesh_given``) is not refined unless
    asked.
    """
    large = tets >= LARGE_TETS
    if refine is None:
        refine = 1 if large and not mesh_given else 0
    if linear_solver is None:  # PARDISO on a 1.40M-tet brain: ~5.9M unknowns, out of memory
        linear_solver = "krylov" if large else "pardiso"
    return refine, linear_solver


#: how the help states the defaults that depend on other options
DEFAULT_TEXT = {
    "linear_solver": f"default: from the size, krylov from {LARGE_TETS:,} tets",
    "refine": f"default: 1 from {LARGE_TETS:,} tets, else 0",
    "flap_diameter_mm": f"default {UNILATERAL_DIAMETER_MM:g}",
    "labels": "default: the ICBM152 template",
    "fibres": "default: radial from the brain's centre",
}


@dataclass
class CraniectomyCase:
    """One 3D scenario: which flap is open, which white matter swells, and how.

    Lengths in mm, volumes in ml, angles in degrees. Each field is declared once with its
    default, unit, range and help (:func:`option`, the text ``brainbulge brain --help``
    shows); the ranges are checked here. ``extra``: what a planner records about the case
    (``brainbulge plan``: the candidate centre's index and side, its point on the skull, why
    a flap was refused); not read by the simulation.
    """

    flap: str = option("left", "the craniectomy (custom needs --flap-centre; none: intact "
                       "skull, infeasible with swelling)", choices=FLAPS)
    swell: str = option("both", "hemisphere(s) whose white matter swells",
                        choices=tuple(SWELL_SIDES))
    swelling: float = option(1.1, "target Js of the white matter (the paper's 1.1)",
                             range=SWELLING_RANGE, label="swelling Js")
    tets: int = option(30_000, f"build a mesh of about this many tets: {TETS_FLOOR_TEXT}",
                       range=TETS_RANGE,
                       solver=True)
    mesh: str | None = option(None, "brain.npz written by `brainbulge mesh` (fixes the "
                              "geometry: overrides --tets and the geometry options)")
    labels: str | None = option(None, "NIfTI label map")
    label_map: str = option("synthseg", "label preset (freesurfer, aseg, synthseg, gmwmcsf) "
                            "or JSON file of --labels")
    brain_volume_ml: float | None = option(
        None, "scale the head so that the --volume-of volume is this", unit=" ml",
        range=BRAIN_VOLUME_RANGE_ML, label="brain volume", flag="--brain-volume")
    volume_of: str = option(
        "intracranial", "what --brain-volume sets: the intracranial volume (incl. CSF), the "
        "brain (cerebral gray + white matter; the paper's 1108 ml) or the white matter",
        choices=VOLUME_OF)
    flap_centre_mm: tuple[float, float, float] | None = option(
        None, "centre of a custom flap on the skull (RAS)", unit=" mm", flag="--flap-centre",
        metavar=("X", "Y", "Z"))
    flap_diameter_mm: float | None = option(
        None, "diameter of a custom flap", unit=" mm", range=FLAP_DIAMETER_RANGE_MM,
        label="flap diameter", flag="--flap-diameter")
    fibres: str | None = option(None, "4D NIfTI (nx, ny, nz, 3) of axon directions, e.g. DTI "
                                "V1, in world axes")
    material: str = option("paper", "tissue preset: paper or paper-pa")
    element: str = option("mini", "MINI (P1 + bubble / P1) or Taylor-Hood (P2 / P1)",
                          choices=ELEMENTS, solver=True)
    linear_solver: str | None = option(
        None, "direct, or GMRES with AMG blocks (with Taylor-Hood a two-level cycle on the "
        "P2 block)", choices=LINEAR_SOLVERS, solver=True)
    steps: int = option(4, "initial number of load steps", range=(1, 1000), solver=True)
    tolerance: float = option(
        1e-9, "Newton's tolerance on the scaled residual at full load (force / (mu L^2), "
        "volume / |Omega|)", range=(1e-14, 1e-3), solver=True)
    compile: bool = option(True, "compile the energy to machine code (a one-off ~10 s; "
                           "assembly ~3.5x faster)", solver=True, internal=True)
    edge_radius_mm: float = option(
        EDGE_RADIUS_MM, "rounding radius of the skull's cut edge, in the bone outside the "
        "opening", unit=" mm", range=EDGE_RADIUS_RANGE_MM, label="edge radius",
        flag="--skull-edge-radius")
    edge_exclusion_mm: float = option(
        5.0, "band around the flap rim left out of max_*/min_*", unit=" mm", range=(0.0, 50.0),
        label="edge exclusion", flag="--edge-exclusion")
    fix: str = option("inferior+superior", "fixed part of the outer surface: the inferior "
                      "surface, or that and the band along the superior midline (the paper's "
                      "Figure 6)", choices=FIXATIONS)
    superior_width_mm: float = option(
        SUPERIOR_WIDTH_MM, "width of the fixed superior band across the mid-sagittal plane "
        "(the superior sagittal sinus)", unit=" mm", range=SUPERIOR_WIDTH_RANGE_MM,
        label="superior band width", flag="--superior-width")
    superior_elevation_deg: float = option(
        SUPERIOR_ELEVATION_DEG, "the superior band covers the midline above this elevation "
        "seen from the brain centre", unit=" deg", range=SUPERIOR_ELEVATION_RANGE_DEG,
        label="superior band elevation", flag="--superior-elevation")
    refine: int | None = option(
        None, "mesh at tets / 8^K and refine it uniformly K times (new surface nodes on the "
        "skull's inner surface)", range=(0, 3), solver=True)
    name: str = option("", "the scenario's name (default FLAP-flap_SWELL-swelling)",
                       internal=True)
    extra: dict = option(None, "what a planner records about the case", internal=True,
                         factory=dict)

    def __post_init__(self) -> None:
        if self.flap not in FLAPS:
            raise InputError(f"unknown flap {self.flap!r}; choose one of {', '.join(FLAPS)}")
        if self.flap == "custom" and self.flap_centre_mm is None and self.mesh is None:
            raise InputError("a custom flap needs its centre: --flap-centre X Y Z (mm)")
        if self.swell not in SWELL_SIDES:
            raise InputError(
                f"unknown swelling side {self.swell!r}; choose one of {', '.join(SWELL_SIDES)}"
            )
        if self.flap_centre_mm is not None:
            self.flap_centre_mm = tuple(self.flap_centre_mm)  # type: ignore[assignment]
        check_ranges(self)
        size = self.tets
        if self.mesh is not None:
            from brainbulge.geometry.brain.export import stored_tets

            # a given mesh's own size; a file that is no brain.npz is refused where it is
            # read, with the reader's reason
            with contextlib.suppress(InputError):
                size = stored_tets(self.mesh)
        self.refine, self.linear_solver = size_defaults(
            size, self.refine, self.linear_solver, self.mesh is not None)
        if self.linear_solver not in LINEAR_SOLVERS:
            raise InputError(f"linear solver {self.linear_solver!r}: choose pardiso or krylov")
        if self.element not in ELEMENTS:
            raise InputError(f"unknown element {self.element!r}; choose mini or taylor-hood")
        if self.volume_of not in VOLUME_OF:
            raise InputError(f"unknown volume_of {self.volume_of!r}; choose one of "
                             f"{', '.join(VOLUME_OF)}")
        if self.fix not in FIXATIONS:
            raise InputError(f"unknown fixation {self.fix!r}; choose one of "
                             f"{', '.join(FIXATIONS)}")
        from brainbulge.model.brain import tissue_materials

        tissue_materials(self.material)  # an unknown preset fails here, before any meshing
        self.superior_band()  # the band's open bounds
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
        if self.refine and self.mesh is not None:
            raise InputError("--refine applies to a mesh built here, not to --mesh: build a "
                             "refined one with `brainbulge mesh --refine` and pass that")
        if self.fibres is not None and not Path(self.fibres).is_file():
            raise InputError(f"fibre image {self.fibres} does not exist or is not a regular "
                             "file; give a NIfTI file (.nii/.nii.gz) of shape (nx, ny, nz, 3)")
        if not self.name:
            self.name = f"{self.flap}-flap_{self.swell}-swelling"

    @property
    def flap_diameter(self) -> float:
        """The custom flap's diameter [mm]: ``flap_diameter_mm``, else the unilateral one."""
        return self.flap_diameter_mm or UNILATERAL_DIAMETER_MM

    def superior_band(self) -> SuperiorBand | None:
        """The fixed superior band, or None with ``fix = "inferior"``."""
        from brainbulge.geometry.brain.boundaries import SuperiorBand

        band = SuperiorBand(self.superior_width_mm, self.superior_elevation_deg)
        return band if self.fix == "inferior+superior" else None


#: the fields of :class:`CraniectomyCase` that say how it is discretised and solved (the
#: ``[solver]`` table of a run file); the others say what is simulated (``[case]``)
SOLVER_FIELDS = solver_fields(CraniectomyCase)

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

from pathlib import Path

import numpy as np

from brainbulge.errors import InputError
from brainbulge.geometry.brain import BrainMesh, to_ngsolve
from brainbulge.geometry.brain.skull import RigidSkull
from brainbulge.materials import MooneyRivlin, preset
from brainbulge.model.brain_case import (  # noqa: F401 - the case's names, offered here too
    FLAPS,
    LARGE_TETS,
    SOLVER_FIELDS,
    SWELL_SIDES,
    CraniectomyCase,
    size_defaults,
)
from brainbulge.model.problem import Contact, Problem

#: tissue -> row of the material table used for it
TISSUE_MATERIAL = {
    "gray": "gray",
    "white": "white",
    "csf": "csf",
    "cerebellum": "cerebellum",
    "brainstem": "cerebellum",
}


def brain_mesh_for(case: CraniectomyCase) -> BrainMesh:
    """Load or build the labelled brain mesh of ``case``, its flap open
    (:func:`open_case_flap`)."""
    from brainbulge.geometry.brain import (
        build_brain_mesh,
        load_brain_mesh,
        load_tissue_image,
    )

    if case.mesh is not None:
        path = Path(case.mesh)
        bm = load_brain_mesh(path / "brain.npz" if path.is_dir() else path)
    else:
        image = load_tissue_image(case.labels, case.label_map) if case.labels else None
        bm = build_brain_mesh(image, target_tets=case.tets,
                              brain_volume_ml=case.brain_volume_ml, volume_of=case.volume_of,
                              refinements=case.refine)
    open_case_flap(bm, case)
    return bm


def open_case_flap(bm: BrainMesh, case: CraniectomyCase) -> None:
    """Open the flap ``case`` asks for on ``bm``: the one rule from the request to the flap.

    A custom flap with a centre (``flap_centre_mm``, ``flap_diameter_mm``, default 120 mm) is
    opened by the fitting rule (:func:`~brainbulge.geometry.brain.flap_fit.open_flap`:
    refused if it reaches the fixed base or crosses the midline, clipped at the case's fixed
    superior band) as ``bm.flaps["custom"]``, on a built mesh and a loaded one alike (the
    mesh is not rebuilt); the named flaps, and a custom flap of a ``brainbulge mesh`` file,
    are the mesh's. An `InputError` if the flap is not on the mesh."""
    if case.flap_centre_mm is not None:
        from brainbulge.geometry.brain.flap_fit import open_flap

        open_flap(bm, case.flap_centre_mm, case.flap_diameter, case.superior_band())
    if case.flap != "none" and case.flap not in bm.flaps:
        raise InputError(f"flap {case.flap!r} is not defined on this mesh (it has "
                         f"{', '.join(sorted(bm.flaps))}); rebuild it with the flap's centre")


def tissue_materials(material: str) -> dict[str, MooneyRivlin]:
    """Tissue name -> material of the preset (brainstem as cerebellum)."""
    table = preset(material)
    return {t: table[m] for t, m in TISSUE_MATERIAL.items()}


def case_skull(bm: BrainMesh, case: CraniectomyCase) -> RigidSkull:
    """The rigid skull of ``case`` on ``bm``: its flap open (none with ``flap = "none"``),
    the cut edge rounded by ``edge_radius_mm``. Built once per run and passed on (problem,
    summary, plan measures)."""
    flap = None if case.flap == "none" else bm.flaps[case.flap]
    return RigidSkull(bm.envelope, flap, case.edge_radius_mm)


def brain_problem(bm: BrainMesh, case: CraniectomyCase,
                  skull: RigidSkull | None = None) -> Problem:
    """The NGSolve problem of ``case`` on the brain mesh ``bm``; ``skull``: the case's rigid
    skull on ``bm`` (:func:`case_skull`, made here if not given)."""
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
    clamped = "base" if band is None else "base|superior"
    # the flap is traction-free but may not pass into the bone: its rounded cut edge lies
    # over the opening's rim (up to edge_radius_mm inside the cutter)
    return Problem(mesh, materials, swelling, clamped=clamped,
                   contacts=[Contact("skull|flap", skull or case_skull(bm, case))])


def white_matter_volume_ml(bm: BrainMesh, sides: tuple[str, ...]) -> float:
    """Reference volume of the white matter on ``sides`` [ml]."""
    vols = bm.region_volumes_ml()
    return float(np.sum([vols.get(f"white_{s}", 0.0) for s in sides]))

"""Brains from MRI labels: tissue images, the skull's inner surface, labelled tet meshes,
boundaries (base, skull, flaps), the rigid-skull obstacle, exports and NGSolve meshes.

Pipeline::

    image = icbm152_tissue_image()                 # or load_tissue_image(path, "synthseg")
    mesh = build_brain_mesh(image, target_tets=100_000, brain_volume_ml=1108)
    save_brain_mesh(mesh, "out/")                  # VTU, XDMF, npz, mesh.json, PNGs
    ng = to_ngsolve(mesh, flap="left")             # materials "{tissue}_{side}"
    phi, grad = mesh.skull("left").signed_distance(points_mm)
"""

from brainbulge.geometry.brain.boundaries import (
    Flap,
    custom_flap,
    frontal_flap,
    unilateral_flap,
)
from brainbulge.geometry.brain.brain_mesh import BrainMesh, build_brain_mesh, check_brain_mesh
from brainbulge.geometry.brain.envelope import IntracranialEnvelope, intracranial_envelope
from brainbulge.geometry.brain.export import brain_summary, load_brain_mesh, save_brain_mesh
from brainbulge.geometry.brain.labels import (
    LABEL_MAP_PRESETS,
    TISSUES,
    TissueImage,
    load_tissue_image,
    tissue_image_from_labels,
)
from brainbulge.geometry.brain.ngsolve_mesh import to_ngsolve
from brainbulge.geometry.brain.regions import MidSagittalPlane
from brainbulge.geometry.brain.skull import RigidSkull
from brainbulge.geometry.brain.template import icbm152_tissue_image

__all__ = [
    "LABEL_MAP_PRESETS",
    "TISSUES",
    "BrainMesh",
    "Flap",
    "IntracranialEnvelope",
    "MidSagittalPlane",
    "RigidSkull",
    "TissueImage",
    "brain_summary",
    "build_brain_mesh",
    "check_brain_mesh",
    "custom_flap",
    "frontal_flap",
    "icbm152_tissue_image",
    "intracranial_envelope",
    "load_brain_mesh",
    "load_tissue_image",
    "save_brain_mesh",
    "tissue_image_from_labels",
    "to_ngsolve",
    "unilateral_flap",
]

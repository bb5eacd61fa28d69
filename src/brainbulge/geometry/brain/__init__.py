"""Brains from MRI labels: tissue images, the skull's inner surface, labelled tet meshes,
boundaries (base, skull, flaps), the rigid-skull obstacle, exports and NGSolve meshes.

Pipeline::

    image = icbm152_tissue_image()                 # or load_tissue_image(path, "synthseg")
    mesh = build_brain_mesh(image, target_tets=100_000, brain_volume_ml=1108)
    save_brain_mesh(mesh, "out/")                  # VTU, XDMF, npz, mesh.json, PNGs
    ng = to_ngsolve(mesh, flap="left")             # materials "{tissue}_{side}"
    phi, grad = mesh.skull("left").signed_distance(points_mm)
"""

from brainbulge.lazy import lazy_names

#: public name -> submodule; loaded on first use (PEP 562), so that importing a light
#: submodule (e.g. ``defaults`` for the CLI's parser) does not pull in scipy.ndimage and the
#: meshing stack: every ``brainbulge`` command paid ~0.3 s for it
_WHERE = {
    "Flap": "boundaries",
    "custom_flap": "boundaries",
    "frontal_flap": "boundaries",
    "unilateral_flap": "boundaries",
    "BrainMesh": "brain_mesh",
    "build_brain_mesh": "brain_mesh",
    "check_brain_mesh": "brain_mesh",
    "IntracranialEnvelope": "envelope",
    "intracranial_envelope": "envelope",
    "brain_summary": "export",
    "load_brain_mesh": "export",
    "save_brain_mesh": "export",
    "LABEL_MAP_PRESETS": "labels",
    "TISSUES": "labels",
    "TissueImage": "labels",
    "load_tissue_image": "labels",
    "tissue_image_from_labels": "labels",
    "to_ngsolve": "ngsolve_mesh",
    "MidSagittalPlane": "regions",
    "RigidSkull": "skull",
    "icbm152_tissue_image": "template",
}

__all__ = sorted(_WHERE)


__getattr__, __dir__ = lazy_names(__name__, globals(), _WHERE)

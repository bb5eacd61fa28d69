"""A toy segmentation (the one of docs/own-mri.md) and its ~1000-tet brain mesh: small enough
for default tests that solve the 3D craniectomy end to end."""

from __future__ import annotations

from pathlib import Path

import nibabel as nib
import numpy as np

#: FreeSurfer/SynthSeg codes of the toy: left / right white 2 / 41, gray 3 / 42, a left lateral
#: ventricle 4 centred at (-20, 0, 0) mm, radius 8 mm
VENTRICLE_CENTRE_MM = (-20.0, 0.0, 0.0)


def toy_labels(path: Path, ventricles: bool = True) -> Path:
    """Write the toy segmentation (RAS+ mm, 3 mm voxels: an ellipsoid of semi-axes 60, 50,
    45 mm, white matter inside 85 % of it) to ``path``; ``ventricles=False`` leaves out the
    left lateral ventricle."""
    g = np.arange(-70.5, 72.0, 3.0)
    x, y, z = np.meshgrid(g, g, g, indexing="ij")
    r = np.sqrt((x / 60) ** 2 + (y / 50) ** 2 + (z / 45) ** 2)
    brain, white, left = r <= 1, r <= 0.85, x < 0
    labels = np.select([white & left, white, brain & left, brain], [2, 41, 3, 42], 0)
    if ventricles:
        cx, cy, cz = VENTRICLE_CENTRE_MM
        labels[(x - cx) ** 2 + (y - cy) ** 2 + (z - cz) ** 2 < 8**2] = 4
    affine = np.diag([3.0, 3.0, 3.0, 1.0])
    affine[:3, 3] = g[0]
    nib.save(nib.Nifti1Image(labels.astype(np.int16), affine), path)
    return path


def toy_mesh(folder: Path, ventricles: bool = True):
    """The toy's brain mesh (about 1000 tets, a custom 70 mm flap over the left hemisphere),
    saved to ``folder/brain.npz``; returns the :class:`BrainMesh`."""
    from brainbulge.geometry.brain import build_brain_mesh, load_tissue_image, save_brain_mesh

    folder.mkdir(parents=True, exist_ok=True)
    image = load_tissue_image(toy_labels(folder / "seg.nii.gz", ventricles), "synthseg")
    mesh = build_brain_mesh(image, target_tets=1000, custom_flap_centre_mm=(-40.0, 20.0, 40.0),
                            custom_flap_diameter_mm=70.0)
    save_brain_mesh(mesh, folder, flap="custom", figures=False)
    return mesh

"""The default brain: tissue labels from the ICBM152 2009a templates that nilearn ships (1 mm).

Gray, white and CSF come from the gray/white probability maps inside the brain mask (CSF =
``1 - p_gray - p_white``; each voxel takes the most probable class, so the ventricles and sulci
are CSF). The cerebellum and the brain stem are separated from the cerebrum by a seeded
watershed of the T1 intensity: the tentorial CSF gap is dark in T1 and the basins grown from
seeds in the cerebellar hemispheres, the pons and the cerebral lobes meet along it. Gray and white
voxels in the cerebellar basin become ``cerebellum``, those in the brain-stem basin
``brainstem``.
"""

from __future__ import annotations

import numpy as np
import scipy.ndimage as ndi

from brainbulge.geometry.brain.labels import (
    BRAINSTEM,
    CEREBELLUM,
    CSF,
    GRAY,
    TEMPLATE_SOURCE,
    WHITE,
    ImageGrid,
    TissueImage,
)

# Seeds in MNI152 world coordinates (mm): (x, y, z).
_CEREBELLUM_SEEDS_MM = [
    (-25, -65, -38),
    (25, -65, -38),
    (-15, -75, -30),
    (15, -75, -30),
    (-35, -60, -45),
    (35, -60, -45),
]
_BRAINSTEM_SEEDS_MM = [(0, -25, -35), (0, -30, -50), (0, -22, -25), (0, -38, -62),
                       (0, -35, -56), (-6, -25, -35), (6, -25, -35), (0, -40, -70)]
_CEREBRUM_SEEDS_MM = [
    (-40, 0, 20),
    (40, 0, 20),
    (-20, -90, 5),
    (20, -90, 5),
    (-45, -10, -25),
    (45, -10, -25),
    (-30, -60, 0),
    (30, -60, 0),
    (-10, -80, -5),
    (10, -80, -5),
    (0, 40, 0),
    (-12, -18, 8),
    (12, -18, 8),
]


def _seed_markers(shape: tuple[int, ...], affine: np.ndarray, tissue: np.ndarray) -> np.ndarray:
    inv = np.linalg.inv(affine)
    markers = np.zeros(shape, dtype=np.int32)
    for label, seeds in (
        (1, _CEREBRUM_SEEDS_MM),
        (2, _CEREBELLUM_SEEDS_MM),
        (3, _BRAINSTEM_SEEDS_MM),
    ):
        for p in seeds:
            i, j, k = np.round(inv[:3, :3] @ np.asarray(p, float) + inv[:3, 3]).astype(int)
            sl = (slice(i - 2, i + 3), slice(j - 2, j + 3), slice(k - 2, k + 3))
            markers[sl][tissue[sl]] = label
    return markers


def icbm152_tissue_image(separate_brainstem: bool = True) -> TissueImage:
    """Tissue labels of the ICBM152 2009a template (1 mm, MNI space, ~1.88 l brain mask).

    With ``separate_brainstem=False`` the brain stem is labelled ``cerebellum``.
    """
    from nilearn import datasets
    from skimage.segmentation import watershed

    mask_img = datasets.load_mni152_brain_mask(resolution=1)
    affine = mask_img.affine.astype(float)
    mask = np.asanyarray(mask_img.dataobj) > 0
    p_gray = np.asanyarray(datasets.load_mni152_gm_template(resolution=1).dataobj).astype(float)
    p_white = np.asanyarray(datasets.load_mni152_wm_template(resolution=1).dataobj).astype(float)
    t1 = np.asanyarray(datasets.load_mni152_template(resolution=1).dataobj).astype(float)
    p_csf = np.clip(1.0 - p_gray - p_white, 0.0, 1.0)
    tissue = np.zeros(mask.shape, dtype=np.int8)
    cls = np.argmax(np.stack([p_gray, p_white, p_csf]), axis=0)
    tissue[mask] = np.array([GRAY, WHITE, CSF], dtype=np.int8)[cls[mask]]

    parenchyma = (tissue == GRAY) | (tissue == WHITE)
    markers = _seed_markers(mask.shape, affine, parenchyma)
    elevation = -ndi.gaussian_filter(t1, 1.0)
    basins = watershed(elevation, markers, mask=parenchyma)
    tissue[basins == 2] = CEREBELLUM
    tissue[basins == 3] = BRAINSTEM if separate_brainstem else CEREBELLUM
    image = TissueImage(tissue, affine)
    assert image.grid is not None
    image.grid = ImageGrid(image.grid.shape, image.grid.affine, source=TEMPLATE_SOURCE)
    return image

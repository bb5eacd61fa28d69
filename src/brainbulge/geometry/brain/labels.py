"""Tissue label images: read a NIfTI segmentation and map its codes to brainbulge tissues.

A :class:`TissueImage` holds one integer tissue code per voxel (see :data:`TISSUES`) and the
voxel-to-world affine (world = RAS+ millimetres, as NIfTI/nibabel define it). Any voxel size and
orientation is accepted: every geometric step works in world millimetres through the affine.

Label maps translate a user's codes to tissues. Presets:

- ``"freesurfer"`` / ``"aseg"`` / ``"synthseg"``: FreeSurfer ``aseg`` codes (SynthSeg uses the same
  codes). Cortex and deep gray nuclei -> gray; cerebral white matter, corpus callosum and
  hypointensities -> white; ventricles, CSF and choroid plexus -> csf; cerebellar cortex and white
  matter -> cerebellum; brain stem (16) -> brainstem.
- ``"gmwmcsf"``: a plain map ``1 = CSF, 2 = gray, 3 = white`` (FSL FAST's ``_seg`` order).

A custom map is a JSON file ``{"gray": [3, 42], "white": [2, 41], "csf": [4], ...}``; codes not
listed (and 0) are background.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from brainbulge.errors import InputError

#: Tissue codes used in every brainbulge label array (0 = outside the brain).
BACKGROUND, GRAY, WHITE, CSF, CEREBELLUM, BRAINSTEM = 0, 1, 2, 3, 4, 5
TISSUES: dict[int, str] = {
    GRAY: "gray",
    WHITE: "white",
    CSF: "csf",
    CEREBELLUM: "cerebellum",
    BRAINSTEM: "brainstem",
}
TISSUE_CODES: dict[str, int] = {name: code for code, name in TISSUES.items()}
#: the ``source`` of the default brain's image grid (:mod:`.template`)
TEMPLATE_SOURCE = "ICBM152 2009a (nilearn, 1 mm)"

_ASEG: dict[str, list[int]] = {
    # cortex, thalamus, caudate, putamen, pallidum, hippocampus, amygdala, accumbens, ventral DC,
    # vessel, both sides
    "gray": [3, 42, 10, 49, 11, 50, 12, 51, 13, 52, 17, 53, 18, 54, 26, 58, 28, 60, 30, 62, 80],
    "white": [2, 41, 77, 78, 79, 85, 251, 252, 253, 254, 255],
    "csf": [4, 43, 5, 44, 14, 15, 24, 31, 63, 72],
    "cerebellum": [7, 46, 8, 47],
    "brainstem": [16],
}
LABEL_MAP_PRESETS: dict[str, dict[str, list[int]]] = {
    "freesurfer": _ASEG,
    "aseg": _ASEG,
    "synthseg": _ASEG,
    "gmwmcsf": {"csf": [1], "gray": [2], "white": [3]},
}


#: working memory per voxel of a label image beyond its own bytes [bytes]: the int64 copy,
#: np.unique's sorted copy, the tissue array and np.isin's masks
WORK_BYTES_PER_VOXEL = 24


def available_memory_bytes() -> int | None:
    """Memory this machine can still give [bytes] (``MemAvailable``; free pages elsewhere),
    None if unknown."""
    try:
        with open("/proc/meminfo", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, AttributeError):
        return None


def check_regular_file(path: str | Path, what: str) -> None:
    """Refuse (`InputError`) an input image that is not a regular file (a FIFO, a device, a
    folder: reading one could wait for good); a link to a regular file is fine."""
    import stat

    try:
        mode = Path(path).stat().st_mode
    except OSError as err:
        raise InputError(f"cannot read {what} {path}: {err.strerror or err}; give a NIfTI "
                         "file (.nii/.nii.gz)") from None
    if not stat.S_ISREG(mode):
        raise InputError(f"{what} {path} is not a regular file (a FIFO, a device or a "
                         "folder); give a NIfTI file (.nii/.nii.gz)")


def check_declared_size(img: object, path: str | Path, what: str,
                        work_bytes_per_voxel: int = WORK_BYTES_PER_VOXEL) -> None:
    """Refuse (`InputError`) a NIfTI image whose header declares more voxels than the memory
    available can read and process (e.g. a corrupt or hostile header on a small file), before
    any of it is read."""
    shape = tuple(int(n) for n in getattr(img, "shape", ()))
    try:
        itemsize = np.dtype(img.get_data_dtype()).itemsize  # type: ignore[attr-defined]
    except (AttributeError, TypeError):
        itemsize = 8
    need = math.prod(shape) * (itemsize + work_bytes_per_voxel)
    free = available_memory_bytes()
    if free is not None and need > free:
        dims = " x ".join(str(n) for n in shape)
        raise InputError(
            f"{what} {path} declares {dims} voxels: {need / 1e9:.1f} GB to read and process, "
            f"but {free / 1e9:.1f} GB of memory is available; check its header (a brain "
            "segmentation is about 256 x 256 x 256 voxels) or crop it")


@dataclass
class TissueImage:
    """Tissue codes on a voxel grid.

    ``tissue``: (nx, ny, nz) int8 array of codes from :data:`TISSUES` (0 = outside the brain);
    ``affine``: 4x4 voxel-index -> world (mm) matrix.
    """

    tissue: np.ndarray
    affine: np.ndarray
    #: the grid of the image as read (kept through :meth:`scaled_about`)
    grid: ImageGrid | None = None

    def __post_init__(self) -> None:
        if self.grid is None:
            shape = tuple(int(n) for n in self.tissue.shape[:3])
            self.grid = ImageGrid(shape, np.asarray(self.affine, float).copy())  # type: ignore[arg-type]

    @property
    def voxel_volume_mm3(self) -> float:
        """Volume of one voxel (mm^3)."""
        return float(abs(np.linalg.det(self.affine[:3, :3])))

    def volumes_ml(self) -> dict[str, float]:
        """Volume of each tissue in the image (ml)."""
        counts = np.bincount(self.tissue.ravel().astype(np.int64), minlength=len(TISSUES) + 1)
        return {name: counts[code] * self.voxel_volume_mm3 / 1000 for code, name in TISSUES.items()}

    def scaled_about(self, factor: float, centre_mm: np.ndarray) -> TissueImage:
        """The same image with world coordinates scaled by ``factor`` about ``centre_mm``."""
        scale = np.eye(4)
        scale[:3, :3] *= factor
        scale[:3, 3] = np.asarray(centre_mm, float) * (1 - factor)
        assert self.grid is not None
        return TissueImage(self.tissue, scale @ self.affine,
                           self.grid.scaled_about(factor, centre_mm))


@dataclass(frozen=True)
class ImageGrid:
    """The voxel grid of the label image a mesh was built from, for maps on that grid.

    ``shape``: (nx, ny, nz) voxels; ``affine``: 4x4 voxel index -> world (mm) matrix of the
    image's header (what a map written on this grid carries); ``to_mesh``: 4x4 world (mm) ->
    mesh (mm) matrix, the identity unless the geometry was scaled to a brain volume
    (``brain_volume_ml``: ``x_mesh = c + s (x - c)``); ``source``: where the image came from
    (its path, or the template's name)."""

    shape: tuple[int, int, int]
    affine: np.ndarray
    to_mesh: np.ndarray = field(default_factory=lambda: np.eye(4))
    source: str = ""

    def index_to_mesh(self) -> np.ndarray:
        """4x4 voxel index -> mesh (mm) matrix: a voxel centre ``(i, j, k)`` lies at
        ``index_to_mesh() @ (i, j, k, 1)`` in the mesh's coordinates."""
        return np.asarray(self.to_mesh, float) @ np.asarray(self.affine, float)

    def scaled_about(self, factor: float, centre_mm: np.ndarray) -> ImageGrid:
        """The same grid for a mesh scaled by ``factor`` about ``centre_mm``."""
        scale = np.eye(4)
        scale[:3, :3] *= factor
        scale[:3, 3] = np.asarray(centre_mm, float) * (1 - factor)
        return ImageGrid(self.shape, self.affine, scale @ self.to_mesh, self.source)


def read_label_map(label_map: str | Path | dict[str, list[int]]) -> dict[str, list[int]]:
    """A label map as ``{tissue name: [codes]}``, from a preset name, a JSON file or a dict."""
    if isinstance(label_map, dict):
        mapping = label_map
    elif str(label_map).lower() in LABEL_MAP_PRESETS:
        mapping = LABEL_MAP_PRESETS[str(label_map).lower()]
    else:
        path = Path(label_map)
        if not path.is_file():
            presets = ", ".join(LABEL_MAP_PRESETS)
            raise InputError(
                f"label map {label_map!r} is neither a preset ({presets}) nor a readable file: "
                'give a preset name or a JSON file {"gray": [codes], ...}'
            )
        try:
            mapping = json.loads(path.read_text(encoding="utf-8-sig"))
        except (OSError, ValueError, RecursionError) as err:
            why = "nested too deeply" if isinstance(err, RecursionError) else " ".join(
                str(err).split())
            raise InputError(
                f'cannot read label map {path}: {why}; write it as JSON {{"gray": [3, 42], ...}}'
            ) from None
    if not isinstance(mapping, dict):
        raise InputError('label map must be a JSON object {"gray": [codes], ...}')
    unknown = set(mapping) - set(TISSUE_CODES)
    if unknown:
        raise InputError(
            f"label map has unknown tissue(s) {sorted(unknown)}: use {sorted(TISSUE_CODES)}"
        )
    for name in ("gray", "white"):
        if not mapping.get(name):
            raise InputError(f"label map gives no codes for {name!r}: add its label codes")
    for name, values in mapping.items():
        whole = isinstance(values, list) and all(
            isinstance(c, int | float) and not isinstance(c, bool) and float(c).is_integer()
            and abs(c) < 2**31 for c in values)
        if not whole:
            raise InputError(f"label map codes of {name!r} must be a list of whole numbers, got "
                             f"{json.dumps(values)[:60]}; write e.g. {{\"gray\": [3, 42]}}")
    codes = {name: [int(c) for c in values] for name, values in mapping.items()}
    owner: dict[int, str] = {}
    for name, values in codes.items():
        for code in values:
            if owner.setdefault(code, name) != name:
                raise InputError(f"label map lists code {code} in both {owner[code]!r} and "
                                 f"{name!r}; give each code to one tissue")
    return codes


def tissue_image_from_labels(
    labels: np.ndarray, affine: np.ndarray, label_map: str | Path | dict[str, list[int]]
) -> TissueImage:
    """Translate a user's integer label array into a :class:`TissueImage`.

    Raises :class:`InputError` for non-integer labels, an absurd voxel size (outside 0.1-5 mm), a
    map whose codes do not occur in the image, or an empty gray/white region.
    """
    mapping = read_label_map(label_map)
    labels = np.asarray(labels)
    if labels.ndim == 4 and labels.shape[3] == 1:
        labels = labels[..., 0]
    if labels.ndim != 3:
        raise InputError(f"label image must be 3D, got shape {labels.shape}: give one label map")
    if not np.issubdtype(labels.dtype, np.integer):
        if not np.all(np.isfinite(labels)) or np.any(labels != np.round(labels)):
            raise InputError(
                "label image holds non-integer values: give a segmentation (label map), "
                "not an intensity or probability image"
            )
        labels = labels.astype(np.int64)
    voxel_mm = np.linalg.norm(np.asarray(affine)[:3, :3], axis=0)
    if np.any(voxel_mm < 0.1) or np.any(voxel_mm > 5.0) or not np.all(np.isfinite(voxel_mm)):
        raise InputError(
            f"voxel size {np.round(voxel_mm, 3).tolist()} mm is outside 0.1-5 mm: "
            "check the NIfTI header (affine / pixdim units)"
        )
    present = set(np.unique(labels).tolist())
    tissue = np.zeros(labels.shape, dtype=np.int8)
    for name, codes in mapping.items():
        tissue[np.isin(labels, codes)] = TISSUE_CODES[name]
    if not present & {c for codes in mapping.values() for c in codes}:
        raise InputError(
            "none of the label map's codes occur in the image: pick the preset that matches "
            "the segmentation (freesurfer, synthseg, gmwmcsf) or pass a JSON map"
        )
    for name in ("gray", "white"):
        if not np.any(tissue == TISSUE_CODES[name]):
            raise InputError(
                f"region {name!r} is empty: none of its codes {mapping[name]} occur in the image"
            )
    return TissueImage(tissue, np.asarray(affine, dtype=float))


def load_tissue_image(
    path: str | Path, label_map: str | Path | dict[str, list[int]]
) -> TissueImage:
    """Read a NIfTI label image (``.nii``/``.nii.gz``) and map it to tissues (see module doc)."""
    import nibabel as nib

    check_regular_file(path, "label image")
    try:
        img = nib.load(str(path))
    except Exception as err:  # nibabel raises many types for unreadable files
        raise InputError(
            f"cannot read label image {path}: {type(err).__name__}; "
            "give a NIfTI file (.nii/.nii.gz)"
        ) from None
    check_declared_size(img, path, "label image")
    try:
        data = np.asanyarray(img.dataobj)
    except Exception as err:  # noqa: BLE001 - truncated data, a header that lies
        raise InputError(
            f"cannot read label image {path}: {type(err).__name__}; "
            "give a NIfTI file (.nii/.nii.gz)"
        ) from None
    image = tissue_image_from_labels(data, img.affine, label_map)
    assert image.grid is not None
    image.grid = dataclasses.replace(image.grid, source=str(Path(path).resolve()))
    return image

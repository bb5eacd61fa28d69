"""Axon directions from a vector image (e.g. the principal eigenvector of DTI).

A 4D NIfTI of shape (nx, ny, nz, 3) holds a direction per voxel in world (RAS+) axes; the
direction at a point is that of the nearest voxel, normalised. Where the image gives no
direction (outside it, or a zero vector), the radial direction from ``centre_mm`` is used, the
default of docs/model.md section 3. The sign of a direction does not matter: ``lambda_n`` and
``lambda_t`` are even in ``n``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from brainbulge.errors import InputError


def check_shape(shape: tuple[int, ...], path: str | Path) -> None:
    """A fibre image's shape (from its header) must be (nx, ny, nz, 3), axes of length 1
    aside."""
    dims = tuple(n for n in shape if n != 1)
    if len(dims) != 4 or dims[3] != 3:
        raise InputError(
            f"fibre image {path} has shape {tuple(shape)}; expected (nx, ny, nz, 3), a unit "
            "vector per voxel (e.g. DTI V1)")


def check_fibres(path: str | Path) -> None:
    """``path`` reads as a fibre image (`read_fibres`: header, shape, size, values); for
    checking a command's inputs before it starts (before anything is meshed). A file checked
    once (same size and modification time) is not read again."""
    p = Path(path)
    try:
        st = p.stat()
    except OSError as err:
        raise InputError(f"cannot read fibre image {path}: {err.strerror or err}; give a NIfTI "
                         "file (.nii/.nii.gz) of shape (nx, ny, nz, 3)") from None
    key = (str(p.resolve()), st.st_size, st.st_mtime_ns)
    if key not in _CHECKED:
        read_fibres(path)
        _CHECKED.add(key)


_CHECKED: set[tuple[str, int, int]] = set()


def read_fibres(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """The directions (nx, ny, nz, 3) and the voxel-to-world affine of the fibre image
    ``path``; `InputError` (one line) for a file that is not a NIfTI, of another shape,
    larger than the memory available, with NaN or infinite components, or whose affine is
    not finite and invertible. Zero vectors are allowed (no direction there)."""
    import nibabel as nib

    from brainbulge.geometry.brain.labels import check_declared_size, check_regular_file

    check_regular_file(path, "fibre image")
    try:
        img = nib.load(str(path))
    except Exception as err:  # noqa: BLE001 - nibabel raises several types
        raise InputError(f"cannot read fibre image {path}: {type(err).__name__}; give a "
                         "NIfTI file (.nii/.nii.gz) of shape (nx, ny, nz, 3)") from None
    check_shape(img.shape, path)
    check_declared_size(img, path, "fibre image", work_bytes_per_voxel=8)
    try:
        data = np.squeeze(np.asarray(img.dataobj, dtype=np.float32))
    except Exception as err:  # noqa: BLE001 - truncated data
        raise InputError(f"cannot read fibre image {path}: {type(err).__name__}; give a "
                         "complete NIfTI file") from None
    bad = ~np.all(np.isfinite(data), axis=-1)
    if bad.any():
        raise InputError(
            f"fibre image {path} has {int(bad.sum())} voxels with a NaN or infinite "
            "component; set them to 0 (no direction there: the radial default is used)")
    affine = np.asarray(img.affine, dtype=float)
    if not np.all(np.isfinite(affine)) or abs(np.linalg.det(affine[:3, :3])) < 1e-12:
        raise InputError(f"fibre image {path} has a voxel-to-world affine that is not finite "
                         "and invertible; correct its NIfTI header (sform/qform)")
    return data, affine


class FibreField:
    """Unit axon directions at world points (mm), read from a vector NIfTI."""

    def __init__(self, path: str | Path, centre_mm: np.ndarray) -> None:
        data, affine = read_fibres(path)
        self.data = data
        self.inv = np.linalg.inv(affine)
        self.centre_mm = np.asarray(centre_mm, dtype=float)

    def __call__(self, points_mm: np.ndarray) -> np.ndarray:
        """Directions (n, 3) at ``points_mm`` (n, 3)."""
        X = np.asarray(points_mm, dtype=float)
        ijk = np.rint(X @ self.inv[:3, :3].T + self.inv[:3, 3]).astype(int)
        shape = np.array(self.data.shape[:3])
        inside = np.all((ijk >= 0) & (ijk < shape), axis=1)
        v = np.zeros_like(X)
        idx = ijk[inside]
        v[inside] = self.data[idx[:, 0], idx[:, 1], idx[:, 2]]
        norm = np.linalg.norm(v, axis=1)
        radial = X - self.centre_mm
        rn = np.linalg.norm(radial, axis=1)
        fallback = norm < 1e-6
        out = np.where(fallback[:, None], radial / np.maximum(rn, 1e-12)[:, None],
                       v / np.maximum(norm, 1e-12)[:, None])
        return out

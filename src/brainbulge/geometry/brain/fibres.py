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
    """Read only ``path``'s header: a NIfTI of the shape `check_shape` wants, whose data
    fits in memory. For checking a command's inputs before it starts."""
    import nibabel as nib

    from brainbulge.geometry.brain.labels import check_declared_size

    try:
        img = nib.load(str(path))
    except Exception as err:  # noqa: BLE001 - nibabel raises several types
        raise InputError(f"cannot read fibre image {path}: {type(err).__name__}; give a "
                         "NIfTI file (.nii/.nii.gz) of shape (nx, ny, nz, 3)") from None
    check_shape(img.shape, path)
    check_declared_size(img, path, "fibre image", work_bytes_per_voxel=8)


class FibreField:
    """Unit axon directions at world points (mm), read from a vector NIfTI."""

    def __init__(self, path: str | Path, centre_mm: np.ndarray) -> None:
        import nibabel as nib

        from brainbulge.geometry.brain.labels import check_declared_size

        try:
            img = nib.load(str(path))
        except Exception as err:  # nibabel raises several types for unreadable files
            raise InputError(f"cannot read fibre image {path}: {err}; give a NIfTI file") from None
        check_shape(img.shape, path)
        check_declared_size(img, path, "fibre image", work_bytes_per_voxel=8)
        try:
            data = np.squeeze(np.asarray(img.dataobj, dtype=np.float32))
        except Exception as err:  # noqa: BLE001 - truncated data
            raise InputError(f"cannot read fibre image {path}: {err}; give a NIfTI file") from None
        if not np.all(np.isfinite(data)):
            raise InputError(f"fibre image {path} holds NaN or infinite values; mask them to 0")
        self.data = data
        self.inv = np.linalg.inv(img.affine)
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

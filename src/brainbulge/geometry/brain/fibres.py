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


class FibreField:
    """Unit axon directions at world points (mm), read from a vector NIfTI."""

    def __init__(self, path: str | Path, centre_mm: np.ndarray) -> None:
        import nibabel as nib

        try:
            img = nib.load(str(path))
            data = np.asarray(img.dataobj, dtype=np.float32)
        except Exception as err:  # nibabel raises several types for unreadable files
            raise InputError(f"cannot read fibre image {path}: {err}; give a NIfTI file") from None
        data = np.squeeze(data)
        if data.ndim != 4 or data.shape[3] != 3:
            raise InputError(
                f"fibre image {path} has shape {data.shape}; expected (nx, ny, nz, 3), a unit "
                "vector per voxel (e.g. DTI V1)"
            )
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
